"""TAPMP_Plant.fmu through fmpy: same numbers as the plain model, rollback, bad input."""

import math
import zipfile

import pytest
from tests.support.fmus import call_status

from tapmp.interface import PLANT
from tapmp.params import PAPER_MODEL
from tapmp.plant import PlantConfig, PlantModel

OUTS = ("q1", "q2", "q3", "q1_true", "q2_true", "q3_true", "dq1", "dq2", "dq3", "X", "Z", "B", "dX", "dZ", "dB")


def forces(k):
    return 30.0 * math.sin(0.01 * k), 18.0 + 5.0 * math.cos(0.02 * k), -20.0 * math.sin(0.013 * k)


def test_fmu_bundles_the_model_package_and_declares_units(built):
    with zipfile.ZipFile(built[PLANT]) as z:
        names = z.namelist()
        md = z.read("modelDescription.xml").decode()
    assert "resources/tapmp/dynamics.py" in names and "resources/fmu_common/slave.py" in names
    assert '<Unit name="N">' in md and 'canGetAndSetFMUstate="true"' in md
    assert 'stepSize="0.0001"' in md and "<InitialUnknowns>" in md


def test_fmu_reproduces_the_plain_model(built, load_fmu):
    params = dict(X0=1e-3, Z0=-2e-3, B0=0.02, dX0=0.01, dB0=0.1, k_pull=300.0, substeps=2)
    fmu = load_fmu(built[PLANT])
    fmu.init(**params)
    cfg = PlantConfig(k_pull=300.0, substeps=2)
    model = PlantModel(PAPER_MODEL, cfg, (1e-3, -2e-3, 0.02), (0.01, 0.0, 0.1))
    worst = 0.0
    for k in range(300):
        F = forces(k)
        fmu.set(F1=F[0], F2=F[1], F3=F[2])
        fmu.slave.doStep(k * 1e-4, 1e-4)
        model.step(k * 1e-4, 1e-4, *F)
        expected = (*model.measured_positions(), *model.joint_positions(), *model.joint_velocities(), *model.state)
        worst = max(worst, max(abs(a - b) for a, b in zip(fmu.get(*OUTS), expected)))
    assert worst <= 1e-12


def test_state_rollback_replays_bit_identically(built, load_fmu):
    fmu = load_fmu(built[PLANT])
    fmu.init(dX0=0.02, dB0=0.2)
    for k in range(20):
        fmu.set(F1=forces(k)[0], F2=forces(k)[1], F3=forces(k)[2])
        fmu.slave.doStep(k * 1e-4, 1e-4)
    state = fmu.slave.getFMUstate()

    def run():
        out = []
        for k in range(20, 60):
            F = forces(k)
            fmu.set(F1=F[0], F2=F[1], F3=F[2])
            fmu.slave.doStep(k * 1e-4, 1e-4)
            out.append(fmu.get(*OUTS))
        return out

    first = run()
    fmu.slave.setFMUstate(state)
    assert run() == first
    fmu.slave.freeFMUstate(state)


def test_non_finite_force_is_refused_with_name_value_and_time(built, load_fmu):
    fmu = load_fmu(built[PLANT])
    fmu.init()
    fmu.slave.doStep(0.0, 1e-4)
    before = fmu.get("q1_true", "X")
    assert call_status(lambda: fmu.set(F1=float("nan"))) == 3
    assert any("F1 = nan at t = 0.0001 s is invalid: allowed is a finite number" in m
               for m in fmu.errors()), fmu.messages
    assert fmu.get("q1_true", "X") == before  # no NaN reached the outputs
    assert call_status(lambda: fmu.slave.doStep(1e-4, 1e-4)) == 3  # the instance refuses to go on


@pytest.mark.parametrize("name,value,allowed", [
    ("m_p", -1.0, "a number in [1e-12, 1e+06]"), ("I_y", 0.0, "a number in [1e-12, 1e+06]"), ("L_1", 0.0, "a number in [1e-06, 1000]"),
    ("c_v2", -0.5, "a number in [0, 1e+09]"), ("encoder_resolution", -1e-7, "a number in [0, 1]"),
    ("substeps", 0, "an integer in [1, 10000]"), ("B0", 1.6, "a number in [-1.5, 1.5]")])
def test_invalid_parameter_fails_initialization_with_a_clear_message(built, load_fmu, name, value, allowed):
    fmu = load_fmu(built[PLANT])
    statuses = fmu.statuses(**{name: value})
    assert statuses == {"set": 0, "setupExperiment": 0, "enterInitializationMode": 3,
                        "exitInitializationMode": 3, "doStep": 3}
    text = "\n".join(fmu.errors())
    assert f"{name} = {value!r}" in text and allowed in text and "t = 0 s" in text, text


def test_leaving_the_kinematic_domain_fails_the_step_and_keeps_finite_outputs(built, load_fmu):
    fmu = load_fmu(built[PLANT])
    fmu.init(B0=1.5, dB0=200.0, force_limit=0.0)
    assert call_status(lambda: fmu.slave.doStep(0.0, 1e-3)) == 3
    text = "\n".join(fmu.errors())
    assert "|B| < pi/2" in text and "t = 0.001 s" in text, text
    assert all(math.isfinite(v) for v in fmu.get(*OUTS))


DISTURBED = dict(k_pull=-400.0, attraction_force=8.0, attraction_gap=0.004, cogging_amplitude=3.0,
                 cogging_pitch=0.012, cogging_phase1=0.5, cogging_phase2=-1.0, cogging_phase3=2.5)


@pytest.mark.parametrize("family", ["python", "native"])
def test_fmu_disturbances_follow_the_plain_model_in_both_families(built, native_built, load_fmu, family):
    """Negative k_pull, attraction and cogging set through the FMU's parameters: the FMU steps the
    plain PlantModel's doubles (and the disturbances do move it: off, the path differs)."""
    path = built[PLANT] if family == "python" else native_built["fmi2"][PLANT]
    fmu = load_fmu(path)
    fmu.init(X0=1e-3, Z0=-2e-3, B0=0.02, dX0=0.01, dB0=0.1, **DISTURBED)
    model = PlantModel(PAPER_MODEL, PlantConfig(**DISTURBED), (1e-3, -2e-3, 0.02), (0.01, 0.0, 0.1))
    undisturbed = PlantModel(PAPER_MODEL, PlantConfig(), (1e-3, -2e-3, 0.02), (0.01, 0.0, 0.1))
    worst = 0.0
    for k in range(300):
        F = forces(k)
        fmu.set(F1=F[0], F2=F[1], F3=F[2])
        fmu.slave.doStep(k * 1e-4, 1e-4)
        model.step(k * 1e-4, 1e-4, *F)
        undisturbed.step(k * 1e-4, 1e-4, *F)
        expected = (*model.measured_positions(), *model.joint_positions(), *model.joint_velocities(), *model.state)
        worst = max(worst, max(abs(a - b) for a, b in zip(fmu.get(*OUTS), expected)))
    assert worst == 0.0
    assert max(abs(a - b) for a, b in zip(model.joint_positions(), undisturbed.joint_positions())) > 1e-7


@pytest.mark.parametrize("family", ["python", "native"])
@pytest.mark.parametrize("name,value,allowed", [
    ("attraction_gap", 0.0, "a number in [1e-06, 1]"), ("cogging_amplitude", -1.0, "a number in [0, 1e+06]"),
    ("k_pull", -2e12, "a number in [-1e+12, 1e+12]")])
def test_fmu_refuses_bad_disturbance_settings_naming_them(built, native_built, load_fmu, family, name, value,
                                                         allowed):
    path = built[PLANT] if family == "python" else native_built["fmi2"][PLANT]
    fmu = load_fmu(path)
    status = fmu.statuses(**{name: value})
    assert 3 in status.values()
    assert any(f"{name} = {value!r}" in m and allowed in m for m in fmu.errors()), fmu.errors()
