"""`tapmp compare` on a process pool (--jobs) and its figures drawn from min/max-decimated
traces: the same files as one run after the other, the same errors, and every sample inside
the drawn envelope."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from orchestrator.tool.baselines import BASELINES
from orchestrator.tool.plots import COLUMNS, decimate
from orchestrator.tool.pool import cores, parse_jobs
from tests.support.runs import PAPER

pytestmark = pytest.mark.slow  # tapmp compare on a process pool


def tapmp(*args, tmp_path):
    return subprocess.run([sys.executable, "-m", "orchestrator", *map(str, args)], capture_output=True, text=True,
                          timeout=600, env=dict(os.environ, TMPDIR=str(tmp_path)))


@pytest.mark.parametrize("value", ["0", "-1", "two", "1.5", "", str(cores() + 1)])
def test_a_bad_jobs_is_one_line_naming_value_and_cores_exit_2(value, built, tmp_path):
    res = tapmp("compare", PAPER, "--ssp", built["ssp"], "--out", tmp_path / "c", "--jobs", value, "--no-progress",
                tmp_path=tmp_path)
    n = cores()
    assert res.returncode == 2
    assert res.stderr.splitlines() == [f"error: --jobs = {value!r} is invalid: allowed is a positive integer up "
                                       f"to the {n} core{'s' if n > 1 else ''} of this machine"]
    assert not (tmp_path / "c").exists()  # refused before anything ran


def test_parse_jobs_defaults_to_one_per_core():
    assert parse_jobs(None) == cores() == len(os.sched_getaffinity(0))
    assert parse_jobs("1") == 1 and parse_jobs(str(cores())) == cores()


def test_compare_on_a_pool_writes_the_same_files_as_one_run_after_the_other(built, tmp_path):
    pool = str(min(2, cores()))  # a pool of 2 on every machine of this project (2 cores or more)
    out = {}
    for jobs in ("1", pool):
        res = tapmp("compare", PAPER, "--ssp", built["ssp"], "--out", tmp_path / jobs, "--set", "stop_time=0.05",
                    "--jobs", jobs, "--no-progress", tmp_path=tmp_path)
        assert res.returncode == 0, res.stderr
        out[jobs] = res.stdout.replace(str(tmp_path / jobs), "OUT").replace(f"--jobs {jobs}", "--jobs N")
    assert out["1"] == out[pool]
    runs = json.loads((tmp_path / "1" / "comparison.json").read_text())["runs"]
    assert set(runs) == {b.name for b in BASELINES}
    for name in runs:
        for f in ("results.csv", "metrics.json"):
            assert (tmp_path / "1" / name / f).read_bytes() == (tmp_path / pool / name / f).read_bytes(), (name, f)
        assert json.loads((tmp_path / pool / name / "run.json").read_text())["status"] == "completed"
    # the noise runs, on the same pool's workers (FMUs kept loaded and reset between runs)
    noisy = sorted(p.name for p in (tmp_path / "1" / "noise").iterdir())
    assert len(noisy) == 10 and noisy == sorted(p.name for p in (tmp_path / pool / "noise").iterdir())
    for name in noisy:
        assert ((tmp_path / "1" / "noise" / name / "metrics.json").read_bytes()
                == (tmp_path / pool / "noise" / name / "metrics.json").read_bytes()), name
    md = {j: (tmp_path / j / "comparison.md").read_text().replace(str(tmp_path / j), "OUT")
          .replace(f"--jobs {j}", "--jobs N") for j in ("1", pool)}
    assert md["1"] == md[pool] and "SC-DC" in md["1"]
    figures = sorted(p.name for p in (tmp_path / pool).glob("*.png"))
    assert figures == sorted(p.name for p in (tmp_path / "1").glob("*.png")) and len(figures) == 5


def test_a_failing_run_on_the_pool_is_the_same_one_line_error_and_exit_code(faulty_ssps, tmp_path):
    res = {jobs: tapmp("compare", PAPER, "--ssp", faulty_ssps["status"], "--out", tmp_path / jobs, "--set",
                       "stop_time=0.002", "--jobs", jobs, "--no-progress", tmp_path=tmp_path)
           for jobs in ("1", str(min(2, cores())))}
    for jobs, r in res.items():
        assert r.returncode == 2, r.stderr
        assert r.stderr.splitlines()[-1] == ("error: plant: doStep failed at t = 0.0005 s: a call returned ERROR, "
                                             "above fmi2Warning")
        info = json.loads((tmp_path / jobs / "comparison.json").read_text())
        assert info["status"] == "failed" and info["error"] == r.stderr.splitlines()[-1][len("error: "):]


@pytest.mark.parametrize("n", [10, 3 * COLUMNS, 25_001, 100_003])
def test_the_decimated_envelope_contains_every_sample(n):
    rng = np.random.default_rng(n)
    t = np.arange(n) * 1e-4
    y = np.cumsum(rng.standard_normal(n)) + np.where(rng.random(n) < 0.01, 50.0, 0.0)  # drift and spikes
    xd, yd = decimate(t, y)
    assert np.all(np.diff(xd) > 0) and xd[0] == t[0] and xd[-1] == t[-1]
    assert len(xd) <= 3 * COLUMNS + 2 * (n // COLUMNS + 1)
    if n < 4 * COLUMNS:
        assert len(xd) == n
    assert set(zip(xd.tolist(), yd.tolist())) <= set(zip(t.tolist(), y.tolist()))  # samples, nothing made up
    # within one pixel column (n / COLUMNS samples, rounded up) of every sample the drawn trace
    # reaches both below and above its value: the decimated envelope contains every sample
    w = -(-n // COLUMNS) * 1e-4 + 1e-12
    lo, hi = np.searchsorted(xd, t - w), np.searchsorted(xd, t + w, side="right")
    for i in range(n):
        near = yd[lo[i]:hi[i]]
        assert near.min() <= y[i] <= near.max(), i
    assert yd.max() == y.max() and yd.min() == y.min()


def test_sigterm_stops_the_pools_runs_and_starts_no_more(built, tmp_path):
    import signal
    import time
    out = tmp_path / "c"
    proc = subprocess.Popen([sys.executable, "-m", "orchestrator", "compare", str(PAPER), "--ssp", str(built["ssp"]),
                             "--out", str(out), "--set", "stop_time=10", "--jobs", str(min(2, cores())),
                             "--no-progress"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=dict(os.environ, TMPDIR=str(tmp_path)))
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not list(out.glob("*/results.csv")):
        time.sleep(0.05)  # the first runs are stepping
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 143, err
    assert err.splitlines()[-1] == "interrupted by SIGTERM: the results so far are in the output folder"
    assert json.loads((out / "comparison.json").read_text())["status"] == "interrupted"
    runs = {p.parent.name: json.loads(p.read_text()) for p in out.glob("*/run.json")}
    assert any(r["status"] == "interrupted" and r["exit_code"] == 143 for r in runs.values())
    assert {r["status"] for r in runs.values()} <= {"completed", "interrupted"}
    assert len(runs) <= min(2, cores()) + 1  # the runs going at the signal (and one just done): no new one started
