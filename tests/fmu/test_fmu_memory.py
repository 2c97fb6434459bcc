"""The native FMUs are memory-safe under any call sequence.

* Sanitizer builds (AddressSanitizer + UndefinedBehaviorSanitizer, detect_leaks=1), no
  finding: the C hosts of tests/fmu/c_host (fmi2_host.c, fmi3_host.c) built with the sanitizers
  load sanitizer builds of every FMU and step them 1,000 times, with FMPy's results on the
  shipped binaries; tests/fmu/c_host/memory_host.c runs the call sequences a memory defect would
  show in (nValues shorter than the value references, states held at FreeInstance, a state
  used after it or its instance was freed, a state of another instance, a second free) on
  every FMU of both versions; the three FMUs linked into one program run the closed loop.
* The defects, pinned through FMPy on the shipped binaries: fmi3SetFloat64 / fmi3GetFloat64
  with nValues smaller than the number of value references return fmi3Error with a message
  and touch no value past nValues; a state of another instance, or a freed one, is refused
  with a message.
"""

import ctypes
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave

from tests.support.ctools import SANITIZE, SANITIZER_ENV, compile_c, extract_sources
from tapmp.interface import CONTROLLER, FMU_NAMES, PLANT, START_OUTPUTS

pytestmark = pytest.mark.slow  # sanitizer builds of every FMU, call sequences under AddressSanitizer

ROOT = Path(__file__).resolve().parents[2]
C_HOST = ROOT / "tests" / "fmu" / "c_host"
FAMILIES = ("fmi2", "fmi3")
BINARIES = {"fmi2": "linux64", "fmi3": "x86_64-linux"}
ENV = {"PATH": os.environ["PATH"], **SANITIZER_ENV}


def clean(proc: subprocess.CompletedProcess) -> bool:
    """No sanitizer report in the output and none of the sanitizers' exit codes."""
    text = proc.stdout + proc.stderr
    return proc.returncode not in (86, 87) and not any(
        mark in text for mark in ("ERROR: AddressSanitizer", "ERROR: LeakSanitizer", "runtime error:", "SUMMARY:"))


@pytest.mark.parametrize("model", FMU_NAMES)
@pytest.mark.parametrize("family", FAMILIES)
def test_the_risky_call_sequences_run_clean_under_the_sanitizers(native_built, family, model, tmp_path):
    src = extract_sources(native_built[family][model], tmp_path)
    exe = tmp_path / "memory_host"
    proc = compile_c(["-std=c99", "-Wall", "-Wextra", *SANITIZE, f"-I{src}", "-o", exe, C_HOST / "memory_host.c",
                      "-lm"])
    assert proc.returncode == 0, proc.stderr
    run = subprocess.run([str(exe)], capture_output=True, text=True, timeout=120, env=ENV)
    assert run.returncode == 0 and clean(run), run.stdout[-4000:] + run.stderr[-4000:]
    assert run.stdout.rstrip().endswith("memory_host: all checks passed")
    checks = [line for line in run.stdout.splitlines() if " -> " in line]
    assert len(checks) == (28 if family == "fmi3" else 19)


@pytest.mark.parametrize("model", FMU_NAMES)
@pytest.mark.parametrize("family", FAMILIES)
def test_the_c_hosts_built_with_sanitizers_step_sanitized_fmus_like_fmpy_steps_the_shipped(
        native_built, family, model, tmp_path):
    from tests.fmu.test_native_hosts import fmpy_run, host_args, parse, unzip
    fmu = native_built[family][model]
    fmu_dir = unzip(fmu, tmp_path / "fmu")
    src = extract_sources(fmu, tmp_path / "src")
    lib = fmu_dir / "binaries" / BINARIES[family] / f"{model}.so"
    proc = compile_c(["-std=c99", "-shared", "-fPIC", "-O1", "-ffp-contract=off", *SANITIZE, f"-I{src}", "-o", lib,
                      src / "all.c", "-lm"])
    assert proc.returncode == 0, proc.stderr
    host = tmp_path / "host"
    proc = compile_c(["-O1", "-Wall", "-Wextra", *SANITIZE, "-o", host, C_HOST / f"{family}_host.c", "-ldl"])
    assert proc.returncode == 0, proc.stderr
    steps = 1000
    run = subprocess.run([str(host), str(fmu_dir), *host_args(model, steps)], capture_output=True, text=True,
                         timeout=300, env=ENV)
    assert run.returncode == 0 and clean(run), run.stderr[-4000:]
    expected = fmpy_run(fmu, unzip(fmu, tmp_path / "fmpy"), model, steps)[-1].tolist()
    assert parse(run.stdout) == expected


@pytest.mark.parametrize("family", FAMILIES)
def test_the_closed_loop_of_the_three_linked_fmus_runs_clean_under_the_sanitizers(native_built, family, tmp_path):
    from tests.fmu.test_source_fmus import build_static_loop
    steps = 2000
    plain = build_static_loop(native_built[family], family, tmp_path / "plain")
    sanitized = build_static_loop(native_built[family], family, tmp_path / "sanitized", flags=SANITIZE)
    runs = [subprocess.run([str(exe), str(steps), "0.0001"], capture_output=True, text=True, timeout=600, env=ENV)
            for exe in (plain, sanitized)]
    assert all(r.returncode == 0 for r in runs) and clean(runs[1]), runs[1].stderr[-4000:]
    assert runs[1].stderr == ""
    assert runs[1].stdout == runs[0].stdout and len(runs[1].stdout.splitlines()) == steps


# -- the defects, through FMPy on the shipped binaries ----------------------------------------

class Instance:
    """One instance of a shipped native FMU through FMPy, its log collected, initialized."""

    def __init__(self, fmu: Path, tmp: Path, name: str):
        self.md = read_model_description(str(fmu))
        self.fmi3 = self.md.fmiVersion.startswith("3")
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.log = []
        unzip = extract(str(fmu), str(tmp / name))
        cls = FMU3Slave if self.fmi3 else FMU2Slave
        self.slave = cls(guid=self.md.guid, unzipDirectory=unzip, modelIdentifier=self.md.coSimulation.modelIdentifier,
                         instanceName=name)
        if self.fmi3:
            self.slave.instantiate(logMessage=lambda env, status, category, message: self.log.append(message.decode()))
            self.slave.enterInitializationMode(startTime=0.0)
        else:
            # callbacks of this instance, kept alive with it (fmpy's shared default callbacks may
            # hold a logger another test set and Python has since freed)
            from fmpy.fmi2 import (calloc, free, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                                   fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)
            from fmpy.logging import addLoggerProxy
            self.callbacks = fmi2CallbackFunctions()
            self.callbacks.logger = fmi2CallbackLoggerTYPE(
                lambda env, name, status, category, message: self.log.append(message.decode()))
            self.callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
            self.callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
            addLoggerProxy(ctypes.byref(self.callbacks))
            self.slave.instantiate(callbacks=self.callbacks)
            self.slave.setupExperiment(startTime=0.0)
            self.slave.enterInitializationMode()
        self.slave.exitInitializationMode()
        self.dll, self.c = self.slave.dll, self.slave.component

    def fn(self, name: str, *argtypes):
        """The FMI function ``name`` of this instance's library with its full prototype (status,
        instance pointer, ``argtypes``): without one, ctypes would pass the pointer as a C int."""
        return ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, *argtypes)((name, self.dll))


def test_fmi3_set_float64_with_fewer_values_than_value_references_is_an_error_not_a_read_past_them(
        native_built, tmp_path):
    fmu = Instance(native_built["fmi3"][PLANT], tmp_path, "plant")
    vrs = (ctypes.c_uint * 3)(fmu.vr["F1"], fmu.vr["F2"], fmu.vr["F3"])
    values = (ctypes.c_double * 3)(5.0, 6.0, 7.0)
    status = fmu.fn("fmi3SetFloat64", ctypes.POINTER(ctypes.c_uint), ctypes.c_size_t, ctypes.POINTER(ctypes.c_double), ctypes.c_size_t)(fmu.c, vrs, 3, values, 1)
    assert status == 3  # fmi3Error
    assert fmu.log == ["fmi3SetFloat64: nValues = 1 is invalid: allowed is 3, the number of value references "
                       "(every variable of TAPMP_Plant is a scalar)"]
    forces = [fmu.vr["F1"], fmu.vr["F2"], fmu.vr["F3"]]
    assert fmu.slave.getFloat64(forces) == [START_OUTPUTS[f] for f in ("F1", "F2", "F3")]  # nothing was set


def test_fmi3_get_float64_with_fewer_values_than_value_references_writes_nothing_past_them(native_built, tmp_path):
    fmu = Instance(native_built["fmi3"][CONTROLLER], tmp_path, "controller")
    vrs = (ctypes.c_uint * 3)(fmu.vr["F1"], fmu.vr["F2"], fmu.vr["F3"])
    values = (ctypes.c_double * 3)(-1.5, -2.5, -3.5)
    assert fmu.fn("fmi3GetFloat64", ctypes.POINTER(ctypes.c_uint), ctypes.c_size_t, ctypes.POINTER(ctypes.c_double), ctypes.c_size_t)(fmu.c, vrs, 3, values, 2) == 3
    assert list(values) == [-1.5, -2.5, -3.5]  # not a value written
    assert fmu.log == ["fmi3GetFloat64: nValues = 2 is invalid: allowed is 3, the number of value references "
                       "(every variable of TAPMP_Controller is a scalar)"]
    ints = (ctypes.c_int32 * 1)(7)
    law = (ctypes.c_uint * 1)(fmu.vr["law"])
    get_int32 = fmu.fn("fmi3GetInt32", ctypes.POINTER(ctypes.c_uint), ctypes.c_size_t, ctypes.POINTER(ctypes.c_int32), ctypes.c_size_t)
    assert get_int32(fmu.c, law, 1, ints, 0) == 3 and list(ints) == [7]


def _foreign_and_freed_states(fmu: str, family: str, tmp: str) -> list:
    """Instance b is handed a state of instance a, then a is handed its own freed state: the
    statuses and both instances' log lines."""
    a, b = Instance(Path(fmu), Path(tmp), "a"), Instance(Path(fmu), Path(tmp), "b")
    get, set_, free = (("fmi3GetFMUState", "fmi3SetFMUState", "fmi3FreeFMUState") if family == "fmi3" else
                       ("fmi2GetFMUstate", "fmi2SetFMUstate", "fmi2FreeFMUstate"))
    state = ctypes.c_void_p()
    out = [a.fn(get, ctypes.POINTER(ctypes.c_void_p))(a.c, ctypes.byref(state)), bool(state.value)]
    out.append(b.fn(set_, ctypes.c_void_p)(b.c, state))
    kept = ctypes.c_void_p(state.value)
    out += [a.fn(free, ctypes.POINTER(ctypes.c_void_p))(a.c, ctypes.byref(state)), state.value]
    out.append(a.fn(set_, ctypes.c_void_p)(a.c, kept))  # freed: refused without being read
    out += [a.log, b.log]
    for x in (a, b):
        x.slave.freeInstance()
    return out


@pytest.mark.parametrize("family", FAMILIES)
def test_a_state_of_another_instance_or_a_freed_one_is_refused_with_a_message(native_built, family, tmp_path):
    # in a process of its own: two copies of the library and states handed between them, away from
    # the FMUs other tests of this session loaded
    script = ("import json, sys; sys.path.insert(0, sys.argv[4]); from test_fmu_memory import _foreign_and_freed_states; "
              "print(json.dumps(_foreign_and_freed_states(*sys.argv[1:4])))")
    res = subprocess.run([sys.executable, "-c", script, str(native_built[family][PLANT]), family, str(tmp_path),
                          str(Path(__file__).parent)], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    got, has_state, foreign, freed, after, refused, a_log, b_log = json.loads(res.stdout.splitlines()[-1])
    assert (got, has_state, foreign, freed, after, refused) == (0, True, 3, 0, None, 3)
    if family == "fmi3":
        allowed = "allowed is a state from fmi3GetFMUState or fmi3DeserializeFMUState of this instance that was not freed"
        assert b_log == [f"fmi3SetFMUState: FMUstate is invalid: {allowed}"]
        assert a_log == [f"fmi3SetFMUState: FMUstate is invalid: {allowed}"]


def test_fmi2_get_real_status_without_a_value_pointer_is_an_error(native_built, tmp_path):
    fmu = Instance(native_built["fmi2"][PLANT], tmp_path, "plant")
    get_real_status = fmu.fn("fmi2GetRealStatus", ctypes.c_int, ctypes.POINTER(ctypes.c_double))
    assert get_real_status(fmu.c, 2, None) == 3  # fmi2LastSuccessfulTime into NULL
    value = ctypes.c_double(-1.0)
    assert get_real_status(fmu.c, 2, ctypes.byref(value)) == 0 and value.value == 0.0
    fmu.slave.freeInstance()
