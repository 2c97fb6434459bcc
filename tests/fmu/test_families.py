"""The three FMU families give the same closed loop, and the command line picks a family
with --fmus or the scenario key fmus."""

import json

import numpy as np
import pytest

from tests.support.runs import COMMANDS, MOTOR_POSITIONS, PAPER, orchestrator_rows, paper_scenario
from orchestrator.builder import families
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


def test_the_paper_scenario_only_restates_every_fmus_defaults():
    """Every value scenarios/paper_simulation.toml gives an FMU (its .ssv when exported) is that
    FMU variable's start value, to the bit (dZ0 is -0.0 in both): the FMUs wired with their
    defaults are the paper's simulation, the plant starting on the reference."""
    import struct

    from orchestrator.tool.scenario import load
    from tapmp.interface import ELEMENT, INITIAL_STATE, VARIABLES
    from tapmp.trajectory import TrajectoryParams, reference

    given = load(PAPER).parameters()
    for model, table in VARIABLES.items():
        start = {v.name: v.start for v in table}
        values = given[ELEMENT[model]]
        assert values, model
        for name, value in values.items():
            assert struct.pack("<d", float(value)) == struct.pack("<d", float(start[name])), (model, name, value)
    assert INITIAL_STATE == reference(0.0, TrajectoryParams())[:6]  # the C model's reference, bit for bit
    assert INITIAL_STATE[3] > 0.02 and INITIAL_STATE[5] > 0.2      # moving: 25 mm/s in X, 0.22 rad/s in B


@pytest.mark.parametrize("family", ("fmi2", "fmi3"))
def test_native_fmus_wired_with_their_defaults_run_the_paper_scenario_bit_for_bit(family, native_built):
    """The master on the native SSP with no parameter set gives the same doubles as the paper
    scenario with its parameters, in both orderings."""
    from orchestrator.engine.master import CoSimulation, RunOptions
    from orchestrator.tool.roles import ROLES

    scenario = paper_scenario(0.05)
    names = MOTOR_POSITIONS + COMMANDS
    for ordering in ("gauss-seidel", "jacobi"):
        ours = orchestrator_rows(native_built[family]["ssp"], scenario, names, ordering)
        rows = []
        with CoSimulation(native_built[family]["ssp"], {}, RunOptions(start_time=0.0, step_size=scenario.step,
                                                                      ordering=ordering, roles=ROLES)) as sim:
            index = [sim.columns.index(n) for n in names]
            rows.append([sim.row()[i] for i in index])
            for _ in range(scenario.n_steps):
                sim.step()
                rows.append([sim.row()[i] for i in index])
        assert np.array_equal(np.array(rows), ours), ordering
        assert np.abs(ours[:, 6:]).max() > 1.0  # N: the loop did something
