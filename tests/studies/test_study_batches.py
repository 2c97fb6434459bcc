"""Cases in batches (orchestrator.studies.batches): the size rule, and on a real two-worker Dask
LocalCluster through the native FMUs: a batched study equals the same study one case per task,
a case that fails inside a batch fails alone, and --resume after a killed client runs exactly
the cases without a row."""

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from orchestrator.cli import main
from orchestrator.studies.batches import MAX_BATCH, batch_size, case_seconds, split, window
from orchestrator.studies.run import run_study
from orchestrator.studies.study import load_study
from tests.support.studies import client, write_study  # noqa: F401 (client is a fixture)

ROOT = Path(__file__).resolve().parents[2]


def test_the_batch_size_is_a_second_of_work_balanced_over_the_threads_and_capped():
    # 0.05 s cases (500 steps): 0.03 s + 500 x 6e-6 s = 0.033 s each, so 30 per second of work
    assert case_seconds(500) == pytest.approx(0.033)
    assert batch_size(10_000, 0.033, 2) == 30
    assert batch_size(1_000, 0.033, 50) == 5      # 1000 / (4 x 50): every thread gets 4 batches
    assert batch_size(7, 0.033, 2) == 1           # fewer cases than 4 batches per thread: one each
    assert batch_size(1_000_000, 1e-4, 2) == MAX_BATCH == 200
    assert batch_size(100, 5.0, 2) == 1           # a case longer than the target: one per task
    assert batch_size(100, 0.033, 0) == 25        # no worker connected yet: as for one thread
    assert (window(0), window(1), window(8)) == (2, 2, 16)
    assert split(list("abcdefg"), 3) == [["a", "b", "c"], ["d", "e", "f"], ["g"]]


def test_a_negative_batch_size_is_refused_in_one_line(tmp_path, capsys):
    study = write_study(tmp_path, '[set]\nstop_time = 0.02\n[grid]\nlaw = ["sc-dc"]\n')
    assert main(["study", str(study), "--batch-size", "-1"]) == 2
    assert capsys.readouterr().err.splitlines()[-1] == (
        "error: --batch-size = -1 is invalid: allowed is an integer >= 1, or 0 for the automatic size")


def table(out: Path) -> dict:
    """study.csv by case without the columns that differ between runs (wall time, worker); the
    stability check's spectral radius to 12 digits (its eigenvalues come from LAPACK, whose last
    bits may differ between processes), every other field as written."""
    with open(out / "study.csv", newline="") as f:
        return {r["case"]: {k: (f"{float(v):.12g}" if k == "spectral_radius" and v else v) for k, v in r.items()
                            if k not in ("wall_time_s", "worker")} for r in csv.DictReader(f)}


def case_files(out: Path) -> dict:
    """{case/file: content} of every case folder, run.json without its wall times."""
    files = {}
    for path in sorted((out / "cases").glob("*/*")):
        if path.name == ".tapmp.lock":
            continue
        data = path.read_text()
        if path.name == "run.json":
            data = {k: v for k, v in json.loads(data).items() if k not in ("wall_time_s", "real_time_factor")}
        files[f"{path.parent.name}/{path.name}"] = data
    return files


# 300 cases of 0.05 s: 150 values of D, each with the default gains (completes) and the paper's
# experimental gains, which with no force (force_limit 0) leave the domain at once (diverged or failed)
D_VALUES = ", ".join(f"{400.0 + 4 * i}" for i in range(150))
MIXED = (f'[set]\nstop_time = 0.05\n"plant.force_limit" = 0.0\n[grid]\n"gain_overrides.D" = [{D_VALUES}]\n'
         'gains = ["default", "paper_experiment"]\n')


@pytest.fixture(scope="module")
def ssp(tmp_path_factory):
    """The native FMI 2.0 FMUs for this machine and their SSP."""
    from orchestrator.builder.build_native import build_native
    return build_native(tmp_path_factory.mktemp("native"), families=("fmi2",), log=lambda *_: None,
                        windows=False)["fmi2"]["ssp"]


@pytest.mark.slow  # two studies of 300 cases on the LocalCluster
def test_a_batched_study_equals_one_case_per_task_and_a_failing_case_fails_alone(ssp, client, tmp_path):
    study = load_study(write_study(tmp_path, MIXED))
    batched = run_study(study, ssp, client, tmp_path / "batched", progress=False)
    single = run_study(study, ssp, client, tmp_path / "single", progress=False, batch_size=1)
    # a second of 0.033 s cases (the rule's cost), fewer than 300 / (4 batches x 2 threads) = 37
    assert batched["batch_size"] == 30 and single["batch_size"] == 1
    rows = table(tmp_path / "batched")
    assert rows == table(tmp_path / "single") and len(rows) == 300
    assert case_files(tmp_path / "batched") == case_files(tmp_path / "single")
    # every batch of 30 holds both kinds; each failing case is its own row, its neighbours complete
    for i in range(0, 300, 2):
        done, bad = rows[f"c{i:04d}"], rows[f"c{i + 1:04d}"]
        assert done["gains"] == "default" and done["status"] == "completed" and float(done["objective"]) < 1.0
        assert bad["gains"] == "paper_experiment" and bad["status"] in ("diverged", "failed") and bad["error"]
    assert batched["counts"]["completed"] == 150


def start(*args, tmpdir: Path) -> subprocess.Popen:
    """`tapmp ARGS` in a child process, in a session of its own (its LocalCluster's processes in
    its process group), with its temp folder in ``tmpdir``."""
    tmpdir.mkdir(parents=True, exist_ok=True)
    return subprocess.Popen([sys.executable, "-m", "orchestrator", *map(str, args)], start_new_session=True,
                            env=dict(os.environ, TMPDIR=str(tmpdir)), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def whole_rows(path: Path) -> list[str]:
    """The case of every whole row of study.csv (a line end written), in file order."""
    if not path.exists():
        return []
    lines = path.read_bytes().split(b"\n")[1:-1]  # the header; the last item is after the last line end
    return [line.split(b",")[0].decode() for line in lines]


@pytest.mark.slow  # tapmp study in child processes on a LocalCluster, killed
def test_resume_after_a_killed_client_runs_exactly_the_cases_without_a_row(ssp, tmp_path):
    values = ", ".join(f"{400.0 + 5 * i}" for i in range(200))
    study = write_study(tmp_path, f'[set]\nstop_time = 0.05\n[grid]\n"gain_overrides.D" = [{values}]\n')
    out = tmp_path / "out"
    args = ("study", study, "--ssp", ssp, "--out", out, "--workers", "2", "--batch-size", "10",
            "--no-progress")
    proc = start(*args, tmpdir=tmp_path / "tmp")
    deadline = time.monotonic() + 240
    while len(whole_rows(out / "study.csv")) < 30:
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "no 30 rows within 240 s"
        time.sleep(0.02)
    os.killpg(proc.pid, signal.SIGKILL)  # the client, its scheduler and workers, all at once
    proc.wait(timeout=60)
    before = (out / "study.csv").read_bytes()
    kept = whole_rows(out / "study.csv")
    assert 30 <= len(kept) < 200 and len(set(kept)) == len(kept)

    resumed = start(*args, "--resume", tmpdir=tmp_path / "tmp2")
    stdout, stderr = resumed.communicate(timeout=600)
    assert resumed.returncode == 0, stdout + stderr + "\n".join(l for l in (out / "study.csv").read_text().splitlines() if "failed" in l)
    assert f"200 cases ({200 - len(kept)} run now, " in stdout and "200 completed, 0 diverged, 0 failed" in stdout
    after = (out / "study.csv").read_bytes()
    assert after.startswith(before[:before.rfind(b"\n") + 1])  # the whole rows stay byte for byte
    cases = whole_rows(out / "study.csv")
    assert sorted(cases) == [f"c{i:04d}" for i in range(200)]  # each once: exactly the missing ones ran
