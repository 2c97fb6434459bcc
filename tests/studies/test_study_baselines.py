"""The robustness study's matched baselines: a grid over compare's run names (grid.baseline) runs
SC-DC, APD-DC and the matched baselines of orchestrator.tool.baselines on the same sampled
plants, each with the gains `tapmp compare` gives it on the nominal scenario."""

import json
import re
from pathlib import Path

import pytest

from orchestrator.cli import main
from orchestrator.tool.baselines import compare_runs
from orchestrator.studies.study import load_study, read_study_csv
from orchestrator.studies.study_file import base_value

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = ROOT / "studies" / "robustness.toml"
SAMPLES = 2


def small_robustness_study(folder: Path) -> Path:
    """studies/robustness.toml as shipped but for SAMPLES samples of 10 ms, writing into ``folder``."""
    text = SHIPPED.read_text()
    text, n_samples = re.subn(r"(?m)^samples = \d+$", f"samples = {SAMPLES}", text)
    text, n_stop = re.subn(r"(?m)^stop_time = [0-9.]+$", "stop_time = 0.01", text)
    text, n_out = re.subn(r'(?m)^output = ".*"$', f'output = "{folder / "out"}"', text)
    text = text.replace('base = "../scenarios/', f'base = "{ROOT / "scenarios"}/')
    assert n_samples == n_stop == n_out == 1
    path = folder / "robustness.toml"
    path.write_text(text)
    return path


@pytest.mark.slow  # a Monte Carlo study on a Dask LocalCluster
def test_the_robustness_study_runs_every_matched_baseline_on_the_same_sampled_plants(built, tmp_path, capsys):
    path = small_robustness_study(tmp_path)
    study = load_study(path)
    names = study.grid["baseline"]
    assert {"sc-dc", "apd-dc", "apd-dc-ms-matched", "pid-dc-full"} <= set(names)
    assert main(["study", str(path), "--ssp", built["ssp"], "--workers", "1", "--no-progress"]) == 0
    out = tmp_path / "out"
    rows = sorted(read_study_csv(out / "study.csv"), key=lambda r: r["case"])  # written as cases finish
    assert [r["baseline"] for r in rows] == [n for n in names for _ in range(SAMPLES)]
    assert all(r["status"] == "completed" for r in rows), rows
    runs = compare_runs(study.base_scenario())  # the gains compare gives each run on the nominal scenario
    plants = {}
    for r in rows:
        scenario = json.loads((out / "cases" / r["case"] / "run.json").read_text())["scenario"]
        want = runs[r["baseline"]]
        assert scenario["law"] == want.law
        if want.law == "pid-dc":
            assert {k: scenario["controller"][k] for k in ("kp_c", "kp_d", "kv_c", "kv_d", "ki_c", "ki_d")} == \
                {k: want.controller[k] for k in ("kp_c", "kp_d", "kv_c", "kv_d", "ki_c", "ki_d")}
        index = rows.index(r) % SAMPLES
        plant = scenario["plant"]
        plants.setdefault(index, []).append(plant)
        # the sampled factors are columns of the row, the same for every baseline at a sample index
        assert plant["m_p"] == pytest.approx(r["m_p"] * base_value(study.base_scenario(), "plant.m_p"))
    for index, same in plants.items():
        assert all(p == same[0] for p in same), index
    assert plants[0] != plants[1]
    assert runs["pid-dc-full"].controller["ki_c"] == runs["pid-dc-full"].controller["ki_d"] > 0
    assert runs["apd-dc-ms-matched"].controller["ki_c"] == runs["apd-dc-ms-matched"].controller["ki_d"] == 0
    summary = (out / "summary.md").read_text().splitlines()
    for name in names:
        line, *paired = [s for s in summary if s.startswith(f"| {name} |")]
        assert f"| {SAMPLES} / {SAMPLES} |" in line
        if name != names[0]:  # sample by sample against the first: counts from the rows
            first = [r for r in rows if r["baseline"] == names[0]]
            other = [r for r in rows if r["baseline"] == name]
            wins = [sum(a[k] < b[k] for a, b in zip(first, other)) for k in ("tracking_mae_um_mean", "sync_mae_um_mean")]
            cells = paired[0].strip("|").split("|")
            assert (cells[1].strip(), cells[3].strip()) == tuple(f"{w} of {SAMPLES}" for w in wins)
    assert (out / "robustness.png").stat().st_size > 10_000


@pytest.mark.parametrize("grid, message", [
    ('baseline = ["sc-dc", "pid-dc-fll"]', "error: {path}: grid.baseline = 'pid-dc-fll' is invalid: allowed are "),
    ('baseline = ["sc-dc"]\nlaw = ["apd-dc"]', "error: {path}: grid: law and baseline cannot both vary: a baseline "
                                               "sets the law; allowed is one of them"),
])
def test_a_baseline_that_is_not_a_compare_run_is_one_line_naming_it(tmp_path, capsys, grid, message):
    path = tmp_path / "s.toml"
    path.write_text(f'[study]\nname = "s"\nbase = "{ROOT / "scenarios" / "paper_simulation.toml"}"\n'
                    f'output = "{tmp_path / "out"}"\n[grid]\n{grid}\n')
    assert main(["study", str(path), "--workers", "1", "--no-progress"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith(message.format(path=path)), err
    assert not (tmp_path / "out").exists()


def test_a_baseline_outside_the_grid_is_one_line(tmp_path, capsys):
    path = tmp_path / "s.toml"
    path.write_text(f'[study]\nname = "s"\nbase = "{ROOT / "scenarios" / "paper_simulation.toml"}"\n'
                    f'[set]\nbaseline = "pid-dc-full"\n[grid]\nlaw = ["sc-dc"]\n')
    assert main(["study", str(path), "--workers", "1", "--no-progress"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].endswith("set: baseline is allowed only in [grid] (a list of compare run names)")
