"""Property tests (hypothesis): for any input, a clear error or finite results, never a crash.

* scenario files: random keys and values (known keys with values inside and outside their
  ranges, unknown keys, wrong types, non-finite numbers) -> a Scenario or a one-line ScenarioError;
* FMU inputs and parameters through fmpy, on the pythonfmu and the native FMI 2.0 FMUs: after
  setting them, initializing and stepping, either a call failed with an error status and an
  error message logged, or every output is finite (never NaN/inf with fmi2OK);
* SSP connection edits (delete, duplicate, redirect): a one-line CoSimulationError, or a run
  whose every output stays finite.

Example counts are small (the file runs in well under a minute)."""

import math
import re
import zipfile
from ctypes import byref

import pytest
from fmpy import calloc, extract, free, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                       fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)
from fmpy.logging import addLoggerProxy
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tapmp.interface import CONTROLLER, PLANT, TRAJECTORY

SETTINGS = settings(max_examples=25, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])

NUMBERS = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.floats(-1e3, 1e3),
                    st.sampled_from([0.0, -0.0, 1e308, -1e308, 1e-320, 5e-324, 1e12, 1e13, -1.0]))
TOML_VALUES = st.one_of(NUMBERS.map(repr),  # TOML spells inf, -inf and nan as Python's repr does
                        st.integers(-10**6, 10**12).map(str), st.booleans().map(lambda b: str(b).lower()),
                        st.text(alphabet="abcdefghijklmnopqrstuvwxyz-_", max_size=12).map(lambda s: f'"{s}"'),
                        st.lists(st.floats(-1e3, 1e3), max_size=4).map(lambda v: "[" + ", ".join(map(repr, v)) + "]"))
TOP_KEYS = ["name", "law", "gains", "step", "start_time", "stop_time", "ordering", "record_every",
            "start_on_trajectory", "clock", "connection_start", "fmus", "bogus"]
TABLE_KEYS = {"plant": ["m_X", "encoder_resolution", "force_limit", "k_pull", "substeps", "c_v1", "nonsense"],
              "controller": ["force_limit", "velocity_source", "K_T1"],
              "gain_overrides": ["Lambda_v", "D", "Lambda_p", "b", "K_T", "Lambda_x"],
              "trajectory": ["radius", "f_xz", "f_B", "X_c"], "limits": ["motor_travel", "platform_angle", "x"]}


@st.composite
def scenario_texts(draw):
    lines = [f"{k} = {draw(TOML_VALUES)}" for k in draw(st.lists(st.sampled_from(TOP_KEYS), unique=True, max_size=4))]
    for table in draw(st.lists(st.sampled_from(sorted(TABLE_KEYS)), unique=True, max_size=2)):
        lines.append(f"[{table}]")
        keys = draw(st.lists(st.sampled_from(TABLE_KEYS[table]), unique=True, min_size=1, max_size=3))
        lines += [f"{k} = {draw(TOML_VALUES)}" for k in keys]
    return "\n".join(lines) + "\n"


@SETTINGS
@given(text=scenario_texts())
def test_any_scenario_file_is_a_scenario_or_one_clear_error(tmp_path, text):
    from orchestrator.tool.scenario import ScenarioError, load
    lines = text.splitlines()
    end = next((i for i, line in enumerate(lines) if line.startswith("[")), len(lines))
    top = [line.split(" = ")[0] for line in lines[:end]]
    path = tmp_path / "s.toml"
    path.write_text(("" if "name" in top else 'name = "p"\n') + ("" if "stop_time" in top else "stop_time = 0.01\n")
                    + text)
    try:
        sc = load(path)
    except ScenarioError as err:
        msg = str(err)
        assert msg and "\n" not in msg.strip() and len(msg) < 2000
        return
    assert math.isfinite(sc.step) and sc.step > 0 and sc.stop_time > sc.start_time
    assert sc.n_steps >= 1
    for element, params in sc.parameters().items():
        for name, value in params.items():
            assert not isinstance(value, float) or math.isfinite(value), f"{element}.{name} = {value}"


# --- FMU inputs and parameters -------------------------------------------------------------

class Fmu:
    """An extracted FMU; instance() makes a fresh instance whose log is collected."""

    def __init__(self, path, unzip):
        self.md = read_model_description(str(path))
        self.unzip = extract(str(path), unzipdir=str(unzip))
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.settable = sorted(v.name for v in self.md.modelVariables
                               if v.causality in ("input", "parameter") and v.type in ("Real", "Integer"))
        self.outputs = [v for v in self.md.modelVariables if v.causality == "output" and v.type == "Real"]

    def run(self, values: dict):
        """Set ``values``, initialize, do two steps; returns (failed, error messages, outputs)."""
        messages = []
        callbacks = fmi2CallbackFunctions()
        callbacks.logger = fmi2CallbackLoggerTYPE(lambda env, inst, status, cat, msg: messages.append((status, msg.decode())))
        callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        addLoggerProxy(byref(callbacks))
        slave = FMU2Slave(guid=self.md.guid, unzipDirectory=self.unzip,
                          modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName="p")
        slave.instantiate(callbacks=callbacks, loggingOn=True)
        failed, outputs = False, []
        try:
            for name, value in values.items():
                v = self.vars[name]
                if v.type == "Integer":
                    value = int(max(-2**31, min(2**31 - 1, value))) if math.isfinite(value) else 0
                    slave.setInteger([v.valueReference], [value])
                else:
                    slave.setReal([v.valueReference], [value])
            slave.setupExperiment(startTime=0.0)
            slave.enterInitializationMode()
            slave.exitInitializationMode()
            slave.doStep(0.0, 1e-4)
            slave.doStep(1e-4, 1e-4)
            outputs = slave.getReal([v.valueReference for v in self.outputs])
        except FMICallException as err:
            failed = err.status >= 3
            assert failed, f"a call returned status {err.status}"
        finally:
            try:
                slave.terminate()
            except FMICallException:
                pass
            slave.freeInstance()
        return failed, [m for s, m in messages if s >= 3], outputs


@pytest.fixture(scope="module")
def fmus(built, native_built, tmp_path_factory):
    root = tmp_path_factory.mktemp("prop_fmus")
    return {(family, model): Fmu(path, root / f"{family}_{model}")
            for family, paths in (("python", built), ("native", native_built["fmi2"]))
            for model, path in paths.items() if model in (PLANT, CONTROLLER, TRAJECTORY)}


@pytest.mark.parametrize("family", ["python", "native"])
@pytest.mark.parametrize("model", [PLANT, CONTROLLER, TRAJECTORY])
def test_any_inputs_and_parameters_give_an_error_with_a_message_or_finite_outputs(fmus, family, model):
    fmu = fmus[(family, model)]

    @SETTINGS
    @given(values=st.dictionaries(st.sampled_from(fmu.settable), NUMBERS, min_size=1, max_size=4))
    def check(values):
        failed, errors, outputs = fmu.run(values)
        if failed:
            assert errors and all(m.strip() for m in errors)   # an error status comes with a message
        else:
            assert all(math.isfinite(x) for x in outputs), dict(zip((v.name for v in fmu.outputs), outputs))
    check()


# --- SSP connection edits ---------------------------------------------------------------------

CONNECTION = re.compile(r'<ssd:Connection [^>]*/>')


@st.composite
def connection_edits(draw, n):
    """A list of (index, action, target) edits of the SSD's ``n`` connections."""
    return draw(st.lists(st.tuples(st.integers(0, n - 1), st.sampled_from(["delete", "duplicate", "redirect"]),
                                   st.integers(0, n - 1)), min_size=1, max_size=3))


def edited_ssd(ssd: str, edits) -> str:
    conns = CONNECTION.findall(ssd)
    new = list(conns)
    for i, action, j in edits:
        if i >= len(new):
            continue
        if action == "delete":
            new.pop(i)
        elif action == "duplicate":
            new.insert(i, new[i])
        else:  # redirect the end of connection i to the end of connection j
            end = re.search(r'endElement="[^"]*" endConnector="[^"]*"', conns[j]).group(0)
            new[i] = re.sub(r'endElement="[^"]*" endConnector="[^"]*"', end, new[i])
    head, tail = ssd.split(conns[0], 1)[0], ssd.rsplit(conns[-1], 1)[1]
    return head + "\n".join(new) + tail


@pytest.mark.slow
@SETTINGS
@given(edits=connection_edits(18))
def test_any_connection_edit_is_one_clear_error_or_a_finite_run(built, tmp_path, edits):
    from orchestrator.engine.master import CoSimulation, CoSimulationError, RunOptions
    from orchestrator.tool.roles import ROLES
    from orchestrator.tool.scenario import load
    from tests.support.runs import PAPER

    src = built["ssp"]
    dst = tmp_path / "edited.ssp"
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for name in zin.namelist():
            data = zin.read(name)
            if name == "SystemStructure.ssd":
                data = edited_ssd(data.decode(), edits).encode()
            zout.writestr(name, data)
    sc = load(PAPER, ["stop_time=0.002"])
    try:
        with CoSimulation(dst, sc.parameters(), RunOptions(start_time=0.0, step_size=sc.step,
                                                           roles=ROLES)) as sim:
            for _ in range(sc.n_steps):
                sim.step()
                assert all(math.isfinite(x) for x in sim.row())
    except CoSimulationError as err:
        msg = str(err)
        assert msg and "\n" not in msg and "Traceback" not in msg
        assert re.search(r"connect|input|drive|element|variable", msg, re.I), msg
