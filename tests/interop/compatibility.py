"""Compatibility results as data: every third-party tool run of the test suite records one row
(tool, its version, FMI version, interface, platform, the command as a user types it, result,
difference from tapmp), and the rows are published as docs/compatibility.json and rendered into
docs/compatibility.md.

A test calls :func:`record` after its assertions have passed, so a row exists only for a run
that passed. The row must equal the committed row of the same key (tool, FMI version,
interface, platform, command): a changed version, result or difference fails the test that
measured it. With the environment variable TAPMP_UPDATE_COMPATIBILITY=1 the rows are written
instead (the rows of every test that ran replace that test's committed rows, the page is
rendered again); then ``git diff docs/compatibility.*`` shows what changed.

Everything in a row is deterministic: no time stamps, versions as the tools print them,
differences bucketed to a power of ten (:func:`difference`), rows sorted by key.
"""

import fcntl
import json
import math
import os
import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SHARED = ROOT.parent / "shared"
JSON_FILE = ROOT / "docs" / "compatibility.json"
MD_FILE = ROOT / "docs" / "compatibility.md"
UPDATE = "TAPMP_UPDATE_COMPATIBILITY"
FIELDS = ("tool", "version", "fmi", "interface", "platform", "command", "result", "difference", "test")
KEY = ("tool", "fmi", "interface", "platform", "command")
LINUX = "x86_64-linux"

_recorded: dict[tuple, dict] = {}      # key -> row, recorded in this session
_updated_tests: set[str] = set()       # tests whose committed rows were replaced in this session


def key_of(row: dict) -> tuple:
    return tuple(row[k] for k in KEY)


def committed_rows(path: Path = JSON_FILE) -> dict[tuple, dict]:
    """{key: row} of the committed JSON file (empty if it does not exist or is empty)."""
    if not path.exists() or path.stat().st_size == 0:
        return {}
    return {key_of(r): r for r in json.loads(path.read_text())["rows"]}


def difference(value: float, unit: str, against: str) -> str:
    """``value`` (the largest absolute difference, in ``unit``) as "0 (bit for bit)" or
    "< 1e-N unit", the next power of ten above it, followed by what it is compared with."""
    if not math.isfinite(value) or value < 0:
        raise ValueError(f"a difference must be a finite number >= 0, not {value!r}")
    text = "0 (bit for bit)" if value == 0.0 else f"< 1e{math.floor(math.log10(value)) + 1}{' ' * bool(unit)}{unit}"
    return f"{text} vs {against}"


def record(request, *, tool: str, version: str, fmi: str, interface: str, command: str, difference: str,
           platform: str = LINUX, result: str = "passed") -> dict:
    """Record the row of the calling test (``request``: its pytest request) and check it against
    the committed one (or write it, with TAPMP_UPDATE_COMPATIBILITY=1)."""
    row = {"tool": tool, "version": version, "fmi": fmi, "interface": interface, "platform": platform,
           "command": command, "result": result, "difference": difference, "test": request.node.nodeid}
    key = key_of(row)
    if key in _recorded and _recorded[key]["test"] != row["test"]:
        raise AssertionError(f"two tests record the row {key}: {_recorded[key]['test']} and {row['test']}")
    _recorded[key] = row
    if os.environ.get(UPDATE):
        _write(row)
        return row
    committed = committed_rows()
    assert key in committed, (f"no committed compatibility row for {key}: run the test with {UPDATE}=1 and "
                              f"commit docs/compatibility.json and docs/compatibility.md")
    assert committed[key] == row, {f: (committed[key][f], row[f]) for f in FIELDS if committed[key][f] != row[f]}
    return row


def recorded_by(nodeid: str) -> set[tuple]:
    """The keys recorded by the test ``nodeid`` in this session."""
    return {k for k, r in _recorded.items() if r["test"] == nodeid}


def _write(row: dict) -> None:
    # read, changed and written under a lock on the file: tests/run.sh's pytest-xdist workers record at once
    with open(JSON_FILE, "a") as held:
        fcntl.flock(held, fcntl.LOCK_EX)
        rows = committed_rows()
        if row["test"] not in _updated_tests:  # the test's old rows go: it records all of its rows again
            _updated_tests.add(row["test"])
            rows = {k: r for k, r in rows.items() if r["test"] != row["test"]}
        rows[key_of(row)] = row
        write(list(rows.values()))


def write(rows: list[dict]) -> None:
    """docs/compatibility.json (rows sorted by key) and docs/compatibility.md rendered from it."""
    ordered = sorted(rows, key=key_of)
    JSON_FILE.write_text(json_text(ordered))
    MD_FILE.write_text(render(ordered))


def json_text(rows: list[dict]) -> str:
    """{"fields": [...], "rows": [...]} with one row per line (a changed row is one changed line)."""
    lines = [json.dumps({f: r[f] for f in FIELDS}, ensure_ascii=False) for r in rows]
    return ('{"fields": ' + json.dumps(list(FIELDS)) + ',\n "rows": [\n  ' + ",\n  ".join(lines) + "\n ]\n}\n")


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


def render(rows: list[dict]) -> str:
    """docs/compatibility.md: the rows as one Markdown table, grouped by tool."""
    lines = [
        "# Compatibility results",
        "",
        "Every row is a run of a third-party FMI tool in the test suite, on the FMUs and SSPs that",
        "`tapmp build` writes; the tests generate this page and its machine-readable copy",
        "[compatibility.json](compatibility.json) (`tests/interop/compatibility.py`). A row exists",
        "only for a run whose test passed, and each test checks that its row still equals the one",
        "committed here: a new tool version, a failure or a changed difference fails that test.",
        "",
        "* **command**: what the test runs, as typed in a shell at the repository root after the",
        "  [quick start](../README.md#quick-start) (`build/` its FMUs, the tools called by their path under",
        "  `../shared/tools/`); `tests/interop/test_docs_commands.py` runs every one of them so. A row whose",
        "  run needs more than one line names its script in `tests/interop/rows/`; a row that starts",
        "  `.venv/bin/python -m pytest` (a host compiled for another platform) or names",
        "  `tests/interop/rows/fmpy_wired_by_hand.py` needs pytest, in the `.venv` that `bash tests/run.sh` sets",
        "  up (the `test` extra). Each tool's commands explained are in [other-tools.md](other-tools.md).",
        "* **difference from tapmp**: the largest absolute difference over the run, rounded up to a",
        "  power of ten, against `tapmp run` (the orchestrator) on the tool's conventions (ordering,",
        "  clock, connection start, as [other-tools.md](other-tools.md) explains), or against FMPy's",
        "  `simulate_fmu` where the tool runs one FMU alone. Model Exchange rows (ME) compare the plant's",
        "  continuous states X, Z, B, dX, dZ, dB, relative to each one's largest value; an encoder position,",
        "  quantized to 0.1 um, may differ there by one count.",
        "* To regenerate after a change: run the interop tests with `TAPMP_UPDATE_COMPATIBILITY=1`,",
        "  e.g. `TAPMP_UPDATE_COMPATIBILITY=1 .venv/bin/python -m pytest -q tests/interop` in the `.venv`",
        "  that `bash tests/run.sh` sets up (pytest is in the `test` extra, not in the quick start's",
        "  `tools`); the test that names each row is in the JSON (`test`).",
        "",
        "| tool | version | FMI | interface | platform | command | result | difference from tapmp |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in sorted(rows, key=key_of):
        lines.append("| " + " | ".join(_cell(r[f]) if f != "command" else f"`{_cell(r[f])}`"
                                       for f in FIELDS[:-1]) + " |")
    return "\n".join(lines) + "\n"


# -- the tools' versions, as they print them -------------------------------------------------------

def tool_output(*args: str) -> str:
    return subprocess.run(list(args), capture_output=True, text=True, timeout=60).stdout.strip()


def readme_version(folder: str) -> str:
    """The version column of ``folder``'s row in ../shared/tools/README.md (for builds that print
    none: fmuCheck prints "Test", fmil_check nothing)."""
    text = (SHARED / "tools" / "README.md").read_text()
    match = re.search(rf"^\| `{re.escape(folder)}/` \|[^|]*\| ([^|]+?) \|", text, re.MULTILINE)
    if not match:
        raise LookupError(f"../shared/tools/README.md has no row for {folder}/")
    return match.group(1).split(" (")[0]


def python_version(distribution: str) -> str:
    from importlib import metadata
    return metadata.version(distribution)


def fmusim_version(program) -> str:
    return tool_output(str(program), "--version").split()[1]  # "fmusim v0.0.39 (x86_64-linux)"


def omsimulator_version(program) -> str:
    return tool_output(str(program), "--version").split()[1].removesuffix("-linux")


# -- differences -----------------------------------------------------------------------------------

def largest(got, expected) -> float:
    """The largest absolute difference of two arrays of the same shape."""
    import numpy as np
    got, expected = np.asarray(got, dtype=float), np.asarray(expected, dtype=float)
    assert got.shape == expected.shape, (got.shape, expected.shape)
    return float(np.abs(got - expected).max()) if got.size else 0.0


def relative(got, expected) -> float:
    """The largest difference of two arrays of rows (t, signals) relative to each signal's
    largest magnitude (so signals of different units are one number)."""
    import numpy as np
    got, expected = np.atleast_2d(np.asarray(got, dtype=float)), np.atleast_2d(np.asarray(expected, dtype=float))
    assert got.shape == expected.shape, (got.shape, expected.shape)
    scale = np.abs(expected).max(axis=0)
    scale[scale == 0.0] = 1.0
    return float((np.abs(got - expected) / scale).max())


def tool(relative: str) -> str:
    """How the commands call a tool of ../shared (``relative``: its path there, tools/fmusim/bin/fmusim)."""
    return f"../shared/{relative}"


PY = ".venv/bin/python"
FMUSIM = tool("tools/fmusim/bin/fmusim")
OMSIMULATOR = tool("tools/OMSimulator/bin/OMSimulator")
FMIL_CHECK = tool("tools/fmil/fmil_check")
FMUCHECK = tool("tools/fmuCheck/fmuCheck.linux64")
FASTER = ("trajectory.f_xz=0.8", "trajectory.f_B=0.8")  # the exported rows' reference, twice the paper's frequency


def export(ssp: str, out: str) -> str:
    """The `tapmp export` command the exported-SSP rows start with: the paper scenario shortened to
    0.2 s with the FASTER reference, from the built ``ssp`` into ``out`` (as the tests export it)."""
    sets = " ".join(f"--set {kv}" for kv in ("stop_time=0.2", *FASTER))
    return f".venv/bin/tapmp export scenarios/paper_simulation.toml --ssp {ssp} --out {out} {sets} --overwrite"


def python_c(code: str) -> str:
    """A one-line Python row: ``code`` (single quotes only) run by the quick start's interpreter."""
    assert '"' not in code, code
    return f'{PY} -c "{code}"'


def node_command(request) -> str:
    """The row of a run only a test makes (hosts it compiles for another platform): the test itself,
    in the .venv of `bash tests/run.sh` (pytest is in the test extra)."""
    return f".venv/bin/python -m pytest -q -p no:cacheprovider '{request.node.nodeid}'"


def family_path(version: str, model: str | None = None) -> str:
    """How the commands name an FMU of a family from the repository root after the quick start:
    build/native/fmi2/MODEL.fmu, build/MODEL.fmu."""
    folder = {"fmi2": "build/native/fmi2/", "fmi3": "build/native/fmi3/", "python": "build/"}[version]
    return folder + (f"{model}.fmu" if model else "")


# -- pytest plugin (tests/conftest.py loads this module as one) ------------------------------------
# A test that passed must have recorded every row committed under its name: a row cannot outlive
# the check that made it.


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item, call):
    report = yield
    if call.when == "call":
        item.compatibility_passed = report.passed
    return report


@pytest.fixture(autouse=True)
def committed_compatibility_rows_are_recorded(request):
    """After a passed test: every committed row naming it was recorded by it in this session."""
    yield
    if not getattr(request.node, "compatibility_passed", False) or os.environ.get(UPDATE):
        return
    nodeid = request.node.nodeid
    expected = {k for k, r in committed_rows().items() if r["test"] == nodeid}
    missing = expected - recorded_by(nodeid)
    assert not missing, f"{nodeid} passed without recording its committed compatibility rows {sorted(missing)}"
