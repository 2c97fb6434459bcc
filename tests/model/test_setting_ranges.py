"""Every setting's range is one rule of the settings table (tapmp.interface), checked by the C
model's generated tapmp_<model>_settings_check: the Python classes raise its verdict as
ModelInputError with the value as the caller gave it, in the order of the FMU variables, and the
clock's warning texts are the C model's too."""

import math

import pytest

from tapmp import cmodel
from tapmp.control import ControllerModel, Gains, ModalGains
from tapmp.errors import KinematicDomainError, ModelInputError
from tapmp.interface import PLANT, SETTINGS_STRUCT, VARIABLES
from tapmp.params import PAPER_MODEL, ModelParams, gain_preset
from tapmp.plant import PlantConfig, PlantModel
from tapmp.trajectory import TrajectoryParams

GAINS = Gains.from_preset(gain_preset("default"))


def message(make) -> str:
    with pytest.raises(ModelInputError) as err:
        make()
    return str(err.value)


@pytest.mark.parametrize("make, text", [
    (lambda: ModelParams(I_y=0).validated(), "I_y = 0 is invalid: allowed is a number in [1e-12, 1e+06]"),
    (lambda: ModelParams(m_2=math.inf, g=-1.0).validated(), "m_2 = inf is invalid: allowed is a number in "
     "[1e-12, 1e+06]"),
    (lambda: GAINS._replace(D=(1.0, -2, 1.0)).validated(), "D2 = -2 is invalid: allowed is a number in [0, 1e+09]"),
    (lambda: GAINS._replace(D=(2e9, 1.0, 1.0)).validated(), "D1 = 2000000000.0 is invalid: allowed is a number in "
     "[0, 1e+09]"),
    (lambda: GAINS._replace(K_T=(1.0, 1.0, 0.0)).validated(), "K_T3 = 0.0 is invalid: allowed is a number in "
     "[1e-12, 1e+12]"),
    (lambda: ModalGains(kv_d=math.nan).validated(), "kv_d = nan is invalid: allowed is a number in [0, 1e+15]"),
    (lambda: ControllerModel(PAPER_MODEL, GAINS, law=3), "law = 3 is invalid: allowed is 0 (SC-DC), 1 (APD-DC) "
     "or 2 (PID-DC)"),
    (lambda: ControllerModel(PAPER_MODEL, GAINS, velocity_source=2), "velocity_source = 2 is invalid: allowed is "
     "0 (backward difference of q) or 1 (dq inputs)"),
    (lambda: ControllerModel(PAPER_MODEL, GAINS, force_limit=-1.0), "force_limit = -1.0 is invalid: allowed is "
     "a number in [0, 1e+09]"),
    (lambda: ControllerModel(PAPER_MODEL, GAINS, T_s=0.0), "T_s = 0.0 is invalid: allowed is a number in "
     "[1e-09, 1000]"),
    (lambda: PlantConfig(v_s=0.0).validated(), "v_s = 0.0 is invalid: allowed is a number in [1e-12, 1000]"),
    (lambda: PlantConfig(substeps=2.0).validated(), "substeps = 2.0 is invalid: allowed is an integer in [1, 10000]"),
    # in the order of the FMU variables, then the relation between settings
    (lambda: TrajectoryParams(radius=-1.0, X_a=math.nan).validated(), "radius = -1.0 is invalid: allowed is a "
     "number in [0, 1]"),
    (lambda: TrajectoryParams(profile=7, j_max_B=0.0).validated(), "profile = 7 is invalid: allowed is 0 (circle "
     "and sinusoid), 1 (step), 2 (ramp) or 3 (S-curve)"),
    (lambda: TrajectoryParams(j_max_B=0.0, B_offset=1.0, B_amplitude=0.6).validated(), "j_max_B = 0.0 is invalid: "
     "allowed is a number in [1e-12, 1e+09]"),
    (lambda: TrajectoryParams(B_offset=1.0, B_amplitude=0.6).validated(), "B_amplitude = 0.6 is invalid: allowed "
     "is |B_offset| + B_amplitude < pi/2 rad (kinematic domain)"),
    (lambda: TrajectoryParams(B_b=-2.0).validated(), "B_b = -2.0 is invalid: allowed is a number in [-1.5, 1.5]"),
])
def test_the_first_setting_out_of_range_is_named_with_its_value_and_what_is_allowed(make, text):
    assert message(make) == text


@pytest.mark.parametrize("pose0, rate0, text", [
    ((0.0, math.nan, 2.0), (0.0, 0.0, 0.0), "Z0 = nan is invalid: allowed is a number in [-1, 1]"),
    ((0.0, 0.0, 0.0), (0.0, 0.0, math.inf), "dB0 = inf is invalid: allowed is a number in [-1000, 1000]"),
    ((0.0, 0.0, -2), (0.0, 0.0, 0.0), "B0 = -2 is invalid: allowed is a number in [-1.5, 1.5]"),
])
def test_the_plants_initial_state_is_checked_within_its_ranges(pose0, rate0, text):
    assert message(lambda: PlantModel(PAPER_MODEL, PlantConfig(), pose0, rate0)) == text


def test_a_reference_outside_the_kinematic_domain_is_a_kinematic_domain_error():
    with pytest.raises(KinematicDomainError):
        TrajectoryParams(B_offset=1.0, B_amplitude=0.6).validated()


def test_every_pose_setting_allowed_by_its_range_lies_inside_the_kinematic_domain():
    """|B| < pi/2 (Eq. 1) needs no check of its own: the ranges of B0, B_a, B_b, B_offset keep them inside."""
    for table in VARIABLES.values():
        for v in table:
            if v.name in ("B0", "B_a", "B_b", "B_offset"):
                assert -math.pi / 2 < v.min and v.max < math.pi / 2


def test_the_settings_struct_is_filled_by_field_name_from_the_table():
    """Each parameter lands in its own member (Var.field) of the C settings struct: set one
    parameter to a marker and read it back by the field the table names."""
    for v in VARIABLES[PLANT]:
        if v.causality != "parameter":
            continue
        marker = int(v.max) if v.type == "Integer" else v.max
        s = cmodel.settings(PLANT, {v.name: marker})
        member = s
        for part in v.field.replace("]", "").replace("[", ".").split("."):
            member = member[int(part)] if part.isdigit() else getattr(member, part)
        assert member == marker, v.name
    assert cmodel.load()[0].typeof(cmodel.settings(PLANT, {})).cname == f"{SETTINGS_STRUCT[PLANT]} *"


def test_settings_inside_every_range_pass_unchanged():
    tp = TrajectoryParams(profile=3, B_a=1.5, B_b=-1.5, radius=0.0)
    assert tp.validated() is tp
    assert ModalGains(0.0, 0.0, 0.0, 0.0, 0.0, 0.0).validated() == (0.0,) * 6


REF = (0.0,) * 9  # the desired pose and its rates: the origin at rest


def test_the_clock_warnings_are_the_c_models_texts():
    """A host that steps 2 T_s: one warning naming the interval; one that passes an instant off
    the grid: one warning naming the instant missed (texts from tapmp_clock_*_text)."""
    q = (0.0, 0.0, 0.0)
    skipping = ControllerModel(PAPER_MODEL, GAINS, T_s=1e-4)
    assert skipping.communication_point(0.0, 2e-4, REF, q, q)[1] is None
    out, warning = skipping.communication_point(2e-4, 2e-4, REF, q, q)
    assert out is not None and skipping.k_last == 2 and skipping.warned
    assert warning == ("the host's communication points skip sample instants of T_s = 0.0001 s: the controller "
                       "sampled at t = 0.0002 s, 0.0002 s (2 T_s) after its previous sample, and uses that "
                       "interval for the velocity estimate and the integral (it samples only at communication "
                       "points on its grid t0 + k T_s)")
    assert skipping.communication_point(4e-4, 2e-4, REF, q, q)[1] is None  # once per instance
    missing = ControllerModel(PAPER_MODEL, GAINS, T_s=1e-4)
    missing.communication_point(0.0, 1.5e-4, REF, q, q)
    held, warning = missing.communication_point(1.5e-4, 1.5e-4, REF, q, q)
    assert held is None and warning == (  # between instants, past the instant 1e-4 s
        "the host's communication points skip sample instants of T_s = 0.0001 s: none fell on the sample instant "
        "t = 0.0001 s; at t = 0.00015 s the controller holds its command until a communication point falls on "
        "its grid t0 + k T_s")
    assert missing.communication_point(4.5e-4, 1.5e-4, REF, q, q) == (None, None)  # off the grid, warned once
