"""The scenario key plant_interface: "cs" (default) or "me"; Model Exchange refuses measurement noise
(drawn once per communication step), so a scenario with both, and so tapmp compare's noise runs of a
Model Exchange scenario, are refused in one line before anything runs."""

from pathlib import Path

import pytest

from orchestrator.tool.scenario import ScenarioError, load

PAPER = Path(__file__).resolve().parents[2] / "scenarios" / "paper_simulation.toml"


def test_the_plant_interface_is_co_simulation_unless_the_scenario_says_me():
    assert load(PAPER).plant_interface == "cs"
    assert load(PAPER, ["plant_interface=me"]).plant_interface == "me"
    with pytest.raises(ScenarioError) as err:
        load(PAPER, ["plant_interface=rk4"])
    assert str(err.value) == "plant_interface = 'rk4' is invalid: allowed are cs, me"


def test_model_exchange_with_measurement_noise_is_refused_naming_both():
    with pytest.raises(ScenarioError) as err:
        load(PAPER, ["plant_interface=me", "plant.noise_rms=2e-8"])
    assert str(err.value) == (
        'plant.noise_rms = 2e-08 is invalid with plant_interface = "me": allowed is 0 (the noise is drawn once '
        'per communication step, which Model Exchange does not have; use plant_interface = "cs", or tapmp '
        "compare --no-noise)")
    scenario = load(PAPER, ["plant_interface=me"])
    with pytest.raises(ScenarioError, match="plant.noise_rms = 2e-08 is invalid with plant_interface"):
        scenario.with_changes(plant={**scenario.plant, "noise_rms": 2e-8})  # what compare's noise runs do
    assert load(PAPER, ["plant.noise_rms=2e-8"]).plant["noise_rms"] == 2e-8  # Co-Simulation draws it
