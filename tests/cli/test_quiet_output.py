"""Terminal output: `tapmp compare` into a log (not a terminal) prints a short summary whose
rows are the runs' metrics.json values, no long line and no carriage-return progress; the
progress of a long task off a terminal is one line per 10 %."""

import json
import os
import subprocess
import sys

import pytest

from tests.support.runs import PAPER
from orchestrator.tool.baselines import BASELINES
from orchestrator.tool.progress import Progress

pytestmark = pytest.mark.slow  # tapmp compare in a child process


def _mean(v):
    return sum(v) / len(v)


def test_compare_into_a_log_prints_a_summary_of_the_metrics_and_no_long_or_progress_lines(built, tmp_path):
    out = tmp_path / "cmp"
    # with progress on (no --no-progress): off a terminal it must not draw a bar
    res = subprocess.run([sys.executable, "-m", "orchestrator", "compare", str(PAPER), "--ssp", str(built["ssp"]),
                          "--out", str(out), "--set", "stop_time=0.05", "--jobs", "1"], capture_output=True,
                         text=True, timeout=600, env=dict(os.environ, TMPDIR=str(tmp_path)))
    assert res.returncode == 0, res.stderr
    for stream in (res.stdout, res.stderr):
        assert "\r" not in stream
        assert all(len(line) <= 200 for line in stream.splitlines())
    assert res.stderr.splitlines()[0] == (f"paper_simulation: {len(BASELINES)} runs of 0.05 s (500 steps, csv) on 1 process(es) "
                                          f"-> {out}")
    assert "paper_simulation: figures" in res.stderr.splitlines()
    lines = res.stdout.splitlines()
    assert len(lines) == 4 + len(BASELINES)
    assert lines[-1] == f"results, figures and the full tables (comparison.md) in {out}"
    assert lines[1].startswith("mean: the steady tracking error per mode")
    del lines[1]
    assert lines[1].split() == ["run", "tracking", "MAE", "[um]", "sync", "MAE", "[um]", "SC-DC", "vs", "it:",
                                "tracking", "sync", "F", "RMS", ">", "100", "Hz", "[N]", "mean:", "common", "diff.", "Z",
                                "diff.", "B", "[um]"]
    metrics = {b.name: json.loads((out / b.name / "metrics.json").read_text()) for b in BASELINES}
    sc_t, sc_y = _mean(metrics["sc-dc"]["tracking_mae_um"]), _mean(metrics["sc-dc"]["sync_mae_um"])
    rows = {r.split()[0]: r.split()[1:] for r in lines[2:-1]}
    assert list(rows) == [b.name for b in BASELINES]
    for name, (t, y, rt, ry, f, *_) in rows.items():
        assert float(f) == pytest.approx(_mean(metrics[name]["force_hf_rms_n"]), rel=1e-3)  # effort, mean of motors
        mt, my = _mean(metrics[name]["tracking_mae_um"]), _mean(metrics[name]["sync_mae_um"])
        assert float(t) == pytest.approx(mt, abs=5e-5) and float(y) == pytest.approx(my, abs=5e-5)
        # SC-DC's reduction against the run: positive where SC-DC has the smaller error
        assert float(rt.rstrip("%")) == pytest.approx(100 * (mt - sc_t) / mt, abs=0.05)
        assert float(ry.rstrip("%")) == pytest.approx(100 * (my - sc_y) / my, abs=0.05)
    assert rows["sc-dc"][2:4] == ["+0.0%", "+0.0%"]
    # the full Markdown is in comparison.md, not on the terminal
    md = (out / "comparison.md").read_text()
    assert "| `sc-dc` | SC-DC |" in md and "|" not in res.stdout


def test_progress_off_a_terminal_is_one_line_per_tenth_of_a_long_task(capsys):
    bar = Progress("paper_experiment sc-dc", "step", quiet_s=0.0)
    for done in range(0, 111113, 100):
        bar(done, 111112)
    bar(111112, 111112)
    bar.close()
    err = capsys.readouterr().err.splitlines()
    assert err == [f"paper_experiment sc-dc: {p} % ({d}/111112 steps)" for p, d in
                   zip(range(10, 101, 10), (11200, 22300, 33400, 44500, 55600, 66700, 77800, 88900, 100100, 111112))]


def test_progress_of_a_short_task_off_a_terminal_prints_nothing(capsys):
    bar = Progress("short", "run", total=9)  # quiet for its first two seconds
    for _ in range(9):
        bar.update()
    bar.close()
    assert capsys.readouterr().err == ""
