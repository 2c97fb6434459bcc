"""The summaries `tapmp run` and `tapmp compare` print give what a control engineer reads first:
beside the MAE the steady (mean) tracking error per mode, and for a point-to-point move its rise
time, overshoot and settling times, the numbers of the run's metrics.json."""

import json
import re
from pathlib import Path

import pytest

from orchestrator.cli import main

pytestmark = pytest.mark.slow  # real co-simulations of the native FMUs

ROOT = Path(__file__).resolve().parents[2]
SHAPES = ((1, 1, 1), (1, 0, -1), (1, -2, 1))


def _modes(metrics: dict) -> list[float]:
    e = metrics["tracking_mean_um"]
    return [sum(v * x for v, x in zip(shape, e)) / sum(v * v for v in shape) for shape in SHAPES]


def test_run_prints_the_steady_error_per_mode_and_the_move_metrics(native_built, tmp_path, capsys):
    out = tmp_path / "p2p"
    assert main(["run", "point_to_point", "--ssp", str(native_built["fmi2"]["ssp"]), "--out", str(out),
                 "--set", "stop_time=0.32", "--no-progress"]) == 0
    printed = capsys.readouterr().out.splitlines()
    m = json.loads((out / "metrics.json").read_text())
    common, diff_z, diff_b = _modes(m)
    assert common == pytest.approx(sum(m["tracking_mean_um"]) / 3) and common > 0.01  # a steady lag, not noise
    assert f"steady (mean) error per mode [um]: common {common:+.4f}, diff. Z {diff_z:+.4f}, diff. B {diff_b:+.4f}" \
        in "\n".join(printed)
    moving = {name: c for name, c in m["move"]["channels"].items() if c["distance"] != 0.0}
    assert moving and "X" in moving
    for name, c in moving.items():
        (line,) = [line for line in printed if line.startswith(f"  sc-dc {name}: ")]
        assert f"rise {c['rise_time_s'] * 1e3:.2f}, overshoot {c['overshoot']:.4f}, settling within " in line
        for band, t in c["settling_time_s"].items():
            assert f"{band}: {'never' if t is None else f'{t * 1e3:.2f}'}" in line


def test_compare_prints_the_steady_error_per_mode_of_every_run(native_built, tmp_path, capsys):
    out = tmp_path / "compare"
    assert main(["compare", "paper_simulation", "--ssp", str(native_built["fmi2"]["ssp"]), "--out", str(out),
                 "--set", "stop_time=0.02", "--no-progress", "--jobs", "1"]) == 0
    printed = capsys.readouterr().out.splitlines()
    header = next(i for i, line in enumerate(printed) if line.startswith("run "))
    assert re.search(r"mean: common\s+diff\. Z\s+diff\. B \[um\]$", printed[header])
    runs = json.loads((out / "comparison.json").read_text())["runs"]
    rows = {line.split()[0]: line.split() for line in printed[header + 1:header + 1 + len(runs)]}
    assert set(rows) == set(runs)
    for name in runs:
        means = _modes(json.loads((out / name / "metrics.json").read_text()))
        assert rows[name][-3:] == [f"{v:+.4f}" for v in means]
    assert not any(line.startswith("move (") for line in printed)  # no move in this scenario
    # one direction in both summaries: SC-DC's reduction against each run, the same numbers as the
    # summary table of comparison.md, row for row (SC-DC against itself: 0)
    md = (out / "comparison.md").read_text().split("## SC-DC against each run")[1].split("\n\n")[1].splitlines()[2:]
    md_reductions = [[c.strip() for c in line.split("|")[4:6]] for line in md]
    printed_rows = [line.split() for line in printed[header + 1:header + 1 + len(runs)]]
    assert [[r[3].rstrip("%"), r[4].rstrip("%")] for r in printed_rows] == md_reductions
    assert rows["sc-dc"][3:5] == ["+0.0%", "+0.0%"]
