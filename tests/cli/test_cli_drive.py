"""`tapmp run` and `tapmp compare` with the drive in the loop (drive = true, [drive] settings): they run the
native family's TAPMP_Drive.ssp and record the drive's forces; a family without the drive, or a drive setting
that is unknown or out of range, is refused with one line and exit code 2."""

import csv
import json
from pathlib import Path

import numpy as np
import pytest

import ctoolchain as toolchain
from orchestrator.cli import main

ROOT = Path(__file__).resolve().parents[2]
PAPER = str(ROOT / "scenarios" / "paper_simulation.toml")


@pytest.fixture(scope="module")
def fmus_dir(tmp_path_factory):
    """A folder of built FMUs as `tapmp build` lays it out: the native FMUs for this host in native/."""
    from orchestrator.builder.build_native import build_native
    folder = tmp_path_factory.mktemp("fmus")
    build_native(folder / "native", log=lambda *_: None, platforms=(toolchain.HOST,))
    return folder


def columns(path: Path) -> dict:
    """{column: values} of a results.csv."""
    with open(path) as f:
        rows = list(csv.reader(f))
    return {name: np.array([float(r[i]) for r in rows[1:]]) for i, name in enumerate(rows[0])}


@pytest.mark.slow  # builds the native FMUs
def test_run_with_the_drive_runs_its_ssp_and_records_its_forces(fmus_dir, tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["run", PAPER, "--set", "drive.current_bandwidth=0.0", "--set", "drive.force_constant_error1=0.1",
                 "--set", "stop_time=0.02", "--fmus-dir", str(fmus_dir), "--out", str(out), "--no-progress"]) == 0
    run = json.loads((out / "run.json").read_text())
    assert run["status"] == "completed" and Path(run["ssp"]) == fmus_dir / "native" / "fmi2" / "TAPMP_Drive.ssp"
    assert run["scenario"]["drive"] == {"current_bandwidth": 0.0, "force_constant_error1": 0.1}
    got = columns(out / "results.csv")
    assert len(got["time"]) == 201
    # the default delay of one sample, the ideal current loop and motor 1's force constant 10 % high
    assert np.array_equal(got["drive.F1"][2:], 1.1 * got["controller.F1"][1:-1])
    assert np.array_equal(got["drive.F2"][2:], got["controller.F2"][1:-1])
    assert "tracking MAE [um]" in capsys.readouterr().out


@pytest.mark.slow  # builds the native FMUs and runs every baseline
def test_compare_with_the_drive_runs_every_law_with_it(fmus_dir, tmp_path):
    out = tmp_path / "compare"
    assert main(["compare", PAPER, "--set", "drive=true", "--set", "stop_time=0.02", "--fmus", "fmi3",
                 "--fmus-dir", str(fmus_dir), "--out", str(out), "--no-figures",
                 "--no-noise", "--no-progress"]) == 0
    runs = [p.parent for p in out.glob("*/run.json")]
    assert {"sc-dc", "apd-dc"} <= {p.name for p in runs}
    for folder in runs:
        run = json.loads((folder / "run.json").read_text())
        assert run["status"] == "completed" and run["ssp"].endswith("fmi3/TAPMP_Drive.ssp")
        assert "drive.F3" in columns(folder / "results.csv")


@pytest.mark.parametrize("args", [["--fmus", "python"], ["--set", 'fmus="python"']], ids=["option", "scenario"])
def test_the_drive_with_the_pythonfmu_family_is_refused_with_one_line_and_exit_2(tmp_path, capsys, args):
    # APD-DC: stable with the drive, so no stability warning precedes the refusal
    assert main(["run", PAPER, "--set", "drive=true", "--set", 'law="apd-dc"', *args, "--out", str(tmp_path / "x"),
                 "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert "drive = true is invalid with fmus = 'python': allowed is fmus = \"native\" or \"fmi3\"" in err
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize("setting, message", [
    ("drive.current_damping=0.0", "drive.current_damping = 0.0 is invalid: allowed is a number in [0.01, 10]"),
    ("drive.delay_samples=4", "drive.delay_samples = 4 is invalid: allowed is an integer in [0, 3]"),
    ("drive.delay=1", "drive.delay is unknown: allowed are delay_samples, "),
    ("drive=1", "drive = 1 is invalid: allowed is true, false or a [drive] table"),
])
def test_a_bad_drive_setting_is_refused_with_one_line_and_exit_2(tmp_path, capsys, setting, message):
    assert main(["run", PAPER, "--set", setting, "--out", str(tmp_path / "x"), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err, err


@pytest.mark.slow  # builds the native FMUs, starts a Dask cluster
def test_a_study_whose_base_scenario_has_the_drive_runs_every_case_with_it(fmus_dir, tmp_path):
    base = tmp_path / "driven.toml"
    base.write_text("drive = true\n" + Path(PAPER).read_text())  # a top-level key before the tables
    study = tmp_path / "s.toml"
    study.write_text(f'[study]\nname = "s"\nbase = "{base}"\noutput = "{tmp_path / "out"}"\nkeep_results = true\n'
                     '[set]\nstop_time = 0.02\n[grid]\nlaw = ["sc-dc", "apd-dc"]\n')
    assert main(["study", str(study), "--fmus-dir", str(fmus_dir), "--workers", "1", "--no-progress"]) == 0
    runs = list((tmp_path / "out").rglob("run.json"))
    assert len(runs) == 2
    for path in runs:
        run = json.loads(path.read_text())
        assert run["status"] == "completed" and run["ssp"].endswith("fmi2/TAPMP_Drive.ssp")
        assert "drive.F1" in columns(path.parent / "results.csv")


def test_check_with_the_drive_finds_sc_dc_unstable_and_apd_dc_stable(capsys):
    # without the drive both are stable; the default drive's delay and current loop make SC-DC unstable
    assert main(["check", PAPER]) == 0
    assert main(["check", PAPER, "--set", "drive=true"]) == 1
    assert main(["check", PAPER, "--set", "drive=true", "--set", 'law="apd-dc"']) == 0
    out, err = capsys.readouterr()
    assert "unstable: spectral radius" in out and "no drive" not in err
