"""Scenario files: validated before anything runs, every error names its key."""

from pathlib import Path

import pytest

from orchestrator.tool.scenario import ScenarioError, load

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "scenarios" / "paper_simulation.toml"


def test_paper_scenarios_load_with_their_frequencies():
    sim = load(PAPER)
    exp = load(ROOT / "scenarios" / "paper_experiment.toml")
    assert (sim.trajectory["f_B"], exp.trajectory["f_B"]) == (0.4, 0.18)
    assert sim.n_steps == 25000 and sim.step == 1e-4


def test_start_on_trajectory_places_the_plant_on_the_reference():
    p = load(PAPER).parameters()["plant"]
    assert (p["X0"], p["Z0"], p["B0"]) == pytest.approx((0.0, 0.0, 0.0), abs=1e-15)
    assert p["dX0"] == pytest.approx(0.01 * 2 * 3.141592653589793 * 0.4, rel=1e-12)  # R w


def test_set_overrides_any_value_and_gain_scalars_apply_to_all_motors():
    s = load(PAPER, ["stop_time=0.5", "plant.k_pull=0", "gain_overrides.D=500", 'law="apd-dc"'])
    assert s.stop_time == 0.5 and s.plant["k_pull"] == 0.0 and s.law == "apd-dc"
    assert s.gain_values().D == (500.0, 500.0, 500.0)
    assert s.parameters()["controller"]["D2"] == 500.0 and s.parameters()["controller"]["law"] == 1


@pytest.mark.parametrize("override,message", [
    ("colour=1", r"colour is unknown: allowed are name, description, law"),
    ("plant.mass=2", r"plant.mass is unknown: allowed are m_p"),
    ("step=-1e-4", r"step = -0.0001 is invalid: allowed is a number > 0"),
    ("stop_time=-1", r"stop_time = -1.0 is invalid: allowed is a number > start_time = 0.0"),
    ('law="pid"', r"law = 'pid' is invalid: allowed are sc-dc, apd-dc"),
    ('gains="fast"', r"gains = 'fast' is invalid: allowed are default, paper_experiment, paper_simulation"),
    ('ordering="random"', r"ordering = 'random' is invalid: allowed are gauss-seidel, jacobi"),
    ('clock="wall"', r"clock = 'wall' is invalid: allowed are exact, accumulated, nanoseconds"),
    ('connection_start="one"', r"connection_start = 'one' is invalid: allowed are propagated, zero"),
    ("plant.m_p=-1", r"plant.m_p = -1.0 is invalid: allowed is a number in \[1e-12, 1e\+06\]"),
    ("plant.substeps=0", r"plant.substeps = 0 is invalid: allowed is an integer in \[1, 10000\]"),
    ("controller.velocity_source=2", r"velocity_source = 2 is invalid: allowed is 0 \(backward difference of q\) or 1 \(dq inputs\)"),
    ("gain_overrides.K_T=0", r"gain_overrides.K_T1 = 0.0 is invalid: allowed is a number in \[1e-12, 1e\+12\]"),
    ("gain_overrides.b=[1, 2]", r"gain_overrides.b = \[1, 2\] is invalid: allowed is a number or a list of 3"),
    ('stop_time="long"', r"stop_time = 'long' has the wrong type: allowed is float"),
    ("trajectory.B_amplitude=2.0", r"trajectory.B_amplitude = 2.0 is invalid"),
])
def test_bad_values_are_rejected_naming_the_key(override, message):
    with pytest.raises(ScenarioError, match=message):
        load(PAPER, [override])


def test_malformed_toml_and_missing_file_are_clear(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("law = \n")
    with pytest.raises(ScenarioError, match="is not valid TOML"):
        load(bad)
    with pytest.raises(ScenarioError, match="does not exist"):
        load(tmp_path / "none.toml")
