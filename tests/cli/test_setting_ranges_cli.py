"""One range rule per setting, from every command: walking the settings table
(tapmp.interface.VARIABLES), a value just outside each parameter's range, set the way a scenario
sets it, gets the same one line naming the setting, exit 2, from `tapmp check`, `tapmp run` and
`tapmp study` (refused while the study's cases are listed, before any FMU is looked for or Dask
worker started). The
Python model and every FMU family refuse the same values with the same text
(tests/fmu/test_setting_ranges_fmu.py)."""

from pathlib import Path

import pytest

from orchestrator.cli import main
from tapmp.interface import CONTROLLER, ELEMENT, VARIABLES, allowed_text
from tapmp.params import GAIN_NAMES

PAPER = Path(__file__).resolve().parents[2] / "scenarios" / "paper_simulation.toml"
INITIAL_STATE = ("X0", "Z0", "B0", "dX0", "dZ0", "dB0")
# set through the scenario's own keys (law, step), whose refusals name those keys (tests/tool/test_scenario.py)
FROM_SCENARIO = {(CONTROLLER, "law"), (CONTROLLER, "T_s")}
SETTINGS = [(model, v) for model, table in VARIABLES.items() for v in table
            if v.causality == "parameter" and (model, v.name) not in FROM_SCENARIO]


def outside(v):
    """A value just outside the range of ``v``: below an Integer's min, 1 % above a Real's max."""
    return int(v.min) - 1 if v.type == "Integer" else v.max * 1.01


def scenario_keys(model: str, v) -> tuple[dict, str]:
    """({dotted scenario key: value}, the name the refusal gives) that set ``v`` just outside its range:
    a controller gain through [gain_overrides] (its motor's entry), the plant's initial state with
    start_on_trajectory = false, any other setting in its element's table."""
    element = ELEMENT[model]
    if model == CONTROLLER and v.name[:-1] in GAIN_NAMES:
        name, motor = v.name[:-1], int(v.name[-1])
        start = next(u.start for u in VARIABLES[model] if u.name == v.name)
        values = [start] * 3
        values[motor - 1] = outside(v)
        return {f"gain_overrides.{name}": values}, f"gain_overrides.{v.name}"
    keys = {f"{element}.{v.name}": outside(v)}
    if v.name in INITIAL_STATE:
        keys["start_on_trajectory"] = False
    return keys, f"{element}.{v.name}"


def refusal(model, v) -> str:
    return f"{scenario_keys(model, v)[1]} = {float(outside(v)) if v.type != 'Integer' else outside(v)!r} is " \
           f"invalid: allowed is {allowed_text(v)}"


def toml_value(value) -> str:
    return repr(value).lower() if isinstance(value, bool) else repr(value)


def set_args(keys: dict) -> list[str]:
    return [a for k, value in keys.items() for a in ("--set", f"{k}={toml_value(value)}")]


@pytest.mark.parametrize("model, v", SETTINGS, ids=[f"{ELEMENT[m]}.{v.name}" for m, v in SETTINGS])
def test_check_and_run_refuse_a_setting_just_outside_its_range_in_one_line(tmp_path, capsys, model, v):
    keys, _ = scenario_keys(model, v)
    # an SSP that does not exist: the setting is refused before any FMU is looked for
    for command in (["check"], ["run", "--out", str(tmp_path / "r"), "--no-progress", "--ssp", str(tmp_path / "no.ssp")]):
        code = main([command[0], str(PAPER), *set_args(keys), *command[1:]])
        err = capsys.readouterr().err
        assert (code, err) == (2, f"error: {refusal(model, v)}\n"), command[0]
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize("model, v", SETTINGS, ids=[f"{ELEMENT[m]}.{v.name}" for m, v in SETTINGS])
def test_a_study_refuses_a_grid_value_just_outside_its_range_before_starting_workers(tmp_path, capsys, model, v):
    keys, _ = scenario_keys(model, v)
    (key, value), *others = keys.items()
    rows = "".join(f'"{k}" = {toml_value(x)}\n' for k, x in others)
    study = tmp_path / "walk.toml"
    study.write_text(f'[study]\nname = "walk"\nbase = "{PAPER}"\n[set]\nstop_time = 0.01\n{rows}'
                     f'[grid]\n"{key}" = [{toml_value(value)}]\n')
    code = main(["study", str(study), "--out", str(tmp_path / "o"), "--no-progress", "--ssp", str(tmp_path / "no.ssp")])
    err = capsys.readouterr().err
    assert (code, err) == (2, f"error: grid: {refusal(model, v)}\n")
    assert not (tmp_path / "o").exists()


def test_the_plants_initial_state_is_refused_where_start_on_trajectory_would_replace_it(capsys):
    code = main(["check", str(PAPER), "--set", "plant.X0=0.001"])
    assert (code, capsys.readouterr().err) == (
        2, "error: plant.X0 = 0.001 is invalid with start_on_trajectory = true (the plant starts on the reference's "
           "pose and velocity): allowed is start_on_trajectory = false to set the plant's initial state\n")
