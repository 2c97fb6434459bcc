"""Result folders through the real `tapmp` CLI: run and compare default to distinct folders, each
folder says what it holds, a completed result is never replaced without --overwrite, a failed or
interrupted one is, and `tapmp plot` writes only the figures of the folder's kind."""

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from orchestrator.cli import main

pytestmark = pytest.mark.slow  # tapmp run, compare and plot in child processes

ROOT = Path(__file__).resolve().parents[2]
PAPER = str(ROOT / "scenarios" / "paper_simulation.toml")
SHORT = ["--set", "stop_time=0.01", "--no-progress"]


def test_run_and_compare_default_to_distinct_folders_under_the_current_directory(built, tmp_path, capsys,
                                                                                  monkeypatch):
    monkeypatch.chdir(tmp_path)  # the scenario's output = "results/paper_simulation", relative to here
    assert main(["run", PAPER, "--ssp", str(built["ssp"]), *SHORT]) == 0
    assert main(["run", PAPER, "--ssp", str(built["ssp"]), "--set", 'law="apd-dc"', *SHORT]) == 0
    assert main(["compare", PAPER, "--ssp", str(built["ssp"]), *SHORT]) == 0
    base = tmp_path / "results" / "paper_simulation"
    assert sorted(p.name for p in base.iterdir()) == ["apd-dc", "compare", "sc-dc"]
    for law in ("sc-dc", "apd-dc"):
        run = json.loads((base / law / "run.json").read_text())
        assert (run["kind"], run["status"], run["scenario"]["law"]) == ("run", "completed", law)
    cmp = json.loads((base / "compare" / "comparison.json").read_text())
    assert sorted(cmp.pop("tapmp_files")) == ["comparison.md", *(n[len("run_"):] for n in RUN_FIGS)]  # what it wrote
    assert cmp == {"kind": "comparison", "scenario": "paper_simulation", "status": "completed", "written_by": "compare",
                   "runs": {"sc-dc": "sc-dc", "apd-dc": "apd-dc", "apd-dc-matched": "apd-dc",
                            "apd-dc-diff-stiffness": "apd-dc", "apd-dc-mode-matched": "pid-dc",
                            "apd-dc-ms-matched": "pid-dc", "pid-dc-mode-matched": "pid-dc", "pid-dc-full": "pid-dc", "sc-dc-b0": "sc-dc", "sc-dc-lp0": "sc-dc"}}
    assert not (base / "compare" / "results.csv").exists()  # nothing of a single run at its top
    assert "results in results/paper_simulation/sc-dc" in capsys.readouterr().out


def test_a_completed_run_is_refused_without_overwrite_in_one_line(built, tmp_path, capsys):
    out = tmp_path / "run"
    args = ["run", PAPER, "--ssp", str(built["ssp"]), "--out", str(out), *SHORT]
    assert main(args) == 0
    before = (out / "results.csv").read_bytes()
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err == (f"error: output folder {out} already holds results of a completed run: choose another with "
                   "--out or pass --overwrite\n")
    assert (out / "results.csv").read_bytes() == before
    assert main(args + ["--overwrite"]) == 0


def test_a_failed_run_is_reused_without_overwrite(built, tmp_path, capsys):
    out = tmp_path / "run"
    missing = tmp_path / "no.ssp"
    assert main(["run", PAPER, "--ssp", str(missing), "--out", str(out), *SHORT]) == 2  # e.g. before build_fmus.sh
    assert json.loads((out / "run.json").read_text())["status"] == "failed"
    capsys.readouterr()
    assert main(["run", PAPER, "--ssp", str(built["ssp"]), "--out", str(out), *SHORT]) == 0  # the natural retry
    assert json.loads((out / "run.json").read_text())["status"] == "completed"
    assert len((out / "results.csv").read_text().splitlines()) == 1 + 101


def test_an_interrupted_run_is_reused_without_overwrite(built, tmp_path):
    out = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "orchestrator", "run", PAPER, "--ssp", str(built["ssp"]), "--out",
                             str(out), "--set", "stop_time=30", "--no-progress"], stderr=subprocess.PIPE, text=True)
    results = out / "results.csv"
    while proc.poll() is None and (not results.exists() or results.stat().st_size < 100_000):
        time.sleep(0.02)
    proc.terminate()
    assert proc.wait(timeout=60) == 143, proc.stderr.read()
    assert json.loads((out / "run.json").read_text())["status"] == "interrupted"
    assert main(["run", PAPER, "--ssp", str(built["ssp"]), "--out", str(out), *SHORT]) == 0
    assert len(results.read_text().splitlines()) == 1 + 101


def test_a_completed_comparison_is_refused_and_kinds_never_mix(built, tmp_path, capsys):
    cmp, run = tmp_path / "cmp", tmp_path / "run"
    assert main(["compare", PAPER, "--ssp", str(built["ssp"]), "--out", str(cmp), *SHORT]) == 0
    assert main(["run", PAPER, "--ssp", str(built["ssp"]), "--out", str(run), *SHORT]) == 0
    capsys.readouterr()
    assert main(["compare", PAPER, "--ssp", str(built["ssp"]), "--out", str(cmp), *SHORT]) == 2
    assert capsys.readouterr().err == (f"error: output folder {cmp} already holds results of a completed "
                                       "comparison: choose another with --out or pass --overwrite\n")
    for args, err in (
            (["run", "--out", str(cmp), "--overwrite"],
             f"error: output folder {cmp} holds a comparison (comparison.json), not a single run: choose another "
             "folder with --out\n"),
            (["compare", "--out", str(run), "--overwrite"],
             f"error: output folder {run} holds a single run (run.json), not a comparison: choose another folder "
             "with --out\n")):
        assert main([args[0], PAPER, "--ssp", str(built["ssp"]), *args[1:], *SHORT]) == 2
        assert capsys.readouterr().err == err
    assert not (cmp / "results.csv").exists() and not (run / "sc-dc").exists()
    assert main(["compare", PAPER, "--ssp", str(built["ssp"]), "--out", str(cmp), "--overwrite", *SHORT]) == 0


def test_a_failed_comparison_is_recorded_and_reused_without_overwrite(built, tmp_path, capsys):
    cmp = tmp_path / "cmp"
    assert main(["compare", PAPER, "--ssp", str(tmp_path / "no.ssp"), "--out", str(cmp), *SHORT]) == 2
    info = json.loads((cmp / "comparison.json").read_text())
    assert info["status"] == "failed" and "no.ssp" in info["error"]
    assert main(["compare", PAPER, "--ssp", str(built["ssp"]), "--out", str(cmp), *SHORT]) == 0
    assert json.loads((cmp / "comparison.json").read_text())["status"] == "completed"


def pngs(folder: Path) -> dict:
    return {p.name: (p.stat().st_mtime_ns, p.read_bytes()) for p in folder.glob("*.png")}


RUN_FIGS = ["run_fig4_trajectory.png", "run_fig5_tracking_errors.png", "run_fig6_sync_errors.png",
            "run_fig7_axis_errors.png", "run_fig8_force_commands.png"]


def test_plot_writes_only_the_figures_of_the_folders_kind(built, tmp_path, capsys):
    cmp = tmp_path / "cmp"
    assert main(["compare", PAPER, "--ssp", str(built["ssp"]), "--out", str(cmp), *SHORT]) == 0
    comparison_figs = pngs(cmp)
    assert sorted(comparison_figs) == [n[len("run_"):] for n in RUN_FIGS]
    capsys.readouterr()
    assert main(["plot", str(cmp / "sc-dc")]) == 0  # a run inside the comparison
    assert sorted(p.name for p in (cmp / "sc-dc").glob("*.png")) == RUN_FIGS
    assert capsys.readouterr().out.splitlines() == [f"wrote {cmp / 'sc-dc' / n}" for n in RUN_FIGS]
    # a legacy mixed folder (an old `tapmp run` into the comparison's top): the comparison's figures stay
    (cmp / "comparison.json").unlink()
    for f in ("results.csv", "run.json"):
        (cmp / f).write_bytes((cmp / "sc-dc" / f).read_bytes())
    assert main(["plot", str(cmp)]) == 0
    assert {k: v for k, v in pngs(cmp).items() if not k.startswith("run_")} == comparison_figs
    assert sorted(k for k in pngs(cmp) if k.startswith("run_")) == RUN_FIGS


def test_plot_of_a_missing_or_empty_folder_is_one_line_exit_2(tmp_path):
    (tmp_path / "empty").mkdir()
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "results.csv").write_text("time\n0\n")
    cases = {"results/nope": "error: result folder results/nope does not exist: allowed is a folder written by "
                             "tapmp run or tapmp compare\n",
             "run/results.csv": "error: result folder run/results.csv is a file, not a folder: allowed is a folder "
                                "written by tapmp run or tapmp compare (this file's folder is run)\n",
             "empty": "error: result folder empty holds no results of tapmp run or tapmp compare (no run.json, "
                      "comparison.json or run folders)\n"}
    for folder, message in cases.items():
        res = subprocess.run([sys.executable, "-m", "orchestrator", "plot", folder], capture_output=True, text=True,
                             cwd=tmp_path, env=dict(os.environ, PYTHONPATH=str(ROOT)))
        assert (res.returncode, res.stderr, res.stdout) == (2, message, "")


def test_help_says_what_relative_paths_are_relative_to():
    for cmd in ("run", "compare", "plot"):
        res = subprocess.run([sys.executable, "-m", "orchestrator", cmd, "--help"], capture_output=True, text=True,
                             env=dict(os.environ, COLUMNS="200", PYTHONPATH=str(ROOT)))
        text = " ".join(res.stdout.split())
        assert "relative to the current directory" in text, cmd
        assert ("the SSP of --fmus is found in --fmus-dir, else $TAPMP_FMUS_DIR, else the repository's build/ "
                "(in a checkout) or ./build (installed as a wheel)") in text, cmd
