"""The pythonfmu FMUs' binary is the native FMUs' runtime (fmu_common/c) with Python model
operations: the same raw FMI 2.0 call sequence, with calls in the wrong state, status
queries, a foreign FMU state and calls on a foreign or freed instance, gives the same
status and the same logged message, call by call, from both families of every model."""

import ctypes
from ctypes import POINTER, c_double, c_int, c_size_t, c_uint, c_void_p

import pytest

from tapmp.interface import FMU_NAMES

FMI2_LAST_SUCCESSFUL_TIME, FMI2_DO_STEP_STATUS = 2, 0


def _fn(dll, name, *argtypes):
    f = getattr(dll, name)
    f.argtypes, f.restype = [c_void_p, *argtypes], c_int
    return f


def _api(dll):
    """The raw FMI 2.0 functions the sequence calls."""
    free = dll.fmi2FreeInstance
    free.argtypes, free.restype = [c_void_p], None
    return (_fn(dll, "fmi2DoStep", c_double, c_double, c_int), _fn(dll, "fmi2GetRealStatus", c_int, POINTER(c_double)),
            _fn(dll, "fmi2GetStatus", c_int, POINTER(c_int)),
            _fn(dll, "fmi2GetReal", POINTER(c_uint), c_size_t, POINTER(c_double)),
            _fn(dll, "fmi2GetBoolean", POINTER(c_uint), c_size_t, POINTER(c_int)),
            _fn(dll, "fmi2SetupExperiment", c_int, c_double, c_double, c_int, c_double),
            _fn(dll, "fmi2EnterInitializationMode"), _fn(dll, "fmi2ExitInitializationMode"), _fn(dll, "fmi2Terminate"),
            _fn(dll, "fmi2SetFMUstate", c_void_p), _fn(dll, "fmi2FreeFMUstate", POINTER(c_void_p)), free)


def _sequence(fmu):
    """(call, status, value or None, messages logged by the call) for each call."""
    comp = fmu.slave.component
    do_step, real_status, status, get_real, get_boolean, setup, enter, leave, terminate, set_state, free_state, \
        free = _api(fmu.slave.dll)
    value, flag = c_double(-1.0), c_int(-1)
    foreign = ctypes.create_string_buffer(4096)  # not an instance, not a state
    foreign_state = c_void_p(ctypes.addressof(foreign))
    calls = [
        ("doStep before initialization", lambda: do_step(comp, 0.0, 1e-4, 1)),
        ("exitInitializationMode in Instantiated", lambda: leave(comp)),
        ("setupExperiment at t = nan", lambda: setup(comp, 0, 0.0, float("nan"), 0, 0.0)),
        ("getRealStatus lastSuccessfulTime", lambda: real_status(comp, FMI2_LAST_SUCCESSFUL_TIME, ctypes.byref(value))),
        ("getStatus", lambda: status(comp, FMI2_DO_STEP_STATUS, ctypes.byref(flag))),
        ("getReal of value reference 9999", lambda: get_real(comp, (c_uint * 1)(9999), 1, (c_double * 1)())),
        ("getBoolean", lambda: get_boolean(comp, (c_uint * 1)(0), 1, (c_int * 1)())),
    ]
    reset = _fn(fmu.slave.dll, "fmi2Reset")
    calls += [
        ("reset", lambda: reset(comp)),  # the state machine from a clean start
        ("setupExperiment", lambda: setup(comp, 0, 0.0, 0.25, 0, 0.0)),
        ("enterInitializationMode", lambda: enter(comp)),
        ("exitInitializationMode", lambda: leave(comp)),
        ("doStep", lambda: do_step(comp, 0.25, 1e-4, 1)),
        ("getRealStatus after a step", lambda: real_status(comp, FMI2_LAST_SUCCESSFUL_TIME, ctypes.byref(value))),
        ("doStep that does not continue the last step", lambda: do_step(comp, 0.5, 1e-4, 1)),
        ("doStep after the error", lambda: do_step(comp, 0.2501, 1e-4, 1)),
        ("enterInitializationMode in Step Mode", lambda: enter(comp)),
        ("getRealStatus after the error", lambda: real_status(comp, FMI2_LAST_SUCCESSFUL_TIME, ctypes.byref(value))),
        ("terminate after the error", lambda: terminate(comp)),
    ]
    calls += [
        ("setFMUstate of a foreign state", lambda: set_state(comp, foreign_state)),
        ("freeFMUstate of a foreign state", lambda: free_state(comp, ctypes.byref(foreign_state))),
        ("terminate", lambda: terminate(comp)),
        ("doStep of a foreign instance", lambda: do_step(ctypes.addressof(foreign), 0.0, 1e-4, 1)),
        ("free", lambda: free(comp)),
        ("doStep of the freed instance", lambda: do_step(comp, 0.25, 1e-4, 1)),
        ("getRealStatus of the freed instance", lambda: real_status(comp, FMI2_LAST_SUCCESSFUL_TIME,
                                                                    ctypes.byref(value))),
        ("second free", lambda: free(comp)),
    ]
    results = []
    for name, call in calls:
        before, value.value = len(fmu.messages), -1.0
        answer = call()
        results.append((name, answer, value.value, fmu.messages[before:]))
    fmu.slave.component = None  # freed above: the fixture's terminate and free see NULL, which is refused
    return results


@pytest.mark.parametrize("model", FMU_NAMES)
def test_the_pythonfmu_and_native_fmi2_binaries_answer_bad_calls_alike(model, built, native_built, load_fmu):
    python = _sequence(load_fmu(built[model], "python"))
    native = _sequence(load_fmu(native_built["fmi2"][model], "native"))
    for p, n in zip(python, native):
        assert p == n
    by_call = {name: (answer, value, messages) for name, answer, value, messages in native}
    assert by_call["getRealStatus lastSuccessfulTime"][:2] == (0, 0.0)  # fmi2OK and the time, in both
    assert by_call["getRealStatus after a step"][:2] == (0, 0.2501)
    assert by_call["getRealStatus after the error"][:2] == (0, 0.2501)
    assert by_call["doStep"][0] == 0 and by_call["doStep after the error"][0] == 3
    assert "refused after an earlier error" in by_call["doStep after the error"][2][0][1]
    assert by_call["doStep of the freed instance"] == (3, -1.0, [])  # refused without touching it
    assert by_call["doStep of a foreign instance"] == (3, -1.0, [])
    assert any("FMUstate is invalid" in m for _, m in by_call["setFMUstate of a foreign state"][2])
    assert len(python) == len(native) == 26 and [s for _, s, _, _ in native].count(3) >= 13
