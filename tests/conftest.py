"""Shared fixtures: the FMUs are built once per test session, for real, with pythonfmu.

Tests that need something from ``../shared`` (relative to the repository root: the third-party
FMI tools in ``../shared/tools``, the paper in ``../shared/paper``) carry the marker
``@pytest.mark.needs_shared("tools/OMSimulator/bin/OMSimulator")``: without that file the test is
skipped with a reason naming it ("needs ../shared/tools/OMSimulator/bin/OMSimulator"), and where
the environment variable CI or TAPMP_REQUIRE_SHARED is set (``.ci/run`` sets it) a missing file
fails the test instead.
"""

import json
import os
import shutil
import tempfile
from pathlib import Path

# as every tapmp command does (orchestrator.cli.single_threaded_blas): before numpy is loaded
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import pytest  # noqa: E402
# pythonfmu from site-packages before any pythonfmu FMU runs in this process: such an FMU puts its
# resources (a copy of pythonfmu's .py files, removed with the FMU) first on sys.path, and a first
# import after that would make FmuBuilder build from that copy, without pythonfmu's binaries
import pythonfmu  # noqa: E402,F401

from orchestrator.builder.build import build_all  # noqa: E402
from tests.support.fmus import LoadedFMU  # noqa: E402
from tests.support.shared import shared  # noqa: E402

# The compatibility rows (tests/interop/compatibility.py): its check after every test; the session's
# own temporary folder (tests/support/temp_folder.py), which tests/project/test_temp_folder.py measures
pytest_plugins = ("tests.interop.compatibility", "tests.support.temp_folder")


def pytest_configure(config):
    config.addinivalue_line("markers", "needs_shared(path, ...): the test needs ../shared/<path> (relative to the "
                                       "repository root); skipped without it, failed without it in CI")


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


def _paths(tree):
    """A fixture's result read back from JSON: every leaf is a path."""
    return {key: _paths(value) if isinstance(value, dict) else Path(value) for key, value in tree.items()}


def built_once(request, tmp_path_factory, name: str, build):
    """``build(folder)`` (returning {name: path or {name: path}}) run once for the whole test run:
    alone, into a folder of this session; on pytest-xdist workers (tests/run.sh runs two), by the
    first worker that asks, under a file lock, into a folder every worker of the run shares, and
    read back by the others from its result file."""
    from filelock import FileLock

    # a worker by its config, not by PYTEST_XDIST_WORKER: a pytest a test starts inherits that variable
    if not hasattr(request.config, "workerinput"):
        return build(tmp_path_factory.mktemp(name))
    run = tmp_path_factory.getbasetemp().parent  # this run's base folder: the workers' folders are in it
    folder, result = run / name, run / f"{name}.json"
    with FileLock(run / f"{name}.lock"):
        if result.is_file():
            return _paths(json.loads(result.read_text()))
        paths = build(folder)
        result.write_text(json.dumps(paths, default=str))
    return paths


@pytest.fixture(scope="session")
def built(request, tmp_path_factory):
    """Paths of the three FMUs and TAPMP.ssp, built into a temporary folder."""
    return built_once(request, tmp_path_factory, "fmus", lambda folder: build_all(folder, log=lambda *_: None))


@pytest.fixture(scope="session")
def faulty_ssps(request, built, tmp_path_factory):
    """{fault: SSP path}: the real controller and trajectory with a plant FMU that misbehaves
    from t = 0.5 ms on, one per fault of tests/support/faults.py's FAULTY ("status", "error_log", "info_log")."""
    from tests.support.faults import faulty_ssps as build
    return built_once(request, tmp_path_factory, "faulty", lambda folder: build(built, folder))


@pytest.fixture(scope="session")
def native_built(request, tmp_path_factory):
    """The native FMUs: {"fmi2" | "fmi3": {model name or "ssp": path}}, built for real for every
    platform (zig cc) into a temporary folder laid out as build/native/."""
    from orchestrator.builder.build_native import build_native
    return built_once(request, tmp_path_factory, "native",
                      lambda folder: build_native(folder, log=lambda *_: None, windows=True))


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
