"""The three FMU families give the same closed loop, and the command line picks a family
with --fmus or the scenario key fmus."""

import json

import numpy as np
import pytest

from conftest import COMMANDS, MOTOR_POSITIONS, PAPER, orchestrator_rows, paper_scenario
from orchestrator.engine import families
from orchestrator.cli import main

TRUE_POSITIONS = MOTOR_POSITIONS[:3]


@pytest.mark.parametrize("law", ("sc-dc", "apd-dc"))
@pytest.mark.parametrize("ordering", ("gauss-seidel", "jacobi"))
def test_native_fmi2_follows_pythonfmu_and_fmi3_follows_fmi2_over_half_a_second(law, ordering, built,
                                                                                  native_built):
    scenario = paper_scenario(0.5, f'law="{law}"')
    names = TRUE_POSITIONS + COMMANDS
    python = orchestrator_rows(built["ssp"], scenario, names, ordering)
    fmi2 = orchestrator_rows(native_built["fmi2"]["ssp"], scenario, names, ordering)
    fmi3 = orchestrator_rows(native_built["fmi3"]["ssp"], scenario, names, ordering)
    assert len(fmi2) == scenario.n_steps + 1 == 5001
    for a, b in ((fmi2, python), (fmi3, fmi2)):
        assert np.abs(a[:, :3] - b[:, :3]).max() <= 1e-12  # m
        assert np.abs(a[:, 3:] - b[:, 3:]).max() <= 1e-6   # N
    assert np.abs(fmi2[:, 3:]).max() > 1.0  # the loop did something


def test_scenario_key_fmus_selects_the_family_of_a_run(native_built, tmp_path, monkeypatch):
    monkeypatch.setitem(families.FAMILIES, "fmi3", native_built["fmi3"]["ssp"])
    out = tmp_path / "run"
    assert main(["run", str(PAPER), "--set", "stop_time=0.01", "--set", 'fmus="fmi3"', "--out", str(out),
                 "--no-progress"]) == 0
    run = json.loads((out / "run.json").read_text())
    assert run["ssp"] == str(native_built["fmi3"]["ssp"]) and run["status"] == "completed"


def test_option_fmus_overrides_the_scenario(native_built, tmp_path, monkeypatch):
    monkeypatch.setitem(families.FAMILIES, "native", native_built["fmi2"]["ssp"])
    out = tmp_path / "run"
    assert main(["run", str(PAPER), "--set", "stop_time=0.01", "--set", 'fmus="python"', "--fmus", "native",
                 "--out", str(out), "--no-progress"]) == 0
    assert json.loads((out / "run.json").read_text())["ssp"] == str(native_built["fmi2"]["ssp"])


def test_a_family_that_is_not_built_is_one_line_naming_the_build_command(tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(families.FAMILIES, "fmi3", tmp_path / "native" / "fmi3" / "TAPMP.ssp")
    assert main(["run", str(PAPER), "--fmus", "fmi3", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "the fmi3 FMUs are not built" in err and "bash build_fmus.sh" in err, err
    assert not (tmp_path / "out" / "results.csv").exists()


def test_an_unknown_family_names_the_allowed_ones(tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["run", str(PAPER), "--fmus", "java"])
    assert exit_.value.code == 2
    assert "python" in capsys.readouterr().err
    assert main(["run", str(PAPER), "--set", 'fmus="java"', "--out", str(tmp_path / "o")]) == 2
    assert "fmus = 'java' is invalid: allowed are python, native, fmi3" in capsys.readouterr().err
