"""`tapmp check`, `tapmp study` and `tapmp reproduce` through the real command line in child
processes, on short horizons: exit codes, the printed numbers against the
library's own values, the files written."""

import csv
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow  # check, study and reproduce in child processes

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "scenarios" / "paper_simulation.toml"


def tapmp(*args, tmp_path, timeout=300):
    tmpdir = tmp_path / "tmp"
    tmpdir.mkdir(exist_ok=True)
    return subprocess.run([sys.executable, "-m", "orchestrator", *map(str, args)], cwd=tmp_path,
                          env=dict(os.environ, TMPDIR=str(tmpdir)), capture_output=True, text=True,
                          timeout=timeout)


@pytest.mark.parametrize("sets, code, verdict, rho", [
    ([], 0, "stable", 0.996172),
    (['gains="paper_simulation"'], 1, "unstable", 39.20),
    (['gains="paper_simulation"', 'ordering="jacobi"'], 1, "unstable", 6.570),
])
def test_check_prints_the_verdict_and_spectral_radius_and_exits_0_only_when_stable(tmp_path, sets, code,
                                                                                    verdict, rho):
    from orchestrator.tool.scenario import load
    from orchestrator.tool.stability import check
    res = tapmp("check", PAPER, *[a for s in sets for a in ("--set", s)], "--eigenvalues", tmp_path=tmp_path)
    assert res.returncode == code, res.stderr
    lines = res.stdout.splitlines()
    m = re.match(r"paper_simulation: (\w+): spectral radius ([0-9.]+) ", lines[0])
    assert m and m.group(1) == verdict
    expected = check(load(PAPER, sets)).spectral_radius
    assert float(m.group(2)) == pytest.approx(expected, abs=1e-6) and expected == pytest.approx(rho, rel=1e-3)
    moduli = [float(x) for x in re.findall(r"\|z\| = ([0-9.]+)", res.stdout)]
    assert len(moduli) == len(lines) - 1 and max(moduli) == pytest.approx(expected, abs=1e-6)


def test_check_refuses_a_bad_key_in_one_line_with_exit_2(tmp_path):
    res = tapmp("check", PAPER, "--set", "stop_tme=0.1", tmp_path=tmp_path)
    assert res.returncode == 2 and len(res.stderr.splitlines()) == 1
    assert res.stderr.startswith("error: ") and "stop_tme" in res.stderr


def test_study_writes_one_row_per_case_with_the_numbers_of_its_metrics(built, tmp_path):
    from orchestrator.studies.study import objective
    study = tmp_path / "s.toml"
    study.write_text(f'[study]\nbase = "{PAPER}"\n[set]\nstop_time = 0.02\n'
                     '[grid]\nlaw = ["sc-dc", "apd-dc"]\n')
    res = tapmp("study", study, "--ssp", built["ssp"], "--out", tmp_path / "out", "--workers", "1",
                "--no-progress", tmp_path=tmp_path)
    assert res.returncode == 0, res.stderr
    out = tmp_path / "out"
    assert re.search(r"2 cases \(2 run now, [0-9.]+ s\): 2 completed, 0 diverged, 0 failed -> " + re.escape(str(out / "study.csv")),
                     res.stdout)
    with open(out / "study.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [r["law"] for r in rows] == ["sc-dc", "apd-dc"] or [r["law"] for r in rows] == ["apd-dc", "sc-dc"]
    for r in rows:
        m = json.loads((out / "cases" / r["case"] / "metrics.json").read_text())
        assert float(r["objective"]) == pytest.approx(objective(m), rel=1e-12)
        assert [float(r[f"tracking_mae_um_{i}"]) for i in (1, 2, 3)] == pytest.approx(m["tracking_mae_um"], rel=1e-12)
        assert float(r["saturation_fraction_max"]) == max(m["saturation_fraction"])
        assert r["status"] == "completed" and r["flag"] == ""
        assert json.loads((out / "cases" / r["case"] / "run.json").read_text())["status"] == "completed"
    assert json.loads((out / "study.json").read_text())["cases"][0]["changes"] == {"law": "sc-dc"}
    assert list((tmp_path / "tmp").iterdir()) == []


@pytest.mark.parametrize("command", ["study", "reproduce"])
def test_workers_below_one_are_refused_alike_by_study_and_reproduce(built, tmp_path, command):
    study = tmp_path / "s.toml"
    study.write_text(f'[study]\nbase = "{PAPER}"\n[grid]\nlaw = ["sc-dc"]\n')
    first = (study,) if command == "study" else ()
    res = tapmp(command, *first, "--ssp", built["ssp"], "--out", tmp_path / "out.md", "--workers", "0",
                tmp_path=tmp_path)
    assert (res.returncode, res.stderr) == (2, "error: --workers = 0 is invalid: allowed is an integer >= 1\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.toml", "tmp"]  # nothing written


def test_reproduce_writes_the_page_with_the_numbers_of_its_runs(built, tmp_path):
    from orchestrator.tool.baselines import BASELINES
    scenarios = tmp_path / "scenarios"
    scenarios.mkdir()
    for name in ("paper_simulation", "paper_experiment"):
        text = (ROOT / "scenarios" / f"{name}.toml").read_text()
        text, n = re.subn(r"(?m)^stop_time = [0-9.]+", "stop_time = 0.02", text)
        assert n == 1
        (scenarios / f"{name}.toml").write_text(text)
    page, results = tmp_path / "repro.md", tmp_path / "results"
    # a comparison `tapmp compare` completed where reproduce writes: refused before anything runs
    mine = results / "paper_simulation" / "compare"
    res = tapmp("compare", scenarios / "paper_simulation.toml", "--ssp", built["ssp"], "--out", mine, "--no-progress",
                tmp_path=tmp_path)
    assert res.returncode == 0, res.stderr
    before = {p: p.read_bytes() for p in mine.rglob("*") if p.is_file() and p.name != ".tapmp.lock"}
    args = ["reproduce", "--scenarios", scenarios, "--results", results, "--out", page, "--ssp", built["ssp"],
            "--paper-gains-stop-time", "0.001", "--no-progress"]
    res = tapmp(*args, tmp_path=tmp_path)
    assert res.returncode == 2 and res.stderr == (
        f"error: output folder {mine} holds a completed comparison that tapmp reproduce did not write (by tapmp "
        "compare): pass --overwrite to replace it, or --results another folder\n")
    assert {p: p.read_bytes() for p in mine.rglob("*") if p.is_file() and p.name != ".tapmp.lock"} == before
    assert not page.exists() and not (results / "paper_experiment").exists()
    res = tapmp(*args, "--overwrite", tmp_path=tmp_path)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip().splitlines()[-1] == f"wrote {page}"
    assert json.loads((mine / "comparison.json").read_text())["written_by"] == "reproduce"
    assert "Produced by `tapmp reproduce --scenarios " in (mine / "comparison.md").read_text()
    total = int(re.search(r"the paper's gains: 1 of (\d+) runs done", res.stderr).group(1))
    assert f"the paper's gains: {total} of {total} runs done" in res.stderr
    text = page.read_text()
    for name in ("paper_simulation", "paper_experiment"):
        assert f"`scenarios/{name}.toml`" in text and "0.02 s at a 0.0001 s step" in text
        runs = sorted(p.parent for p in results.glob(f"{name}/compare/*/metrics.json"))  # not compare/noise/
        assert {p.name for p in runs} == {b.name for b in BASELINES}
        for run in runs:
            m = json.loads((run / "metrics.json").read_text())
            cells = " | ".join(f"{v:.3f}" for v in (*m["tracking_std_um"], *m["tracking_mae_um"]))
            assert cells in text   # the run's tracking STD and MAE, as printed in Table 1 / 4
        assert any(p.suffix == ".png" for p in runs[0].parent.iterdir())
