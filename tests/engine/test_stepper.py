"""The compiled stepping core (orchestrator/engine/stepper.c) against the master's Python loop,
the reference: the same rows to the bit on every FMU family, ordering and clock, and on
failing runs the same error message, exit code and partial results."""

import json
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

from orchestrator.engine import stepper
from tapmp import cmodel
from orchestrator.engine.master import CoSimulation, CoSimulationError, DivergenceError, RunOptions
from orchestrator.tool.roles import ROLES
from orchestrator.tool.envelope import envelope
from orchestrator.tool.reading import read_results
from orchestrator.tool.results import run_scenario
from orchestrator.tool.stops import request_stop
from tests.support.runs import PAPER, paper_scenario


def rows_of(ssp, scenario, stepper_kind, ordering, clock="exact", blocks=(7, 300, 193)):
    """Row 0 and the rows of ``sum(blocks)`` steps, stepped in blocks of those sizes."""
    with CoSimulation(ssp, scenario.parameters(), RunOptions(start_time=scenario.start_time, step_size=scenario.step,
                                                             ordering=ordering, check=envelope(scenario), clock=clock,
                                                             stepper=stepper_kind, roles=ROLES)) as sim:
        assert (sim._core is not None) == (stepper_kind == "compiled")
        out = [np.array([sim.row()])]
        for n in blocks:
            block = np.full((n, len(sim.columns)), np.nan)
            assert sim.advance(block) == n
            out.append(block)
        return sim.columns, np.vstack(out)


def family_ssp(family, built, native_built):
    return built["ssp"] if family == "pythonfmu" else native_built[family]["ssp"]


@pytest.mark.parametrize("ordering", ["gauss-seidel", "jacobi"])
@pytest.mark.parametrize("family", ["fmi2", "fmi3", "pythonfmu"])
def test_the_compiled_core_gives_the_python_loops_rows_bit_for_bit(family, ordering, built, native_built):
    ssp, sc = family_ssp(family, built, native_built), paper_scenario(0.05)
    cols_py, py = rows_of(ssp, sc, "python", ordering)
    cols_c, c = rows_of(ssp, sc, "compiled", ordering)
    assert cols_py == cols_c and py.shape == (501, len(cols_py))
    assert py.tobytes() == c.tobytes()
    # the loop moved: the plant follows the reference, time is t0 + k h
    assert c[-1, 0] == 500 * 1e-4 and np.all(np.isfinite(c))
    assert np.ptp(c[:, cols_c.index("plant.X")]) > 1e-4


@pytest.mark.parametrize("clock", ["accumulated", "nanoseconds"])
def test_the_compiled_core_keeps_the_other_masters_clocks_to_the_bit(clock, native_built):
    ssp, sc = native_built["fmi2"]["ssp"], paper_scenario(0.05)
    _, py = rows_of(ssp, sc, "python", "jacobi", clock)
    _, c = rows_of(ssp, sc, "compiled", "jacobi", clock)
    assert py.tobytes() == c.tobytes()
    if clock == "accumulated":  # t_{k+1} = t_k + h
        expected = [0.0]
        for _ in range(500):
            expected.append(expected[-1] + 1e-4)
    else:  # integer nanoseconds
        expected = [k * 100_000 / 1e9 for k in range(501)]
    assert c[:, 0].tolist() == expected


def run_both(monkeypatch, tmp_path, ssp, sc, arguments=lambda kind: {}):
    """run_scenario with each stepper (and ``arguments(stepper)``): {stepper: (error or None,
    run.json without wall times, result file bytes)}."""
    out = {}
    for kind in ("python", "compiled"):
        monkeypatch.setenv("TAPMP_STEPPER", kind)
        err = None
        try:
            run_scenario(sc, ssp, tmp_path / kind, **arguments(kind))
        except BaseException as e:  # noqa: B902  (an Interrupted is a KeyboardInterrupt)
            err = e
        info = json.loads((tmp_path / kind / "run.json").read_text())
        for key in ("wall_time_s", "real_time_factor"):
            info.pop(key, None)
        out[kind] = (err, info, (tmp_path / kind / "results.csv").read_bytes())
    return out


@pytest.mark.parametrize("fault", ["status", "error_log"])
@pytest.mark.parametrize("ordering", ["gauss-seidel", "jacobi"])
def test_a_failing_fmu_gives_the_same_message_exit_code_and_partial_rows(fault, ordering, faulty_ssps,
                                                                         monkeypatch, tmp_path):
    sc = paper_scenario(0.01, f'ordering="{ordering}"')
    res = run_both(monkeypatch, tmp_path, faulty_ssps[fault], sc)
    (e_py, info_py, csv_py), (e_c, info_c, csv_c) = res["python"], res["compiled"]
    assert type(e_c) is type(e_py) is CoSimulationError
    assert str(e_c) == str(e_py) and e_c.element == e_py.element == "plant" and e_c.time == e_py.time
    assert str(e_c).startswith("plant: doStep failed at t = 0.0005 s: ")
    assert info_c == info_py and info_c["status"] == "failed" and info_c["exit_code"] == 2
    assert csv_c == csv_py
    assert len(csv_c.decode().splitlines()) == 1 + 6  # header, t = 0 ... 0.5 ms: the steps before the failure


def test_a_breach_of_the_envelope_gives_the_same_divergence_error_and_rows(built, monkeypatch, tmp_path):
    """motor_travel limit of 1 mm below the trajectory's travel: the loop leaves it mid-block."""
    sc = paper_scenario(0.5, "limits.motor_travel=0.0005")
    res = run_both(monkeypatch, tmp_path, built["ssp"], sc)
    (e_py, info_py, csv_py), (e_c, info_c, csv_c) = res["python"], res["compiled"]
    assert type(e_c) is type(e_py) is DivergenceError
    assert str(e_c) == str(e_py) and "outside the envelope |plant.q" in str(e_c)
    assert (e_c.signal, e_c.value, e_c.time) == (e_py.signal, e_py.value, e_py.time)
    assert info_c == info_py and info_c["exit_code"] == 2
    assert csv_c == csv_py
    rows = np.loadtxt(csv_c.decode().splitlines()[1:], delimiter=",", ndmin=2)
    assert 1 < len(rows) < 5001 and rows[-1, 0] < e_c.time  # whole rows, up to the step before the breach


def test_a_stop_request_ends_both_at_the_same_block_with_the_same_rows(built, monkeypatch, tmp_path):
    sc = paper_scenario(0.5)

    def arguments(kind):  # a stopped token stays stopped in this process: one per run
        return {"progress": lambda k, n: request_stop(f"stepper-test-{kind}"), "stop_token": f"stepper-test-{kind}"}

    res = run_both(monkeypatch, tmp_path, built["ssp"], sc, arguments)
    (e_py, info_py, csv_py), (e_c, info_c, csv_c) = res["python"], res["compiled"]
    assert str(e_c) == str(e_py) == "interrupted by SIGTERM (the study was stopped) at t = 0.0999 s"
    assert info_c == info_py and info_c["exit_code"] == 143 and info_c["status"] == "interrupted"
    assert csv_c == csv_py and len(csv_c.decode().splitlines()) == 1 + 1000


@pytest.mark.slow
def test_the_core_is_built_once_into_the_cache_folder(tmp_path, monkeypatch):
    """A fresh cache: built on first use under the lock, then found; the library is outside the package."""
    monkeypatch.setenv("TAPMP_CACHE", str(tmp_path / "cache"))
    path = stepper.build()
    assert path.parent == tmp_path / "cache" and path.is_file() and path.suffix == ".so"
    mtime = path.stat().st_mtime_ns
    assert stepper.build() == path and path.stat().st_mtime_ns == mtime


@pytest.mark.slow
def test_a_core_that_cannot_be_built_is_one_line_and_the_run_steps_in_python(tmp_path, built, monkeypatch):
    """No compiler: `tapmp run` says so in one line and completes with the Python loop (the C
    model's library is there, as after any build: only the stepping core is missing)."""
    library = cmodel.library_path()
    monkeypatch.setenv("TAPMP_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("CC", str(tmp_path / "no-such-cc"))
    (tmp_path / "cache").mkdir()
    shutil.copyfile(library, cmodel.cached_library_path())
    env = dict(os.environ, TAPMP_CACHE=str(tmp_path / "cache"), CC=str(tmp_path / "no-such-cc"),
               TMPDIR=str(tmp_path))
    env.pop("TAPMP_STEPPER", None)
    res = subprocess.run([sys.executable, "-m", "orchestrator", "run", PAPER, "--ssp", str(built["ssp"]),
                          "--out", str(tmp_path / "out"), "--set", "stop_time=0.01", "--no-progress"],
                         capture_output=True, text=True, timeout=300, env=env)
    assert res.returncode == 0, res.stderr
    notes = [line for line in res.stderr.splitlines() if "compiled stepping core" in line]
    assert notes == [f"note: compiled stepping core unavailable (the compiled stepping core (x86_64-linux): C compiler "
                     f"{str(tmp_path / 'no-such-cc')!r} not found (unset CC to use zig cc from the ziglang package)); "
                     "stepping in Python"]
    columns, rows = read_results(tmp_path / "out")
    assert rows.shape == (101, len(columns))


def test_a_bad_stepper_is_refused_naming_the_allowed_values(built, monkeypatch):
    monkeypatch.setenv("TAPMP_STEPPER", "fortran")
    with pytest.raises(CoSimulationError, match=r"^stepper = 'fortran' is invalid \(TAPMP_STEPPER or the "
                                                r"stepper argument\): allowed are auto, compiled, python$"):
        CoSimulation(built["ssp"], {})


def test_csv_rows_read_back_to_the_same_doubles_at_every_magnitude():
    """Shortest round-trip text for every magnitude and sign, subnormals and the extremes
    included; a block with a non-finite value is written with Python's repr."""
    from orchestrator.tool.writers import format_csv_rows
    rng = np.random.default_rng(7)
    block = rng.standard_normal((300, 12)) * np.logspace(-310, 300, 12)
    block[0, :6] = [0.0, -0.0, 5e-324, 1.7976931348623157e308, 1e-05, 0.1]
    text = format_csv_rows(block).decode()
    lines = text.splitlines()
    assert text.endswith("\n") and len(lines) == 300 and all(line.count(",") == 11 for line in lines)
    back = np.array([[float(x) for x in line.split(",")] for line in lines])
    assert back.tobytes() == block.tobytes()
    assert lines[0].split(",")[:2] == ["0.0", "-0.0"]

    def digits(text):  # the significant digits of a number's text
        return text.lstrip("-").split("e")[0].replace(".", "").strip("0")
    assert all(digits(x) == digits(repr(float(v))) for line, row in zip(lines, block)
               for x, v in zip(line.split(","), row))  # the digits of Python's repr: the shortest
    block[1, 3] = np.inf
    assert format_csv_rows(block[:2]).decode().splitlines()[1].split(",")[3] == "inf"


@pytest.mark.slow
def test_tapmp_build_builds_the_core_into_the_cache(tmp_path):
    env = dict(os.environ, TAPMP_CACHE=str(tmp_path / "cache"), TMPDIR=str(tmp_path))
    res = subprocess.run([sys.executable, "-m", "orchestrator", "build", "--out", str(tmp_path / "build")],
                         capture_output=True, text=True, timeout=600, env=env)
    assert res.returncode == 0, res.stderr
    built = list((tmp_path / "cache").glob("tapmp_stepper_*.so"))
    assert len(built) == 1 and f"compiled stepping core in {built[0]}" in res.stdout.splitlines()
    assert (tmp_path / "build" / "TAPMP.ssp").is_file()
