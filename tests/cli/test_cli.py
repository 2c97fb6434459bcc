"""The tapmp command line: run, compare, plot, errors and exit codes (real FMUs)."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from orchestrator.cli import main

ROOT = Path(__file__).resolve().parents[2]
PAPER = str(ROOT / "scenarios" / "paper_simulation.toml")


def test_run_writes_results_run_info_and_metrics(built, tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["run", PAPER, "--ssp", str(built["ssp"]), "--out", str(out), "--set", "stop_time=0.02",
                 "--no-progress"]) == 0
    header = (out / "results.csv").read_text().splitlines()
    assert len(header) == 202 and header[0].split(",")[:2] == ["time", "trajectory.X_d"]
    assert "plant.q1_true" in header[0] and "controller.es3" in header[0]
    run = json.loads((out / "run.json").read_text())
    assert run["status"] == "completed" and run["ordering"] == "gauss-seidel" and run["step"] == 1e-4
    assert set(run["guids"]) == {"trajectory", "controller", "plant"} and run["versions"]["fmpy"] == "0.3.32"
    metrics = json.loads((out / "metrics.json").read_text())
    assert len(metrics["tracking_mae_um"]) == 3 and metrics["samples"] == 201
    assert "tracking MAE [um]" in capsys.readouterr().out


def test_existing_results_are_not_overwritten_without_flag(built, tmp_path, capsys):
    out = tmp_path / "run"
    args = ["run", PAPER, "--ssp", str(built["ssp"]), "--out", str(out), "--set", "stop_time=0.001", "--no-progress"]
    assert main(args) == 0
    before = (out / "results.csv").read_text()
    assert main(args + ["--set", "plant.k_pull=0"]) == 2
    assert "already holds results" in capsys.readouterr().err
    assert (out / "results.csv").read_text() == before
    assert main(args + ["--overwrite"]) == 0


@pytest.mark.slow
def test_compare_writes_three_runs_comparison_and_figures(built, tmp_path, capsys):
    out = tmp_path / "cmp"
    assert main(["compare", PAPER, "--ssp", str(built["ssp"]), "--out", str(out), "--set", "stop_time=0.05",
                 "--no-progress"]) == 0
    for run in ("sc-dc", "apd-dc", "apd-dc-matched"):
        assert (out / run / "metrics.json").is_file()
    text = (out / "comparison.md").read_text()
    assert "paper: Table 1" in text and "| paper: SC-DC (proposed) | 3.16 | 3.28 | 3.29 |" in text
    matched = json.loads((out / "apd-dc-matched" / "run.json").read_text())["scenario"]["gain_values"]
    assert matched["Lambda_p"] == pytest.approx([0.36 * 900] * 3)
    for fig in ("fig4_trajectory", "fig5_tracking_errors", "fig6_sync_errors", "fig7_axis_errors",
                "fig8_force_commands"):
        assert (out / f"{fig}.png").stat().st_size > 10000
    printed = capsys.readouterr().out  # the summary: one row per run, the full tables only in comparison.md
    assert "ours: SC-DC (proposed)" in text and "ours: SC-DC (proposed)" not in printed
    sc = json.loads((out / "sc-dc" / "metrics.json").read_text())
    row = next(line.split() for line in printed.splitlines() if line.startswith("sc-dc "))
    assert float(row[1]) == pytest.approx(sum(sc["tracking_mae_um"]) / 3, abs=5e-5)


def test_bad_scenario_gives_one_line_and_exit_code_2(tmp_path, capsys):
    assert main(["run", PAPER, "--set", "step=-1", "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: step = -1.0 is invalid") and "Traceback" not in err


def _subcommands():
    from orchestrator.cli import parser
    return sorted(parser()._subparsers._group_actions[0].choices)


@pytest.mark.slow
@pytest.mark.parametrize("cmd", [[]] + [[c] for c in _subcommands()])
def test_every_command_has_help(cmd):
    res = subprocess.run([sys.executable, "-m", "orchestrator", *cmd, "--help"], capture_output=True, text=True)
    assert res.returncode == 0 and f"usage: tapmp {' '.join(cmd)}".rstrip() in res.stdout


@pytest.mark.slow
def test_the_help_lists_every_subcommand():
    res = subprocess.run([sys.executable, "-m", "orchestrator", "--help"], capture_output=True, text=True)
    assert set(_subcommands()) == {"build", "run", "check", "analyze", "frf", "compare", "reproduce", "study", "export", "plot",
                                   "calibrate", "paper-gains", "null-models", "theorem1", "modal"}
    for c in _subcommands():
        assert c in res.stdout


BAD_FILES = {
    "malformed TOML": ('name = "x"\nstop_time = = 1\n', "is not valid TOML"),
    "unknown key": ('name = "x"\nstop_tme = 1.0\n', "stop_tme is unknown: allowed are"),
    "wrong type": ('name = "x"\nstop_time = "long"\n', "stop_time = 'long' has the wrong type: allowed is float"),
    "negative step": ('name = "x"\nstep = -1e-4\n', "step = -0.0001 is invalid: allowed is a number > 0"),
    "stop before start": ('name = "x"\nstart_time = 1.0\nstop_time = 0.5\n',
                          "stop_time = 0.5 is invalid: allowed is a number > start_time = 1.0"),
    "unknown limit": ('name = "x"\n[limits]\nmotor = 1.0\n', "limits.motor is unknown: allowed are motor_travel"),
    "record_every 0": ('name = "x"\nrecord_every = 0\n', "record_every = 0 is invalid: allowed is an integer from 1 to 2147483647"),
}


@pytest.mark.parametrize("case", BAD_FILES)
def test_bad_scenario_files_get_one_clear_line_exit_2_and_a_traceback_only_with_debug(case, tmp_path, capsys):
    text, message = BAD_FILES[case]
    path = tmp_path / "bad.toml"
    path.write_text(text)
    assert main(["run", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and message in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()  # nothing was started
    assert main(["--debug", "run", str(path), "--out", str(tmp_path / "out")]) == 2
    assert "Traceback" in capsys.readouterr().err


@pytest.mark.parametrize("content", [None, b"this is not a zip archive"])
def test_a_missing_or_corrupt_ssp_is_named_with_exit_2(content, tmp_path, capsys):
    ssp = tmp_path / "TAPMP.ssp"
    if content is not None:
        ssp.write_bytes(content)
    assert main(["run", PAPER, "--ssp", str(ssp), "--out", str(tmp_path / "out"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and str(ssp) in err and "Traceback" not in err


@pytest.mark.slow
def test_a_c_model_that_cannot_be_compiled_is_one_line_naming_the_compiler(tmp_path):
    """The Python model runs the C model's library; with none in the cache and a compiler that
    does not exist, `tapmp run` stops with one line naming both, exit code 2."""
    import os
    cc = tmp_path / "no-such-cc"
    env = dict(os.environ, TAPMP_CACHE=str(tmp_path / "cache"), CC=str(cc))
    res = subprocess.run([sys.executable, "-m", "orchestrator", "run", PAPER, "--out", str(tmp_path / "out"),
                          "--no-progress"], capture_output=True, text=True, timeout=300, env=env)
    assert res.returncode == 2
    assert res.stderr.splitlines() == [f"error: the C model (x86_64-linux): C compiler {str(cc)!r} not found "
                                       "(unset CC to use zig cc from the ziglang package)"]
    assert not (tmp_path / "out").exists()
