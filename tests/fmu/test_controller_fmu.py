"""TAPMP_Controller.fmu and TAPMP_Trajectory.fmu through fmpy."""

import math

import pytest
from tests.support.fmus import call_status

from tapmp.control import ControllerModel, Gains
from tapmp.interface import CONTROLLER, TRAJECTORY, VARIABLES
from tapmp.kinematics import inverse
from tapmp.params import PAPER_MODEL, gain_preset
from tapmp.trajectory import TrajectoryParams, reference

REF = ("X_d", "Z_d", "B_d", "dX_d", "dZ_d", "dB_d", "ddX_d", "ddZ_d", "ddB_d")
OUTS = tuple(f"{n}{i}" for n in ("F", "u", "e", "es") for i in (1, 2, 3))


def inputs(k):
    t = k * 1e-4
    ref = reference(t, TrajectoryParams())
    q = inverse(*ref[:3], 0.09)
    q = (q[0] + 1e-6 * math.sin(30 * t), q[1] - 2e-6 * math.cos(20 * t), q[2] + 5e-7)
    return ref, q, (0.01, 0.02, -0.01)


@pytest.mark.parametrize("law", [0, 1])
def test_controller_fmu_reproduces_the_plain_controller(built, load_fmu, law):
    fmu = load_fmu(built[CONTROLLER])
    ref, q, dq = inputs(0)
    fmu.set(law=law, **dict(zip(REF, ref)), q1=q[0], q2=q[1], q3=q[2], dq1=dq[0], dq2=dq[1], dq3=dq[2])
    fmu.init()
    model = ControllerModel(PAPER_MODEL, Gains.from_preset(gain_preset("default")), law)
    F0 = model.sample(0.0, 1e-4, ref, q, dq, advance=False)[0]
    assert fmu.get("F1", "F2", "F3") == pytest.approx(F0, rel=1e-12)
    worst = 0.0
    for k in range(200):
        ref, q, dq = inputs(k)
        fmu.set(**dict(zip(REF, ref)), q1=q[0], q2=q[1], q3=q[2], dq1=dq[0], dq2=dq[1], dq3=dq[2])
        fmu.slave.doStep(k * 1e-4, 1e-4)
        F, u, e, es = model.sample(k * 1e-4, 1e-4, ref, q, dq)
        got = fmu.get(*OUTS)
        worst = max(worst, max(abs(a - b) / max(1.0, abs(b)) for a, b in zip(got, (*F, *u, *e, *es))))
    assert worst <= 1e-12


def test_controller_rollback_restores_integral_and_previous_sample(built, load_fmu):
    fmu = load_fmu(built[CONTROLLER])
    fmu.init()
    for k in range(30):
        ref, q, dq = inputs(k)
        fmu.set(**dict(zip(REF, ref)), q1=q[0], q2=q[1], q3=q[2])
        fmu.slave.doStep(k * 1e-4, 1e-4)
    state = fmu.slave.getFMUstate()

    def run():
        out = []
        for k in range(30, 80):
            ref, q, dq = inputs(k)
            fmu.set(**dict(zip(REF, ref)), q1=q[0], q2=q[1], q3=q[2])
            fmu.slave.doStep(k * 1e-4, 1e-4)
            out.append(fmu.get(*OUTS))
        return out
    first = run()
    fmu.slave.setFMUstate(state)
    assert run() == first


def test_retuned_gain_takes_effect_at_the_next_sample(built, load_fmu):
    fmu = load_fmu(built[CONTROLLER])
    fmu.init(law=1, velocity_source=1)
    ref, q, dq = inputs(5)
    fmu.set(**dict(zip(REF, ref)), q1=q[0], q2=q[1], q3=q[2], dq1=0.0, dq2=0.0, dq3=0.0)
    fmu.slave.doStep(0.0, 1e-4)
    u_before, e1 = fmu.get("u1", "e1")
    fmu.set(Lambda_p1=1000.0)
    fmu.slave.doStep(1e-4, 1e-4)
    u_after = fmu.get("u1")[0]
    assert u_after - u_before == pytest.approx((1000.0 - 300.0) * e1, rel=1e-9)


@pytest.mark.parametrize("name,value,fails_in,allowed", [
    ("K_T2", 0.0, "enterInitializationMode", "K_T2 = 0.0 is invalid: allowed is a number in [1e-12, 1e+12]"),
    ("Lambda_v1", -1.0, "enterInitializationMode",
     "Lambda_v1 = -1.0 is invalid: allowed is a number in [0, 1e+12]"),
    ("law", 3, "enterInitializationMode", "law = 3 is invalid: allowed is 0 (SC-DC), 1 (APD-DC) or 2 (PID-DC)"),
    ("velocity_source", -1, "enterInitializationMode", "velocity_source = -1 is invalid"),
    ("q2", 0.06, "exitInitializationMode", "allowed is |value| < 1"),
    ("dq3", float("inf"), "set", "dq3 = inf at t = 0 s is invalid: allowed is a finite number")])
def test_bad_input_is_fmi2Error_at_the_call_that_receives_it(built, load_fmu, name, value, fails_in, allowed):
    fmu = load_fmu(built[CONTROLLER])
    statuses = fmu.statuses(**{name: value})
    first = next(call for call, status in statuses.items() if status != 0)
    assert (first, statuses[first]) == (fails_in, 3), statuses
    assert statuses["doStep"] == 3, statuses  # and the instance refuses to go on
    text = "\n".join(fmu.errors())
    assert allowed in text and "t = 0 s" in text, text
    assert all(math.isfinite(v) for v in fmu.get(*OUTS))


def test_trajectory_fmu_outputs_the_reference_at_the_end_of_each_step(built, load_fmu):
    fmu = load_fmu(built[TRAJECTORY])
    fmu.init(f_B=0.18)
    tp = TrajectoryParams(f_B=0.18)
    assert fmu.get(*REF) == pytest.approx(reference(0.0, tp), abs=1e-15)
    for k in range(50):
        fmu.slave.doStep(k * 1e-4, 1e-4)
    r = reference(49 * 1e-4 + 1e-4, tp)
    assert fmu.get(*REF) == pytest.approx(r, rel=1e-12, abs=1e-15)
    assert fmu.get("q1_d", "q2_d", "q3_d") == pytest.approx(inverse(*r[:3], 0.09), rel=1e-12, abs=1e-15)


def test_parameters_set_in_initialization_mode_reach_the_outputs_read_there(built, load_fmu):
    """Ecos sets parameters after fmi2EnterInitializationMode and propagates the outputs
    it reads before fmi2ExitInitializationMode: they must already use those parameters."""
    fmu = load_fmu(built[TRAJECTORY])
    fmu.slave.setupExperiment(startTime=0.0)
    fmu.slave.enterInitializationMode()
    default_Z = fmu.get("Z_d")[0]
    fmu.set(Z_c=-0.02, radius=0.005)               # phase 0: the top of the circle
    assert default_Z != pytest.approx(-0.015)
    assert fmu.get("Z_d")[0] == pytest.approx(-0.015, abs=1e-15)
    fmu.set(radius=-1.0)                            # invalid: outputs keep the last valid set
    assert fmu.get("Z_d")[0] == pytest.approx(-0.015, abs=1e-15)
    fmu.set(radius=0.004)
    assert fmu.get("Z_d")[0] == pytest.approx(-0.016, abs=1e-15)
    fmu.slave.exitInitializationMode()
    assert fmu.get("Z_d")[0] == pytest.approx(-0.016, abs=1e-15) and fmu.errors() == []


def test_invalid_parameter_set_in_initialization_mode_fails_at_exit(built, load_fmu):
    fmu = load_fmu(built[TRAJECTORY])
    fmu.slave.setupExperiment(startTime=0.0)
    fmu.slave.enterInitializationMode()
    fmu.set(radius=-1.0)
    assert fmu.errors() == []  # maybe a master's half-way point: not an error yet
    assert call_status(fmu.slave.exitInitializationMode) == 3
    assert any("radius = -1" in m for m in fmu.errors())


def test_controller_reports_its_command_in_initialization_mode_once_inputs_are_set(built, load_fmu):
    """fmpy's container runtime copies each connection once in Initialization Mode and then
    leaves it: the F it passes to the plant is the one read there."""
    fmu = load_fmu(built[CONTROLLER])
    ref, q, dq = inputs(0)
    fmu.slave.setupExperiment(startTime=0.0)
    fmu.slave.enterInitializationMode()
    model = ControllerModel(PAPER_MODEL, Gains.from_preset(gain_preset("default")), 0)
    # inputs at their start values: the paper run's initial reference, encoder positions and velocities
    start = [v.start for v in VARIABLES[CONTROLLER] if v.causality == "input"]
    zero = model.sample(0.0, 1e-4, start[:9], start[9:12], start[12:15], advance=False)[0]
    assert fmu.get("F1", "F2", "F3") == pytest.approx(zero, rel=1e-12)
    fmu.set(**dict(zip(REF, ref)), q1=q[0], q2=q[1], q3=q[2], dq1=dq[0], dq2=dq[1], dq3=dq[2])
    in_init = fmu.get("F1", "F2", "F3")
    F0 = model.sample(0.0, 1e-4, ref, q, dq, advance=False)[0]
    assert F0 != pytest.approx(zero, rel=1e-3)
    assert in_init == pytest.approx(F0, rel=1e-12) and min(map(abs, F0)) > 1.0
    fmu.set(Lambda_p1=600.0)                                     # a parameter changes it again
    assert fmu.get("F1")[0] != pytest.approx(in_init[0], rel=1e-6)
    fmu.set(Lambda_p1=gain_preset("default")["Lambda_p"][0])
    fmu.slave.exitInitializationMode()
    assert fmu.get("F1", "F2", "F3") == in_init


PID_GAINS = dict(kp_c=500.0, kv_c=0.5, ki_c=3000.0, kp_d=2000.0, kv_d=0.8, ki_d=90000.0)


@pytest.mark.parametrize("family", ["python", "native"])
def test_controller_fmu_law_2_is_pid_dc_in_both_families(built, native_built, load_fmu, family):
    """law = 2 with the six modal gains set: the FMU's commands and errors follow the plain
    PID-DC controller (tapmp.control.ControllerModel with law PIDDC, integral of e) over 200 samples."""
    from tapmp.control import PIDDC, ModalGains
    path = built[CONTROLLER] if family == "python" else native_built["fmi2"][CONTROLLER]
    fmu = load_fmu(path)
    ref, q, dq = inputs(0)
    fmu.set(law=2, **PID_GAINS, **dict(zip(REF, ref)), q1=q[0], q2=q[1], q3=q[2], dq1=dq[0], dq2=dq[1], dq3=dq[2])
    fmu.init()
    model = ControllerModel(PAPER_MODEL, Gains.from_preset(gain_preset("default")), PIDDC, modal=ModalGains(**PID_GAINS))
    worst = 0.0
    for k in range(200):
        ref, q, dq = inputs(k)
        fmu.set(**dict(zip(REF, ref)), q1=q[0], q2=q[1], q3=q[2], dq1=dq[0], dq2=dq[1], dq3=dq[2])
        fmu.slave.doStep(k * 1e-4, 1e-4)
        F, u, e, es = model.sample(k * 1e-4, 1e-4, ref, q, dq)
        worst = max(worst, max(abs(a - b) / max(1.0, abs(b)) for a, b in zip(fmu.get(*OUTS), (*F, *u, *e, *es))))
    assert worst == 0.0  # both families run the same doubles as the plain model
    assert model.integral != [0.0, 0.0, 0.0]


@pytest.mark.parametrize("family", ["python", "native"])
@pytest.mark.parametrize("name,value,allowed", [
    ("ki_d", -1.0, "a number in [0, 1e+15]"), ("law", 3, "0 (SC-DC), 1 (APD-DC) or 2 (PID-DC)")])
def test_controller_fmu_refuses_bad_pid_dc_settings_naming_them(built, native_built, load_fmu, family, name,
                                                                value, allowed):
    path = built[CONTROLLER] if family == "python" else native_built["fmi2"][CONTROLLER]
    fmu = load_fmu(path)
    status = fmu.statuses(**{name: value})
    assert 3 in status.values()
    assert any(f"{name} = {value!r}" in m and allowed in m for m in fmu.errors()), fmu.errors()
