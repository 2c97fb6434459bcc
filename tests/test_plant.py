"""The plant model (tapmp/plant.py): non-idealities, integration and its fast right-hand side."""

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

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
    ("c_v2", -1.0, ">= 0"), ("encoder_resolution", -1e-7, ">= 0"), ("substeps", 0, "integer >= 1")])
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


@given(X=finite.filter(lambda v: abs(v) < 0.05), Z=finite.filter(lambda v: abs(v) < 0.05),
       B=finite.filter(lambda v: abs(v) < 1.4), dX=finite.filter(lambda v: abs(v) < 2.0),
       dZ=finite.filter(lambda v: abs(v) < 2.0), dB=finite.filter(lambda v: abs(v) < 50.0),
       F=st.tuples(*[finite.filter(lambda v: abs(v) < 2000.0)] * 3),
       k_pull=st.sampled_from([0.0, 200.0]))
def test_fused_right_hand_side_is_bit_identical_to_the_composed_one(X, Z, B, dX, dZ, dB, F, k_pull):
    """step() integrates with a fused closure for speed; it must be the same arithmetic
    as derivatives(), which composes the documented kinematics, friction and dynamics."""
    plant = PlantModel(PAPER_MODEL, PlantConfig(k_pull=k_pull), (0.001, -0.002, 0.01))
    lim = plant.cfg.force_limit
    held = [min(max(f, -lim), lim) for f in F]  # step() saturates the held command once
    assert plant._rhs(X, Z, B, dX, dZ, dB, *held) == tuple(plant.derivatives([X, Z, B, dX, dZ, dB], *F))
