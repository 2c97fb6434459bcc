"""`tapmp run --real-time` through the real command: a paced run writes the unpaced run's files, its
statistics under run.json's real_time (the keys a benchmark reads), a summary and real_time.png; the
overrun policy abort fails the run naming the step, with its results written; SIGINT ends a paced run
as any interrupted run; bad input is one line, exit 2, before any output folder is made."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from orchestrator.cli import main
from orchestrator.engine.pacing import INJECT_ENV

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "scenarios" / "paper_simulation.toml"
KEYS = {"factor", "overrun_policy", "steps", "lateness_s", "execution_s", "overruns", "longest_overrun_run",
        "achieved_factor", "measures", "histogram"}


@pytest.fixture(scope="module")
def ssp(tmp_path_factory):
    from orchestrator.builder.build_native import build_native
    return build_native(tmp_path_factory.mktemp("native"), families=("fmi2",), log=lambda *_: None,
                        windows=False)["fmi2"]["ssp"]


def run(out, *args, stop="0.02"):
    return main(["run", str(PAPER), "--out", str(out), "--set", f"stop_time={stop}", "--no-progress", *args])


@pytest.mark.parametrize("args, line", [
    (["--real-time", "0"], "error: --real-time = '0' is invalid: allowed is a finite number > 0 (simulated seconds "
                           "per wall second: 1 the wall clock, 0.5 half speed, 10 ten times faster)"),
    (["--real-time", "-2"], "error: --real-time = '-2' is invalid: allowed is a finite number > 0"),
    (["--real-time", "inf"], "error: --real-time = 'inf' is invalid: allowed is a finite number > 0"),
    (["--real-time", "nan"], "error: --real-time = 'nan' is invalid: allowed is a finite number > 0"),
    (["--real-time", "fast"], "error: --real-time = 'fast' is invalid: allowed is a finite number > 0"),
    (["--overrun", "skip"], "error: --overrun is for a paced run: it goes with --real-time [FACTOR]"),
    (["--real-time-trace"], "error: --real-time-trace is for a paced run: it goes with --real-time [FACTOR]"),
    (["--real-time", "--rt-priority", "0"], "error: --rt-priority = '0' is invalid: allowed is an integer in [1, 99]"),
    (["--real-time", "--spin-margin", "-5"], "error: --spin-margin = '-5' is invalid: allowed is a number of "
                                             "microseconds in [0, 100000]"),
    (["--real-time", "--set", "plant_interface=me"], "error: real time (--real-time) needs the compiled stepping "
                                                     "core: a Model Exchange plant (plant_interface = \"me\") steps "
                                                     "in the Python loop"),
])
def test_bad_input_is_one_line_exit_2_and_no_folder(tmp_path, capsys, args, line):
    assert run(tmp_path / "out", *args) == 2
    err = capsys.readouterr().err
    assert err.startswith(line) and err.count("\n") == 1
    assert not (tmp_path / "out").exists()


def test_real_time_with_the_python_loop_is_refused(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("TAPMP_STEPPER", "python")
    assert run(tmp_path / "out", "--real-time", "2") == 2
    assert capsys.readouterr().err == ("error: real time (--real-time) needs the compiled stepping core: "
                                       "TAPMP_STEPPER=python selects the Python loop\n")
    assert not (tmp_path / "out").exists()


def test_a_study_takes_no_real_time(tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["study", "robustness", "--real-time"])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert "unrecognized arguments: --real-time" in err and err.count("\n") == 1


@pytest.mark.slow  # builds the native FMUs, runs paced
def test_a_paced_run_writes_the_unpaced_files_its_statistics_and_figure(ssp, tmp_path, capsys):
    assert run(tmp_path / "fast", "--ssp", ssp) == 0
    capsys.readouterr()
    assert run(tmp_path / "paced", "--ssp", ssp, "--real-time", "0.5", "--real-time-trace") == 0
    out = capsys.readouterr().out.splitlines()
    for name in ("results.csv", "metrics.json"):
        assert (tmp_path / "paced" / name).read_bytes() == (tmp_path / "fast" / name).read_bytes()
    info = json.loads((tmp_path / "paced" / "run.json").read_text())
    rt = info["real_time"]
    assert KEYS <= set(rt) and info["status"] == "completed"
    assert rt["factor"] == 0.5 and rt["steps"] == 200 and rt["overrun_policy"] == "continue"
    assert set(rt["lateness_s"]) >= {"p50", "p99", "p999", "max"} and set(rt["execution_s"]) >= {"p50", "max"}
    assert rt["wall_time_s"] >= 0.04 and rt["achieved_factor"] <= 0.5  # 0.02 s at half speed
    assert set(rt["measures"]) == {"mlockall", "cpu_affinity", "sched_fifo"}
    assert all(set(m) == {"applied", "detail"} for m in rt["measures"].values())
    assert (tmp_path / "paced" / "real_time.png").stat().st_size > 10000
    trace = (tmp_path / "paced" / "real_time_trace.csv").read_text().splitlines()
    assert trace[0] == "step,lateness_s,execution_s" and len(trace) == 201 and trace[1].startswith("1,")
    assert {"real_time.png", "real_time_trace.csv"} <= set(info["tapmp_files"])
    assert out[1].startswith("real time: factor 0.5 (period 200 us), overrun policy continue, 200 steps, "
                             "achieved factor ")
    assert out[2].startswith("  lateness [us] (completion - deadline, > 0 overrun): p50 ")
    assert out[3].startswith(f"  overruns: {rt['overruns']} (longest run {rt['longest_overrun_run']}")
    assert out[4].startswith("  measures: mlockall ")


@pytest.mark.slow
def test_abort_fails_the_run_naming_the_step_with_its_results_written(ssp, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv(INJECT_ENV, "50:0.004")  # the test hook: step 50 takes 4 ms longer, period 1 ms
    assert run(tmp_path / "out", "--ssp", ssp, "--real-time", "0.1", "--overrun", "abort") == 2
    err = capsys.readouterr().err
    info = json.loads((tmp_path / "out" / "run.json").read_text())
    assert info["status"] == "failed" and info["exit_code"] == 2 and info["error"] == err[len("error: "):].strip()
    assert info["real_time"]["overrun_policy"] == "abort" and info["real_time"]["overruns"] == 1
    step = info["real_time"]["first_overruns"][0]["step"]
    assert err.startswith(f"error: real time: step {step} (to t = ") and "after its deadline (overrun policy abort)" in err
    assert step <= 50 and info["real_time"]["steps"] == step
    rows = (tmp_path / "out" / "results.csv").read_text().splitlines()
    assert len(rows) == 1 + 1 + step  # the header, t = 0 and every step up to the late one
    assert (tmp_path / "out" / "real_time.png").is_file()


@pytest.mark.slow
def test_sigint_ends_a_paced_run_as_any_interrupted_run(ssp, tmp_path):
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "orchestrator", "run", str(PAPER), "--ssp", str(ssp), "--out",
                             str(out), "--set", "stop_time=3", "--real-time", "--no-progress"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:  # until the paced run writes rows
        if (out / "results.csv").is_file() and len((out / "results.csv").read_bytes().splitlines()) > 1000:
            break
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130
    assert "interrupted by SIGINT" in err and err.count("\n") == 1
    info = json.loads((out / "run.json").read_text())
    assert info["status"] == "interrupted" and info["signal"] == "SIGINT"
    rows = len((out / "results.csv").read_text().splitlines()) - 2
    assert 1000 <= rows < 30000 and info["real_time"]["steps"] == rows
    assert (out / "real_time.png").is_file()
