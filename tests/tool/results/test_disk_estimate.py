"""Output size before a run: the recorded rows and the estimated size against real result
files, the lines printed above 100 MB and 1 GB, and the refusal (exit 2, one line, nothing
written) when the disk cannot hold the results; --record-every keeps every N-th step while the
metrics still use every step."""

import io
import json
import os
import re
import shutil
import subprocess
import sys

import pytest

from tests.support.runs import PAPER
from orchestrator.tool.estimate import (BYTES_PER_VALUE, RECORDED_COLUMNS, SECONDS_PER_ROW, SECONDS_PER_STEP,
                                        DiskSpaceError, check_output_size, output_estimate, recorded_rows)
from orchestrator.tool.reading import read_results
from orchestrator.tool.scenario import load

pytestmark = pytest.mark.slow  # run, compare, study and reproduce in child processes


def tapmp(*args, tmp_path):
    return subprocess.run([sys.executable, "-m", "orchestrator", *map(str, args)], capture_output=True, text=True,
                          timeout=600, env=dict(os.environ, TMPDIR=str(tmp_path)))


@pytest.mark.parametrize("steps, every, rows", [
    (25000, 1, 25001),   # step 0 and every step
    (25000, 10, 2501),   # 0, 10, ..., 25000
    (25000, 3, 8335),    # 0, 3, ..., 24999 (8334 rows) and the last step 25000
    (25000, 25000, 2),   # first and last
])
def test_recorded_rows_by_hand(steps, every, rows):
    sc = load(PAPER).with_changes(stop_time=steps * 1e-4, record_every=every)
    assert sc.n_steps == steps
    assert recorded_rows(sc) == rows


@pytest.mark.parametrize("fmt, every", [("csv", 1), ("csv", 7), ("mat", 1)])
def test_the_estimate_matches_the_files_a_run_writes(built, tmp_path, fmt, every):
    out = tmp_path / "run"
    res = tapmp("run", PAPER, "--ssp", built["ssp"], "--out", out, "--set", "stop_time=0.05", "--format", fmt,
                "--record-every", every, "--no-progress", tmp_path=tmp_path)
    assert res.returncode == 0, res.stderr
    sc = load(PAPER).with_changes(stop_time=0.05, record_every=every, format=fmt)
    columns, rows = read_results(out)
    assert rows.shape == (recorded_rows(sc), RECORDED_COLUMNS) and len(columns) == RECORDED_COLUMNS
    size = (out / f"results.{fmt}").stat().st_size
    estimate, seconds = output_estimate([sc])
    assert estimate == recorded_rows(sc) * RECORDED_COLUMNS * BYTES_PER_VALUE[fmt]
    assert seconds == pytest.approx(500 * SECONDS_PER_STEP + recorded_rows(sc) * SECONDS_PER_ROW)
    assert 0.8 < size / estimate < 1.25, (size, estimate)


def test_record_every_keeps_every_nth_step_and_the_same_metrics(built, tmp_path):
    metrics = {}
    for every in ("1", "10"):
        out = tmp_path / every
        res = tapmp("run", PAPER, "--ssp", built["ssp"], "--out", out, "--set", "stop_time=0.0105",
                    "--record-every", every, "--no-progress", tmp_path=tmp_path)
        assert res.returncode == 0, res.stderr
        metrics[every] = json.loads((out / "metrics.json").read_text())
    _, full = read_results(tmp_path / "1")
    _, kept = read_results(tmp_path / "10")
    assert full.shape[0] == 106 and kept.shape[0] == 12  # steps 0..105; 0, 10, ..., 100 and 105
    assert (kept == full[[*range(0, 101, 10), 105]]).all()
    assert metrics["10"]["tracking_mae_um"] == metrics["1"]["tracking_mae_um"]
    assert metrics["10"]["sync_mae_um"] == metrics["1"]["sync_mae_um"]


def test_the_estimate_is_printed_above_100_mb_and_warned_about_above_1_gb(tmp_path):
    small, mid, big = (load(PAPER).with_changes(stop_time=t) for t in (2.5, 20.0, 200.0))
    for sc, lines in ((small, 0), (mid, 1), (big, 2)):
        stream = io.StringIO()
        size = check_output_size([sc], tmp_path / "out", "paper_simulation", stream=stream)
        rows = sc.n_steps + 1
        assert size == rows * RECORDED_COLUMNS * 21
        text = stream.getvalue().splitlines()
        assert len(text) == lines
        if lines:
            assert text[0].startswith(f"paper_simulation: about {size / 1e6 if size < 1e9 else size / 1e9:.3g} "
                                      f"{'MB' if size < 1e9 else 'GB'} of results ({rows} rows x 40 columns, csv) "
                                      "and about ")
            # the CPU time, and the wall time it takes on this machine's CPUs at its load (one process)
            cpu = sc.n_steps * SECONDS_PER_STEP + rows * SECONDS_PER_ROW
            assert re.fullmatch(rf".* \d+ s of runs \(1 process\(es\) on {os.cpu_count()} CPU\(s\) at a load of "
                                rf"[\d.]+, {cpu:.0f} s of CPU\)", text[0]), text[0]
        if lines == 2:
            assert text[1].startswith("warning: paper_simulation: the results will take about 1.68 GB of ")
    assert not (tmp_path / "out").exists()
    # the same 200 s (2e6 steps) as MAT with every 10th step: 200001 rows of 8-byte values, 64 MB: nothing printed
    stream = io.StringIO()
    assert check_output_size([big.with_changes(format="mat", record_every=10)], tmp_path, "x", stream=stream) == \
        200001 * 40 * 8
    assert stream.getvalue() == ""


def test_results_larger_than_the_free_space_are_refused(tmp_path):
    free = shutil.disk_usage(tmp_path).free
    stop = 10 * free / (RECORDED_COLUMNS * 21) * 1e-4  # ten times the free space, as CSV
    sc = load(PAPER).with_changes(stop_time=round(stop, 1))
    with pytest.raises(DiskSpaceError, match=r"paper_simulation: the runs would write about [0-9.]+ [kMGT]?B into "):
        check_output_size([sc], tmp_path / "a" / "b", "paper_simulation", stream=io.StringIO())


@pytest.mark.parametrize("command", ["run", "compare"])
def test_the_command_line_refuses_with_one_line_naming_size_and_free_space_and_writes_nothing(built, tmp_path,
                                                                                               command):
    out = tmp_path / "out"
    res = tapmp(command, PAPER, "--ssp", built["ssp"], "--out", out, "--set", "stop_time=1e6", "--no-progress",
                tmp_path=tmp_path)
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert re.fullmatch(r"error: paper_simulation: the runs would write about [0-9.]+ TB into \S+ but its disk has "
                        r"[0-9.]+ [kMGT]?B free: shorten stop_time, record fewer rows \(--record-every N\) or write "
                        r"MAT \(--format mat\)", lines[-1]), lines
    assert [x for x in lines if not x.startswith("warning: ")] == [lines[-1]]  # the plausibility warning may precede
    assert not out.exists() and res.stdout == ""


@pytest.mark.parametrize("command", ["run", "compare", "reproduce", "study"])
@pytest.mark.parametrize("value", ["0", "-3", "ten", "1.5", "99999999999999999999"])
def test_a_bad_record_every_is_one_line_exit_2_and_writes_nothing(tmp_path, command, value):
    target = {"run": [PAPER], "compare": [PAPER], "reproduce": [],
              "study": [PAPER.parent.parent / "studies" / "gain_sweep.toml"]}[command]
    res = tapmp(command, *target, "--out", tmp_path / "out.md" if command == "reproduce" else tmp_path / "out",
                "--record-every", value, "--no-progress", tmp_path=tmp_path)
    assert res.returncode == 2
    assert res.stderr.strip().splitlines() == [f"error: --record-every = {value!r} is invalid: allowed is an integer "
                                               "from 1 to 2147483647 (keep every N-th step)"]
    assert not any(p.name.startswith("out") for p in tmp_path.iterdir())


def test_a_study_takes_format_and_record_every_for_every_case(built, tmp_path):
    study = tmp_path / "s.toml"
    study.write_text(f'[study]\nname = "s"\nbase = "{PAPER}"\noutput = "{tmp_path / "out"}"\nkeep_results = true\n'
                     '[set]\nstop_time = 0.0105\n[grid]\nlaw = ["sc-dc", "apd-dc"]\n')
    res = tapmp("study", study, "--ssp", built["ssp"], "--workers", "1", "--format", "mat", "--record-every", "10",
                "--no-progress", tmp_path=tmp_path)
    assert res.returncode == 0, res.stderr
    cases = sorted((tmp_path / "out" / "cases").iterdir())
    assert len(cases) == 2
    for case in cases:
        run = json.loads((case / "run.json").read_text())
        assert (run["format"], run["record_every"]) == ("mat", 10)
        assert read_results(case)[1].shape == (12, RECORDED_COLUMNS)  # steps 0, 10, ..., 100 and 105
