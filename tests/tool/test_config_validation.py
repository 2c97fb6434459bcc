"""Scenario and study validation: declarative rules without side effects, one line per error."""

import copy
from pathlib import Path

import pytest

from orchestrator.tool.config import build
from orchestrator.tool.scenario import Scenario, ScenarioError, create, from_dict, read_gains_file
from orchestrator.studies.study import StudyError, load_study

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "scenarios" / "paper_simulation.toml"
SC_DC = ROOT / "docs" / "tuning" / "sc-dc.toml"


def test_validation_leaves_its_input_unchanged():
    data = {"name": "x", "stop_time": 1, "plant": {"m_p": 2}, "gain_overrides": {"D": 500},
            "settling_bands": [1, 2e-7], "limits": {"motor_travel": 1}, "mismatch": {"m_1": 2}}
    before = copy.deepcopy(data)
    s = from_dict(data)
    assert data == before and type(data["plant"]["m_p"]) is int  # the input keeps its ints
    assert s.plant["m_p"] == 2.0 and type(s.plant["m_p"]) is float and s.gain_overrides["D"] == [500.0] * 3
    assert s.settling_bands == [1.0, 2e-7] and s.limits["motor_travel"] == 1.0


def test_with_changes_leaves_the_original_scenario_unchanged():
    s = create(name="x", plant={"m_p": 2.0})
    t = s.with_changes(plant={"m_p": 3}, law="apd-dc")
    assert (s.plant, s.law) == ({"m_p": 2.0}, "sc-dc") and (t.plant, t.law) == ({"m_p": 3.0}, "apd-dc")


def test_validation_reads_no_file_the_gains_file_is_read_after_it(tmp_path):
    missing = str(tmp_path / "none.toml")
    s = build(Scenario, ScenarioError, name="x", gains_file=missing)  # validation only: no file is opened
    assert s.gains_file == missing and s.gain_file_values == {}
    with pytest.raises(ScenarioError, match="none.toml' does not exist"):
        read_gains_file(s)
    read = create(name="x", gains_file=str(SC_DC), gain_overrides={"D": 500})
    assert read.gain_file_values and read.gain_values().D == (500.0,) * 3
    with pytest.raises(ScenarioError, match=r"^gain_overrides.K_T1 = 0.0 is invalid"):
        create(name="x", gains_file=str(SC_DC), gain_overrides={"K_T": 0})  # checked on the file's preset


def test_several_errors_give_one_line_naming_the_first():
    with pytest.raises(ScenarioError) as err:
        create(name="x", law="pd", ordering="random", plant={"mass": 1})
    assert str(err.value) == "law = 'pd' is invalid: allowed are sc-dc, apd-dc, pid-dc"


def test_a_study_is_validated_before_its_base_scenario_is_looked_for(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text('[study]\nbase = "none.toml"\n[grid]\n"plant.mass" = [1.0]\n')
    with pytest.raises(StudyError, match=r"s.toml: grid: plant.mass is unknown: allowed are") as err:
        load_study(path)
    assert "\n" not in str(err.value)
    path.write_text('[study]\nbase = "none.toml"\n[grid]\n"plant.m_p" = [1.0]\n')
    with pytest.raises(StudyError, match=r"s.toml: study.base = 'none.toml' does not exist"):
        load_study(path)
