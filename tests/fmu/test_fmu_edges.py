"""Every FMU family behaves the same at every edge: the pythonfmu FMUs and the native FMI 2.0
FMUs return the same status at the same call with the same logged message, for bad
input, FMI state-machine misuse, overflow, a wrong GUID and corrupt FMU states. The
native FMI 3.0 FMUs are run through the same sequences where FMI 3.0 has the call."""

import ctypes
import math
import subprocess
import sys

import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave

from tests.support.fmus import call_status
from tapmp.interface import CONTROLLER, PLANT, TRAJECTORY

FAMILIES = ("python", "native")


def fmu_path(family, model, built, native_built):
    return built[model] if family == "python" else native_built["fmi2"][model]


def _init_step(fmu, steps=1, **params):
    fmu.init(**params)
    for k in range(steps):
        fmu.slave.doStep(k * 1e-4, 1e-4)


# (model, a function of the loaded FMU that runs a call sequence and returns the statuses)
SEQUENCES = {
    "non-finite input": (PLANT, lambda f: [call_status(lambda: _init_step(f)),
                                           call_status(lambda: f.set(F1=float("nan"))),
                                           call_status(lambda: f.slave.doStep(1e-4, 1e-4))]),
    "parameter model check": (PLANT, lambda f: list(f.statuses(m_p=-1.0).values())),
    "substeps above its bound": (PLANT, lambda f: list(f.statuses(substeps=20000).values())),
    "gain that overflows": (CONTROLLER, lambda f: list(f.statuses(Lambda_v1=1e308).values())),
    "K_T that overflows": (CONTROLLER, lambda f: list(f.statuses(K_T1=1e-320).values())),
    "tunable gain refused at set": (CONTROLLER, lambda f: [
        call_status(lambda: _init_step(f)), call_status(lambda: f.set(Lambda_p1=-5.0)),
        call_status(lambda: f.set(Lambda_p1=1e13)), call_status(lambda: f.slave.doStep(1e-4, 1e-4))]),
    "input that overflows the command": (CONTROLLER, lambda f: [
        call_status(lambda: _init_step(f)), call_status(lambda: f.set(ddX_d=1e308)),
        call_status(lambda: f.slave.doStep(1e-4, 1e-4)), f.get("F1", "F2", "F3")]),
    "kinematic domain of the measurement": (CONTROLLER, lambda f: list(f.statuses(q2=0.06).values())),
    "time that is not finite": (TRAJECTORY, lambda f: [call_status(lambda: f.init()),
                                                       call_status(lambda: f.slave.doStep(float("nan"), 1e-4))]),
    "time that does not continue the last step": (TRAJECTORY, lambda f: [
        call_status(lambda: _init_step(f, 3)), call_status(lambda: f.slave.doStep(0.5, 1e-4))]),
    "frequency that overflows": (TRAJECTORY, lambda f: list(f.statuses(f_xz=1e308).values())),
    "radius out of range": (TRAJECTORY, lambda f: list(f.statuses(radius=2.0).values())),
    "doStep in Initialization Mode": (PLANT, lambda f: [
        call_status(lambda: f.slave.setupExperiment(startTime=0.0)),
        call_status(f.slave.enterInitializationMode), call_status(lambda: f.slave.doStep(0.0, 1e-4))]),
    "doStep before initialization": (PLANT, lambda f: [call_status(lambda: f.slave.doStep(0.0, 1e-4))]),
    "calls after terminate": (PLANT, lambda f: [
        call_status(lambda: _init_step(f)), call_status(f.slave.terminate),
        call_status(lambda: f.slave.doStep(1e-4, 1e-4)), call_status(lambda: f.set(F1=1.0))]),
    "exit without enter": (PLANT, lambda f: [call_status(f.slave.exitInitializationMode)]),
    "enter in Step Mode": (PLANT, lambda f: [call_status(lambda: _init_step(f)),
                                             call_status(f.slave.enterInitializationMode)]),
    "output set": (PLANT, lambda f: [call_status(lambda: f.set(q1=1.0))]),
    "fixed parameter in Step Mode": (PLANT, lambda f: [call_status(lambda: _init_step(f)),
                                                       call_status(lambda: f.set(k_pull=10.0))]),
    "plant leaves the domain": (PLANT, lambda f: [call_status(lambda: f.init(B0=1.5, dB0=200.0, force_limit=0.0)),
                                                  call_status(lambda: f.slave.doStep(0.0, 1e-3)),
                                                  f.get("X", "B")]),
}


@pytest.mark.parametrize("case", sorted(SEQUENCES))
def test_pythonfmu_and_native_fmi2_fail_alike_with_the_same_message(case, built, native_built, load_fmu):
    model, run = SEQUENCES[case]
    results = {}
    for family in FAMILIES:
        fmu = load_fmu(fmu_path(family, model, built, native_built), family)
        results[family] = (run(fmu), fmu.errors())
    assert results["python"] == results["native"]
    statuses, errors = results["native"]
    assert errors and 3 in [s for s in statuses if isinstance(s, int)], results
    for value in statuses:  # no non-finite value ever reaches an output
        if isinstance(value, list):
            assert all(math.isfinite(v) for v in value), value


def test_the_messages_name_variable_value_time_and_what_is_allowed(built, native_built, load_fmu):
    expected = {
        "gain that overflows": "Lambda_v1 = 1e+308 is invalid: allowed is a number in [0, 1e+12] (at t = 0 s)",
        "K_T that overflows": "K_T1 = 1e-320 is invalid: allowed is a number in [1e-12, 1e+12] (at t = 0 s)",
        "substeps above its bound": "substeps = 20000 is invalid: allowed is an integer in [1, 10000] (at t = 0 s)",
        "input that overflows the command": "at t = 0.0002 s is invalid: allowed is a finite number (the output "
                                            "overflowed; check the inputs and parameters)",
        "time that is not finite": "currentCommunicationPoint = nan is invalid: allowed is a finite number (at t = 0 s)",
        "time that does not continue the last step": "currentCommunicationPoint = 0.5 is invalid: allowed is the end "
                                                     "of the previous step, 0.00030000000000000003 s (within 1e-08 s)",
        "doStep in Initialization Mode": "fmi2DoStep is not allowed in Initialization Mode: allowed in Step Mode",
        "calls after terminate": "fmi2DoStep is not allowed in Terminated: allowed in Step Mode",
        "exit without enter": "fmi2ExitInitializationMode is not allowed in Instantiated: allowed in "
                              "Initialization Mode",
        "enter in Step Mode": "fmi2EnterInitializationMode is not allowed in Step Mode: allowed in Instantiated",
        "tunable gain refused at set": "Lambda_p1 = -5.0 is invalid: allowed is a number in [0, 1e+12] (at t = 0.0001 s)",
    }
    for case, text in expected.items():
        model, run = SEQUENCES[case]
        fmu = load_fmu(native_built["fmi2"][model], "native")
        run(fmu)
        assert any(text in m for m in fmu.errors()), (case, fmu.errors())


def _instantiate_with_guid(path, guid, tmp_path):
    md = read_model_description(str(path))
    messages = []
    slave = FMU2Slave(guid=guid, unzipDirectory=extract(str(path), unzipdir=str(tmp_path / guid.strip("{}"))),
                      modelIdentifier=md.coSimulation.modelIdentifier, instanceName="guid")
    from fmpy.fmi2 import fmi2CallbackFunctions, fmi2CallbackLoggerTYPE
    callbacks = fmi2CallbackFunctions()
    callbacks.logger = fmi2CallbackLoggerTYPE(lambda env, inst, status, cat, msg: messages.append(msg.decode()))
    from fmpy.logging import addLoggerProxy
    addLoggerProxy(ctypes.byref(callbacks))  # formats the variadic message
    with pytest.raises(Exception):
        slave.instantiate(callbacks=callbacks, loggingOn=True)
    return md, messages


@pytest.mark.parametrize("family", FAMILIES)
def test_a_guid_that_is_not_the_fmus_is_refused_at_instantiation(family, built, native_built, tmp_path):
    md, messages = _instantiate_with_guid(fmu_path(family, PLANT, built, native_built), "{not-this-one}", tmp_path)
    assert any(f"fmuGUID = '{{not-this-one}}' is not this FMU's: allowed is '{md.guid}'" in m for m in messages), messages


HOST = r"""
import sys
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
path = sys.argv[1]
md = read_model_description(path)
s = FMU2Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier,
              instanceName="twice")
s.instantiate()
free = s.dll.fmi2FreeInstance   # called directly: fmpy's freeInstance also unloads the library
free(s.component)
free(s.component)               # a second free of the same instance
s.component = None
s.setupExperiment = None
print("survived")
"""


@pytest.mark.parametrize("family", FAMILIES)
def test_a_second_free_of_an_instance_is_ignored(family, built, native_built):
    proc = subprocess.run([sys.executable, "-c", HOST, str(fmu_path(family, PLANT, built, native_built))],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0 and "survived" in proc.stdout, proc.stderr


def _serialized(fmu):
    state = fmu.slave.getFMUstate()
    data = fmu.slave.serializeFMUstate(state)
    fmu.slave.freeFMUstate(state)
    return bytes(data)


def test_a_native_state_holding_nan_is_refused_whole(native_built, load_fmu):
    fmu = load_fmu(native_built["fmi2"][PLANT], "native")
    _init_step(fmu, 5, F1=1.0)
    data = bytearray(_serialized(fmu))
    before = fmu.get("q1_true", "X", "dX")
    nan = ctypes.c_double(float("nan"))
    at = data.find(bytes(ctypes.c_double(before[1])))  # the stored X
    assert at > 0
    data[at:at + 8] = bytes(nan)
    with pytest.raises(FMICallException):
        fmu.slave.deSerializeFMUstate(bytes(data))
    assert any("is invalid: allowed is a finite number" in m and "nothing was changed" in m for m in fmu.errors())
    assert fmu.get("q1_true", "X", "dX") == before


def test_a_python_state_holding_nan_is_refused_whole(built, load_fmu):
    # the pythonfmu FMUs serialize a state in the native runtime's layout: X is one double there
    fmu = load_fmu(built[PLANT], "python")
    _init_step(fmu, 5, F1=1.0)
    data = bytearray(_serialized(fmu))
    before = fmu.get("q1_true", "X", "dX")
    at = data.find(bytes(ctypes.c_double(before[1])))  # the stored X
    assert at > 0
    data[at:at + 8] = bytes(ctypes.c_double(float("nan")))
    status = call_status(lambda: fmu.slave.deSerializeFMUstate(bytes(data)))
    assert status == 3
    assert fmu.get("q1_true", "X", "dX") == before


@pytest.mark.parametrize("family", ("python", "fmi2", "fmi3"))
def test_a_rollback_replays_bit_for_bit_with_the_hidden_state(family, built, native_built, tmp_path):
    path = built[CONTROLLER] if family == "python" else native_built[family][CONTROLLER]
    md = read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmi3 = family == "fmi3"
    slave = (FMU3Slave if fmi3 else FMU2Slave)(guid=md.guid, unzipDirectory=extract(str(path),
                                               unzipdir=str(tmp_path / family)),
                                               modelIdentifier=md.coSimulation.modelIdentifier, instanceName="rb")
    slave.instantiate()
    if fmi3:
        slave.enterInitializationMode(startTime=0.0)
    else:
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
    slave.exitInitializationMode()
    set_real, get_real = (slave.setFloat64, slave.getFloat64) if fmi3 else (slave.setReal, slave.getReal)
    outs = [vr[f"F{i}"] for i in (1, 2, 3)]

    def run(k0):
        values = []
        for k in range(k0, k0 + 50):
            set_real([vr["X_d"], vr["q1"], vr["q2"], vr["q3"]], [1e-5 * k, 2e-6 * k, 1e-6 * k, -1e-6 * k])
            slave.doStep(k * 1e-4, 1e-4)
            values.append(get_real(outs))
        return values
    run(0)
    state = slave.getFMUState() if fmi3 else slave.getFMUstate()
    data = slave.serializeFMUState(state) if fmi3 else slave.serializeFMUstate(state)
    first = run(50)
    if fmi3:
        slave.setFMUState(state)
    else:
        slave.setFMUstate(state)
    assert run(50) == first
    restored = slave.deserializeFMUState(data) if fmi3 else slave.deSerializeFMUstate(data)
    if fmi3:
        slave.setFMUState(restored)
    else:
        slave.setFMUstate(restored)
    assert run(50) == first  # the integral of c and the previous q came back too
    slave.terminate()
    slave.freeInstance()
