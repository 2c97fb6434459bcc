"""Dynamics (paper Eq. 5-14) and the plant model."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from tapmp.dynamics import coriolis_matrix, energy, mass_matrix, mass_matrix_eq13, task_acceleration
from tapmp.errors import ModelInputError
from tapmp.kinematics import jacobian
from tapmp.params import PAPER_MODEL, ModelParams
from tapmp.plant import IDEAL, PlantConfig, PlantModel

angles = st.floats(-1.5, 1.5)


def coriolis_eq13(B: float, dB: float, p: ModelParams):
    """The paper's closed-form C of Eq. 13 (assumes m_1 = m_3), the reference coriolis_matrix is
    checked against."""
    L, m1, c, s = p.L_1, p.m_1, math.cos(B), math.sin(B)
    k = 2.0 * math.sqrt(3.0) * m1 * L * dB / 3.0
    return ((0.0, 0.0, -k * s), (0.0, 0.0, k * c), (0.0, 0.0, 4.0 * m1 * L * L * dB * c * s / 3.0))


@given(angles)
def test_mass_matrix_is_symmetric_positive_definite_over_the_workspace(B):
    M = np.array(mass_matrix(B, PAPER_MODEL))
    assert np.array_equal(M, M.T)
    assert np.linalg.eigvalsh(M).min() > 0


@given(angles)
def test_mass_matrix_is_platform_plus_jacobian_weighted_movers(B):
    p = PAPER_MODEL
    J = np.array(jacobian(B, p.L_1))
    expected = np.diag([p.m_p, p.m_p, p.I_y]) + J.T @ np.diag([p.m_1, p.m_2, p.m_3]) @ J
    assert np.allclose(mass_matrix(B, p), expected, rtol=1e-13, atol=1e-15)


@given(angles, st.floats(-3, 3))
def test_exact_form_equals_eq13_when_m1_equals_m3(B, dB):
    p = PAPER_MODEL._replace(m_3=PAPER_MODEL.m_1)
    assert np.allclose(mass_matrix(B, p), mass_matrix_eq13(B, p), rtol=1e-13, atol=1e-15)
    assert np.allclose(coriolis_matrix(B, dB, p), coriolis_eq13(B, dB, p), rtol=1e-12, atol=1e-15)


def test_exact_form_differs_from_eq13_with_the_identified_masses():
    # m_1 = 4.776, m_3 = 4.775 kg: M12 = (m_1 - m_3)/sqrt(3) = 5.77e-4 kg, which Eq. 13 sets to 0.
    assert mass_matrix(0.0, PAPER_MODEL)[0][1] == pytest.approx(0.001 / math.sqrt(3))
    assert mass_matrix_eq13(0.0, PAPER_MODEL)[0][1] == 0.0


@given(angles, st.floats(-3, 3))
def test_mdot_minus_2c_is_skew_symmetric(B, dB):
    h = 1e-6
    Mdot = (np.array(mass_matrix(B + h * dB, PAPER_MODEL)) - np.array(mass_matrix(B - h * dB, PAPER_MODEL))) / (2 * h)
    N = Mdot - 2 * np.array(coriolis_matrix(B, dB, PAPER_MODEL))
    assert np.allclose(N, -N.T, atol=1e-7)


def test_platform_at_rest_under_gravity_accelerates_as_hand_derived():
    # B = 0, xd = 0, u = 0: M xdd = -G. Hand-solved with the exact M (M12 = (m1-m3)/sqrt3 etc.).
    p = PAPER_MODEL
    xdd = task_acceleration(0.0, 0.0, 0.0, 0.0, 0.0, p)
    M = np.array(mass_matrix(0.0, p))
    assert np.allclose(M @ np.array(xdd), [0.0, -p.m_p * p.g, 0.0], atol=1e-12)
    assert xdd[1] == pytest.approx(-p.m_p * p.g / (p.m_p + (p.m_1 + p.m_3) / 3), rel=1e-3)


def test_energy_is_conserved_without_force_and_friction():
    """Thrown upwards at 1.79 m/s, the platform rises and falls back in 1 s, and gravity
    drives B to 0.42 rad through the configuration-dependent M: every term of M, C and G
    takes part. RK4's global error at h = 0.1 ms is O((h w)^4) with w ~ 4 rad/s, ~1e-14;
    measured drift is 3e-15 of the largest kinetic energy. The bound 1e-10 leaves margin
    for round-off on other machines and still fails for any wrong term (a 1e-6 change
    of one M entry gives ~1e-7)."""
    p = PAPER_MODEL
    plant = PlantModel(p, IDEAL, (0.0, 0.0, 0.0), (0.05, 1.79, 0.0))
    E0 = energy(*plant.state[1:3], *plant.state[3:], p)
    worst, kmax = 0.0, 0.0
    for k in range(10000):
        plant.step(k * 1e-4, 1e-4, 0.0, 0.0, 0.0)
        X, Z, B, dX, dZ, dB = plant.state
        E = energy(Z, B, dX, dZ, dB, p)
        kmax = max(kmax, E - p.m_p * p.g * Z)
        worst = max(worst, abs(E - E0))
    assert abs(plant.state[2]) > 0.3  # the rotation really took part
    assert worst / kmax < 1e-10


@pytest.mark.parametrize("field,value,allowed", [
    ("m_p", -1.0, r"a number in \[1e-12, 1e\+06\]"), ("I_y", 0.0, r"a number in \[1e-12, 1e\+06\]"),
    ("L_1", 0.0, r"a number in \[1e-06, 1000\]")])
def test_invalid_model_parameters_are_named(field, value, allowed):
    with pytest.raises(ModelInputError, match=f"{field} = {value}.*{allowed}"):
        PlantModel(PAPER_MODEL._replace(**{field: value}), PlantConfig())


def test_model_params_validated_accepts_the_paper_values():
    assert ModelParams().validated() == PAPER_MODEL
