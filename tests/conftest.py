"""Shared fixtures: the FMUs are built once per test session, for real, with pythonfmu.

Tests that need something from ``../shared`` (relative to the repository root: the third-party
FMI tools in ``../shared/tools``, the paper in ``../shared/paper``) carry the marker
``@pytest.mark.needs_shared("tools/OMSimulator/bin/OMSimulator")``: without that file the test is
skipped with a reason naming it ("needs ../shared/tools/OMSimulator/bin/OMSimulator"), and where
the environment variable CI or TAPMP_REQUIRE_SHARED is set (``.ci/run`` sets it) a missing file
fails the test instead.
"""

import os
import shutil
import tempfile
from ctypes import byref
from pathlib import Path

import pytest
from fmpy import calloc, extract, free, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                       fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)
from fmpy.logging import addLoggerProxy

from orchestrator.engine.build import build_all

# The compatibility rows (tests/interop/compatibility.py): its check after every test
pytest_plugins = ("compatibility",)

ROOT = Path(__file__).resolve().parent.parent
SHARED = ROOT.parent / "shared"
REQUIRE_SHARED = ("CI", "TAPMP_REQUIRE_SHARED")  # environment variables that make a missing file a failure


def pytest_configure(config):
    # the system's temporary folder and what it held before any test (tests/project/test_temp_folder.py)
    config.system_temp = tempfile.gettempdir()
    config.system_temp_before = set(os.listdir(config.system_temp))
    config.addinivalue_line("markers", "needs_shared(path, ...): the test needs ../shared/<path> (relative to the "
                                       "repository root); skipped without it, failed without it in CI")


def shared_required() -> bool:
    """True where a missing ../shared file fails a test instead of skipping it (CI)."""
    return any(os.environ.get(name) for name in REQUIRE_SHARED)


def shared(relative: str) -> Path:
    """``../shared/<relative>`` (relative to the repository root) if it exists; else the test is
    skipped with a reason naming it, or fails where :func:`shared_required`."""
    path = SHARED / relative
    if not path.exists():
        reason = f"needs ../shared/{relative}"
        if shared_required():
            pytest.fail(f"{reason} (relative to the repository root {ROOT}), which is missing; "
                        f"{' or '.join(REQUIRE_SHARED)} is set, so it is required", pytrace=False)
        pytest.skip(reason)
    return path


# Markers every test of a folder carries (the markers themselves are registered in pyproject.toml;
# elsewhere `slow` and `windows` are set per file with pytestmark or per test).
FOLDER_MARKERS = {"interop": ("interop", "slow")}
# Markers every test using a fixture carries: native_built compiles every family for every
# platform (about a minute), faulty_ssps builds three plant FMUs of their own.
LAST_TEST = "test_temp_folder.py::test_the_suite_leaves_at_most_100_mb_in_the_temporary_folders"
FIXTURE_MARKERS = {"native_built": ("slow",), "faulty_ssps": ("slow",)}


def pytest_collection_modifyitems(config, items):
    """Adds :data:`FOLDER_MARKERS` and :data:`FIXTURE_MARKERS` to the tests they name, and
    ``interop`` and ``slow`` to every test that needs a tool of ../shared/tools, and runs the
    temporary-folder test (:data:`LAST_TEST`) after every other."""
    here = Path(__file__).resolve().parent
    for item in items:
        names = set(getattr(item, "fixturenames", ()))
        for fixture, markers in FIXTURE_MARKERS.items():
            if fixture in names:
                for name in markers:
                    item.add_marker(name)
        if any(str(path).startswith("tools/") for m in item.iter_markers("needs_shared") for path in m.args):
            item.add_marker("interop")  # a third-party FMI tool of ../shared/tools, wherever the test is
            item.add_marker("slow")
        try:
            folder = item.path.resolve().relative_to(here).parts[0]
        except ValueError:
            continue  # a test outside tests/ (a scratch repository's)
        for name in FOLDER_MARKERS.get(folder, ()):
            item.add_marker(name)
    # what the suite leaves in the temporary folders is measured after every other test
    last = [item for item in items if item.nodeid.endswith(LAST_TEST)]
    items[:] = [item for item in items if not item.nodeid.endswith(LAST_TEST)] + last


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item):
    """Checks every ``needs_shared`` path before any fixture of the test is set up."""
    for marker in item.iter_markers("needs_shared"):
        for relative in marker.args:
            shared(relative)


@pytest.fixture(scope="session", autouse=True)
def session_temp_folder(tmp_path_factory):
    """The same for session and module fixtures (set up before any test's own folder)."""
    folder = tmp_path_factory.mktemp("session_tmp")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("TMPDIR", str(folder))
        mp.setattr(tempfile, "tempdir", str(folder))
        yield folder


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item, call):
    """Records whether each phase of a test passed (``item.phase_failed``), for own_temp_folder."""
    report = yield
    if report.failed:
        item.phase_failed = True
    return report


@pytest.fixture(autouse=True)
def own_temp_folder(request, tmp_path_factory, monkeypatch):
    """Every test's temporary files in its own folder (beside its tmp_path, under pytest's base
    folder): Python's tempfile (fmpy's extractions, Dask's scratch space), and TMPDIR for C
    libraries (Ecos's ecos_ssp_*) and child processes; nothing is left in the system's /tmp.
    Removed when the test passed, kept for a failed one (as pytest keeps a failed test's tmp_path:
    tmp_path_retention_policy = "failed" in pyproject.toml)."""
    folder = tmp_path_factory.mktemp("tmp")
    monkeypatch.setenv("TMPDIR", str(folder))
    monkeypatch.setattr(tempfile, "tempdir", str(folder))
    yield folder
    if not getattr(request.node, "phase_failed", False):
        shutil.rmtree(folder, ignore_errors=True)


@pytest.fixture(scope="session")
def built(tmp_path_factory):
    """Paths of the three FMUs and TAPMP.ssp, built into a temporary folder."""
    return build_all(tmp_path_factory.mktemp("fmus"), log=lambda *_: None)


@pytest.fixture(scope="session")
def faulty_ssps(built, tmp_path_factory):
    """{fault: SSP path}: the real controller and trajectory with a plant FMU that misbehaves
    from t = 0.5 ms on, one per fault of tests/faults.py's FAULTY ("status", "error_log", "info_log")."""
    from faults import faulty_ssps as build
    return build(built, tmp_path_factory.mktemp("faulty"))


@pytest.fixture(scope="session")
def native_built(tmp_path_factory):
    """The native FMUs: {"fmi2" | "fmi3": {model name or "ssp": path}}, built for real for every
    platform (zig cc) into a temporary folder laid out as build/native/."""
    from orchestrator.engine.build_native import build_native
    return build_native(tmp_path_factory.mktemp("native"), log=lambda *_: None, windows=True)


class LoadedFMU:
    """One FMU instance through fmpy, with its log messages collected."""

    def __init__(self, path, tmp_path, name="inst"):
        self.md = read_model_description(str(path))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.types = {v.name: v.type for v in self.md.modelVariables}
        self.messages = []
        self.callbacks = fmi2CallbackFunctions()
        self.callbacks.logger = fmi2CallbackLoggerTYPE(self._log)
        self.callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        self.callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        addLoggerProxy(byref(self.callbacks))
        unzip = extract(str(path), unzipdir=str(tmp_path / f"{name}_unzip"))
        self.slave = FMU2Slave(guid=self.md.guid, unzipDirectory=unzip,
                               modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=name)
        self.slave.instantiate(callbacks=self.callbacks, loggingOn=True)

    def _log(self, env, instance, status, category, message):
        self.messages.append((status, message.decode()))

    def set(self, **values):
        for k, v in values.items():
            if self.types[k] == "Integer":
                self.slave.setInteger([self.vr[k]], [int(v)])
            else:
                self.slave.setReal([self.vr[k]], [float(v)])

    def get(self, *names):
        return self.slave.getReal([self.vr[n] for n in names])

    def init(self, t0=0.0, **params):
        self.set(**params)
        self.slave.setupExperiment(startTime=t0)
        self.slave.enterInitializationMode()
        self.slave.exitInitializationMode()

    def statuses(self, **values):
        """Set values, initialize and do one step; the fmi2Status of each call, in order
        (fmpy raises FMICallException for a status above fmi2Warning)."""
        calls = {"set": lambda: self.set(**values),
                 "setupExperiment": lambda: self.slave.setupExperiment(startTime=0.0),
                 "enterInitializationMode": self.slave.enterInitializationMode,
                 "exitInitializationMode": self.slave.exitInitializationMode,
                 "doStep": lambda: self.slave.doStep(0.0, 1e-4)}
        return {name: call_status(call) for name, call in calls.items()}

    def errors(self):
        return [m for s, m in self.messages if s >= 3]

    def close(self):
        try:
            self.slave.terminate()
        except Exception:
            pass
        self.slave.freeInstance()


def call_status(call) -> int:
    """The fmi2Status of an fmpy call: 0 (or 1) if it returned, else the raised status."""
    try:
        call()
    except FMICallException as err:
        return err.status
    return 0


@pytest.fixture
def load_fmu(tmp_path):
    """Factory: load_fmu(path) -> LoadedFMU; every instance is freed after the test."""
    loaded = []

    def make(path, name="inst"):
        fmu = LoadedFMU(path, tmp_path, f"{name}{len(loaded)}")
        loaded.append(fmu)
        return fmu
    yield make
    for fmu in loaded:
        fmu.close()


PAPER = ROOT / "scenarios" / "paper_simulation.toml"
MOTOR_POSITIONS = tuple(f"plant.q{i}_true" for i in (1, 2, 3)) + tuple(f"plant.q{i}" for i in (1, 2, 3))
COMMANDS = tuple(f"controller.F{i}" for i in (1, 2, 3))


def paper_scenario(stop_time=0.2, *overrides):
    """The paper's simulation scenario, shortened (0.2 s = 2,000 steps of 0.1 ms)."""
    from orchestrator.tool.scenario import load
    return load(PAPER, [f"stop_time={stop_time}", *overrides])


def orchestrator_rows(ssp, scenario, names, ordering="jacobi", **conventions):
    """The orchestrator's values of ``names`` ("element.variable") at t_0 ... t_n, one row per
    communication point; ``conventions`` are CoSimulation's clock / connection_start."""
    import numpy as np

    from orchestrator.engine.master import CoSimulation
    from orchestrator.tool.roles import ROLES
    rows = []
    with CoSimulation(ssp, scenario.parameters(), scenario.start_time, scenario.step, ordering,
                      **conventions, roles=ROLES) as sim:
        index = [sim.columns.index(n) for n in names]
        rows.append([sim.row()[i] for i in index])
        for _ in range(scenario.n_steps):
            sim.step()
            row = sim.row()
            rows.append([row[i] for i in index])
    return np.array(rows)
