"""The plant model (tapmp/plant.py): non-idealities, integration and its fast right-hand side."""

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from tapmp import cmodel
from tapmp.errors import ModelInputError
from tapmp.params import PAPER_MODEL
from tapmp.plant import IDEAL, PlantConfig, PlantModel, quantize

finite = st.floats(allow_nan=False, allow_infinity=False)


def test_quantization_rounds_to_the_nearest_count():
    assert quantize(1.26e-7, 1e-7) == pytest.approx(1e-7)
    assert quantize(1.5e-7 + 1e-12, 1e-7) == pytest.approx(2e-7)
    assert quantize(-2.4e-7, 1e-7) == pytest.approx(-2e-7)
    assert quantize(1.234e-7, 0.0) == 1.234e-7


def test_friction_saturation_and_pulling_forces_are_as_documented():
    cfg = PlantConfig(c_v1=10.0, F_c1=2.0, v_s=1e-3, force_limit=100.0, k_pull=1000.0)
    plant = PlantModel(PAPER_MODEL, cfg)
    f = plant.joint_forces(500.0, 0.0, 0.0, (0.0, 1e-3, 0.0), (0.01, 0.0, 0.0))
    # F1: saturated 100 - viscous 10*0.01 - Coulomb 2*tanh(10) + pull 1000*(1e-3 - 0)
    assert f[0] == pytest.approx(100.0 - 0.1 - 2 * math.tanh(10.0) + 1.0)
    # mover 2: -(pull 12) + pull 23 = -1 + 1000*(0 - 1e-3) = -2; mover 3: -pull 23 = +1
    assert f[1] == pytest.approx(-2.0)
    assert f[2] == pytest.approx(1.0)


@pytest.mark.parametrize("field,value,allowed", [
    ("c_v2", -1.0, r"a number in \[0, 1e\+09\]"), ("encoder_resolution", -1e-7, r"a number in \[0, 1\]"),
    ("substeps", 0, r"an integer in \[1, 10000\]"), ("attraction_force", -1.0, r"a number in \[0, 1e\+06\]"),
    ("attraction_gap", 0.0, r"a number in \[1e-06, 1\]"), ("cogging_amplitude", -2.0, r"a number in \[0, 1e\+06\]"),
    ("cogging_pitch", 0.0, r"a number in \[1e-06, 1\]"), ("cogging_phase2", math.inf, r"a number in \[-1e\+06, 1e\+06\]"),
    ("k_pull", math.nan, r"a number in \[-1e\+12, 1e\+12\]")])
def test_invalid_plant_settings_are_named(field, value, allowed):
    with pytest.raises(ModelInputError, match=f"{field} = {value}.*{allowed}"):
        PlantModel(PAPER_MODEL, PlantConfig()._replace(**{field: value}))


def test_non_finite_force_is_refused_with_the_time():
    plant = PlantModel(PAPER_MODEL, PlantConfig())
    with pytest.raises(ModelInputError, match=r"F2 = nan at t = 0.5 s is invalid: allowed is a finite number"):
        plant.step(0.5, 1e-4, 0.0, float("nan"), 0.0)


def test_plant_refuses_to_leave_the_kinematic_domain():
    plant = PlantModel(PAPER_MODEL, IDEAL, (0.0, 0.0, 1.5), (0.0, 0.0, 200.0))
    with pytest.raises(ModelInputError, match=r"\|B\| < pi/2"):
        plant.step(0.0, 1e-3, 0.0, 0.0, 0.0)


@pytest.mark.slow
@given(X=finite.filter(lambda v: abs(v) < 0.05), Z=finite.filter(lambda v: abs(v) < 0.05),
       B=finite.filter(lambda v: abs(v) < 1.4), dX=finite.filter(lambda v: abs(v) < 2.0),
       dZ=finite.filter(lambda v: abs(v) < 2.0), dB=finite.filter(lambda v: abs(v) < 50.0),
       F=st.tuples(*[finite.filter(lambda v: abs(v) < 2000.0)] * 3),
       k_pull=st.sampled_from([0.0, 200.0, -500.0]), attraction=st.sampled_from([0.0, 20.0]),
       cogging=st.sampled_from([0.0, 3.0]), flex=st.sampled_from([0.0, 400.0]),
       z_f=finite.filter(lambda v: abs(v) < 1e-4), dz_f=finite.filter(lambda v: abs(v) < 1.0))
def test_fused_right_hand_side_is_bit_identical_to_the_composed_one(X, Z, B, dX, dZ, dB, F, k_pull,
                                                                     attraction, cogging, flex, z_f, dz_f):
    """step() integrates with the C model's fused right-hand side (tapmp_plant_rhs); it must be
    the same arithmetic as derivatives(), which composes the documented kinematics, friction and
    dynamics."""
    cfg = PlantConfig(k_pull=k_pull, attraction_force=attraction, attraction_gap=0.2, cogging_amplitude=cogging,
                      cogging_phase1=0.3, cogging_phase2=-1.0, cogging_phase3=2.0, flex_frequency=flex)
    plant = PlantModel(PAPER_MODEL, cfg, (0.001, -0.002, 0.01))
    lim = plant.cfg.force_limit
    held = [min(max(f, -lim), lim) for f in F]  # step() saturates the held command once
    ffi, lib = cmodel.load()
    ds = ffi.new("double[8]")
    lib.tapmp_plant_rhs(plant._pl, [X, Z, B, dX, dZ, dB, z_f, dz_f], held, ds)
    assert tuple(ds) == tuple(plant.derivatives([X, Z, B, dX, dZ, dB, z_f, dz_f], *F))


# --- disturbances: the force laws of docs/disturbances.md, against hand-derived values ---

def _forces(q, **cfg):
    """Net mover forces with zero command, at rest, at true motor positions q, start pose 0."""
    plant = PlantModel(PAPER_MODEL, IDEAL._replace(**cfg))
    return plant.joint_forces(0.0, 0.0, 0.0, q, (0.0, 0.0, 0.0))


def test_negative_k_pull_is_a_negative_stiffness_on_the_gaps():
    # gap 12 widened by 1 um (q2 - q1 = +1e-6), gap 23 unchanged (q3 - q2 = 0) with k_pull = -2000 N/m:
    # p12 = -2000 * 1e-6 = -2 mN: mover 1 pushed away from mover 2 (-), mover 2 pushed on (+)
    f = _forces((0.0, 1e-6, 1e-6), k_pull=-2000.0)
    assert f == pytest.approx((-2e-3, 2e-3, 0.0), rel=1e-9)


def test_attraction_pulls_adjacent_movers_together_with_an_inverse_square_law():
    # F_a = 10 N at g_a = 5 mm. Pair 12: the gap shrank by 1 mm (q1 = +1 mm): g = 4 mm, 10 (5/4)^2 = 15.625 N;
    # pair 23 unchanged: 10 N. Mover 1 pulled towards 2 (+15.625), mover 2: -15.625 + 10, mover 3: -10.
    f = _forces((1e-3, 0.0, 0.0), attraction_force=10.0, attraction_gap=5e-3)
    assert f == pytest.approx((15.625, -5.625, -10.0), rel=1e-12)
    # at the initial gaps: the bias, equal and opposite, sums to zero over the three movers
    assert _forces((0.0, 0.0, 0.0), attraction_force=10.0, attraction_gap=5e-3) == pytest.approx((10.0, 0.0, -10.0))


def test_attraction_stiffness_is_negative_minus_two_force_over_gap():
    # d/dg of F_a (g_a/g)^2 at g = g_a: -2 F_a / g_a = -2 * 10 / 5e-3 = -4000 N/m (central difference)
    d = 1e-9
    f_open = _forces((0.0, d, 0.0), attraction_force=10.0, attraction_gap=5e-3)[0]   # gap 12 widened by d
    f_shut = _forces((0.0, -d, 0.0), attraction_force=10.0, attraction_gap=5e-3)[0]
    assert (f_open - f_shut) / (2 * d) == pytest.approx(-4000.0, rel=1e-6)


def test_attraction_once_the_movers_touch_leaves_the_domain():
    plant = PlantModel(PAPER_MODEL, IDEAL._replace(attraction_force=10.0, attraction_gap=1e-6))
    assert all(math.isnan(f) for f in plant.joint_forces(0.0, 0.0, 0.0, (2e-6, 0.0, 0.0), (0.0,) * 3)[:2])
    plant.state = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    with pytest.raises(ModelInputError, match=r"plant state .* finite values"):
        plant.step(0.0, 1e-4, 1e5, 0.0, 0.0)  # mover 1 driven into mover 2 within the step


def test_cogging_is_periodic_in_each_motor_position_with_its_phase():
    # A = 3 N, pitch 24 mm, phases (0, pi/2, pi): q = (6 mm, 0, 2 mm)
    # F1 = 3 sin(2 pi 6/24) = 3 sin(pi/2) = 3; F2 = 3 sin(pi/2) = 3; F3 = 3 sin(2 pi/12 + pi) = -1.5
    cfg = dict(cogging_amplitude=3.0, cogging_pitch=0.024, cogging_phase1=0.0, cogging_phase2=math.pi / 2,
               cogging_phase3=math.pi)
    assert _forces((6e-3, 0.0, 2e-3), **cfg) == pytest.approx((3.0, 3.0, -1.5), rel=1e-12, abs=1e-12)
    # one pitch further on every motor: the same forces
    assert _forces((30e-3, 24e-3, 26e-3), **cfg) == pytest.approx((3.0, 3.0, -1.5), rel=1e-9, abs=1e-12)


def test_disturbances_are_off_by_default_and_the_default_forces_are_unchanged():
    d = PlantConfig()
    assert (d.attraction_force, d.cogging_amplitude, d.k_pull) == (0.0, 0.0, 200.0)
    plant = PlantModel(PAPER_MODEL, d)
    # friction 5 N s/m, 2 N tanh, pulling 200 N/m as before: at dq1 = 1 mm/s, gap 12 widened by 1 um
    f = plant.joint_forces(0.0, 0.0, 0.0, (0.0, 1e-6, 1e-6), (1e-3, 0.0, 0.0))
    assert f == pytest.approx((-5e-3 - 2.0 * math.tanh(1.0) + 2e-4, -2e-4, 0.0), rel=1e-12)
