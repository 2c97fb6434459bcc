"""Control laws: SC-DC (Eq. 15-26), APD-DC (Eq. 38-39) and the discrete controller."""

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from tapmp.control import (APDDC, SCDC, ControllerModel, Gains, apd_command, feedforward, scdc_command,
                           sync_deviation, sync_errors)
from tapmp.errors import ModelInputError
from tapmp.kinematics import inverse, joint_velocity
from tapmp.params import PAPER_MODEL, gain_preset
from tapmp.plant import IDEAL, PlantModel
from tapmp.trajectory import TrajectoryParams, reference

G = Gains((2.0, 3.0, 4.0), (0.5, 0.6, 0.7), (10.0, 20.0, 30.0), (100.0, 200.0, 300.0), (1e-4, 2e-4, 5e-5))
errs = st.floats(-1e-3, 1e-3)


@given(errs, errs, errs)
def test_synchronization_error_and_its_deviation_sum_to_zero(e1, e2, e3):
    es = sync_errors(e1, e2, e3)
    assert sum(es) == pytest.approx(0.0, abs=1e-18)
    assert sum(sync_deviation(*es)) == pytest.approx(0.0, abs=1e-18)


def test_sync_errors_and_deviation_by_hand():
    # e = (3, 1, -2) um: es = (2, 3, -5) um (Eq. 18); c = (2+5, 3-2, -5-3) = (7, 1, -8) um (Eq. 21)
    es = sync_errors(3e-6, 1e-6, -2e-6)
    assert es == pytest.approx((2e-6, 3e-6, -5e-6))
    assert sync_deviation(*es) == pytest.approx((7e-6, 1e-6, -8e-6))


def test_scdc_command_by_hand():
    e, de, c, integ, u_d = (1e-6, 2e-6, 3e-6), (1e-3, 0.0, -1e-3), (7e-6, 1e-6, -8e-6), (1e-7, 0.0, 2e-7), (10.0, 20.0, 30.0)
    # motor 1: e_c = 1e-6 + 10*1e-7 = 2e-6; de_c = 1e-3 + 10*7e-6 = 1.07e-3; n = 1.07e-3 + 100*2e-6 = 1.27e-3
    #          u = 1e-4*10 + 0.5*1.27e-3 + 2*7e-6 = 1e-3 + 6.35e-4 + 1.4e-5 = 1.649e-3
    # motor 2: e_c = 2e-6; de_c = 0 + 20*1e-6 = 2e-5; n = 2e-5 + 200*2e-6 = 4.2e-4
    #          u = 2e-4*20 + 0.6*4.2e-4 + 3*1e-6 = 4e-3 + 2.52e-4 + 3e-6 = 4.255e-3
    # motor 3: e_c = 3e-6 + 30*2e-7 = 9e-6; de_c = -1e-3 + 30*(-8e-6) = -1.24e-3; n = -1.24e-3 + 300*9e-6 = 1.46e-3
    #          u = 5e-5*30 + 0.7*1.46e-3 + 4*(-8e-6) = 1.5e-3 + 1.022e-3 - 3.2e-5 = 2.49e-3
    assert scdc_command(e, de, c, integ, u_d, G) == pytest.approx((1.649e-3, 4.255e-3, 2.49e-3), rel=1e-12)


def test_apd_command_is_eq38():
    e, de, u_d = (1e-6, 2e-6, 3e-6), (1e-3, 0.0, -1e-3), (10.0, 20.0, 30.0)
    # u_i = K_T u_d + k_v de + k_p e
    expected = (1e-3 + 0.5e-3 + 2e-6, 4e-3 + 0.0 + 6e-6, 1.5e-3 - 0.7e-3 + 12e-6)
    assert apd_command(e, de, u_d, G) == pytest.approx(expected, rel=1e-12)


def test_scdc_with_zero_coupling_reduces_to_pd_on_e():
    # b = 0, Lambda_p = 0: u = K_T u_d + Lambda_v (de + D e) -- APD-DC with k_p = Lambda_v D.
    g0 = G._replace(b=(0.0,) * 3, Lambda_p=(0.0,) * 3)
    e, de, u_d = (1e-6, -2e-6, 3e-6), (1e-3, 2e-3, -1e-3), (1.0, 2.0, 3.0)
    matched = G._replace(Lambda_p=tuple(v * d for v, d in zip(G.Lambda_v, G.D)))
    assert scdc_command(e, de, (5e-6, 1e-6, -6e-6), (1.0, 1.0, 1.0), u_d, g0) == \
        pytest.approx(apd_command(e, de, u_d, matched), rel=1e-12)


def _controller(law=SCDC, velocity_source=0, gains=G):
    return ControllerModel(PAPER_MODEL, gains, law, velocity_source)


def test_integral_of_c_is_a_right_rectangle_sum_over_samples():
    ctl = _controller()
    ref = (0.0,) * 9
    h = 1e-4
    q_seq = [(1e-6, 0.0, 0.0), (2e-6, 0.0, -1e-6), (0.0, 3e-6, 0.0)]
    expected = [0.0, 0.0, 0.0]
    for q in q_seq:
        e = tuple(-x for x in q)
        c = sync_deviation(*sync_errors(*e))
        expected = [expected[i] + h * c[i] for i in range(3)]
        ctl.sample(0.0, h, ref, q, (0.0, 0.0, 0.0))
        assert ctl.integral == pytest.approx(expected, rel=1e-12, abs=1e-20)
    assert ctl.q_prev == q_seq[-1]


def test_velocity_is_the_backward_difference_after_the_first_sample():
    ctl = _controller(gains=G._replace(Lambda_p=(0.0,) * 3, b=(0.0,) * 3, D=(0.0,) * 3))
    ref = (0.0,) * 9
    ctl.sample(0.0, 1e-4, ref, (0.0, 0.0, 0.0), (5.0, 5.0, 5.0))  # first sample uses dq inputs
    F, u, e, es = ctl.sample(1e-4, 1e-4, ref, (1e-6, 1e-6, 1e-6), (5.0, 5.0, 5.0))
    ud = feedforward((1e-6,) * 3, (1e-2,) * 3, (0.0,) * 3, (0.0,) * 3, PAPER_MODEL)
    # de = 0 - (1e-6 / 1e-4) = -1e-2 m/s, independent of the dq inputs
    assert u == pytest.approx(tuple(G.K_T[i] * ud[i] + G.Lambda_v[i] * -1e-2 for i in range(3)), rel=1e-12)
    assert F == pytest.approx(tuple(u[i] / G.K_T[i] for i in range(3)), rel=1e-15)


def test_law_1_is_apd_dc_with_the_same_feedforward():
    ref = reference(0.3, TrajectoryParams())
    q, dq = (1e-3, 2e-3, 1.5e-3), (0.01, 0.02, 0.0)
    ctl = _controller(law=APDDC, velocity_source=1)
    F, u, e, es = ctl.sample(0.3, 1e-4, ref, q, dq)
    qd = inverse(*ref[:3], PAPER_MODEL.L_1)
    dqd = joint_velocity(ref[2], *ref[3:6], PAPER_MODEL.L_1)
    e_hand = tuple(qd[i] - q[i] for i in range(3))
    de_hand = tuple(dqd[i] - dq[i] for i in range(3))
    ud = feedforward(q, dq, ref[3:6], ref[6:9], PAPER_MODEL)
    assert e == pytest.approx(e_hand, rel=1e-12)
    assert u == pytest.approx(apd_command(e_hand, de_hand, ud, G), rel=1e-12)


@pytest.mark.parametrize("t", [0.0, 0.37, 1.1, 2.0])
def test_feedforward_is_the_exact_inverse_of_the_plant_dynamics(t):
    """Model on the trajectory, feedback gains 0: F = u_d / K_T gives the plant xdd = xdd_d."""
    gains = Gains((0.0,) * 3, (0.0,) * 3, (0.0,) * 3, (0.0,) * 3, (4.1e-5,) * 3)
    ref = reference(t, TrajectoryParams())
    plant = PlantModel(PAPER_MODEL, IDEAL, ref[:3], ref[3:6])
    ctl = ControllerModel(PAPER_MODEL, gains, SCDC, velocity_source=1)
    F = ctl.sample(t, 1e-4, ref, plant.joint_positions(), plant.joint_velocities(), advance=False)[0]
    xdd = plant.derivatives(plant.state, *F)[3:]
    for got, want in zip(xdd, ref[6:9]):
        assert got == pytest.approx(want, rel=1e-9, abs=1e-12)


@pytest.mark.parametrize("kwargs,match", [
    ({"gains": G._replace(K_T=(0.0, 1e-5, 1e-5))}, r"K_T1 = 0.0 is invalid: allowed is a finite number > 0"),
    ({"gains": G._replace(Lambda_v=(1.0, -1.0, 1.0))}, r"Lambda_v2 = -1.0 .* >= 0"),
    ({"law": 2}, r"law = 2 is invalid: allowed is 0 \(SC-DC\) or 1 \(APD-DC\)"),
    ({"velocity_source": 3}, r"velocity_source = 3 is invalid"),
])
def test_invalid_controller_settings_are_named(kwargs, match):
    with pytest.raises(ModelInputError, match=match):
        _controller(**kwargs)


def test_non_finite_input_and_bad_pose_are_named_with_the_time():
    ctl = _controller()
    with pytest.raises(ModelInputError, match=r"q2 = nan at t = 0.25 s"):
        ctl.sample(0.25, 1e-4, (0.0,) * 9, (0.0, math.nan, 0.0), (0.0,) * 3)
    with pytest.raises(ModelInputError, match=r"allowed is \|value\| < 1"):
        ctl.sample(0.25, 1e-4, (0.0,) * 9, (0.0, 0.06, 0.0), (0.0,) * 3)


def test_presets_hold_the_paper_gains():
    assert gain_preset("paper_simulation")["Lambda_v"] == (150.0, 158.5, 108.5)  # Eq. 40
    assert gain_preset("paper_experiment")["K_T"] == (3e-5, 3e-5, 3e-5)          # Eq. 42
    with pytest.raises(ValueError, match="allowed are default, paper_experiment, paper_simulation"):
        gain_preset("fast")
