"""The master's additive input perturbation (RunOptions.perturb, orchestrator.engine.perturbation):
the FMU steps with what the connection delivers plus the perturbation, the master keeps the values
set, a zero perturbation changes no bit, and a perturbation it cannot apply is refused by name."""

import math
from dataclasses import replace

import numpy as np
import pytest

from orchestrator.engine.master import CoSimulation, CoSimulationError
from orchestrator.tool.results import run_options
from orchestrator.tool.scenario import load

from tests.support.shared import ROOT

pytestmark = pytest.mark.slow

PAPER = ROOT / "scenarios" / "paper_simulation.toml"
STEPS = 300


@pytest.fixture(scope="module")
def native(tmp_path_factory):
    from orchestrator.builder.build_native import build_native
    return build_native(tmp_path_factory.mktemp("native_perturb"), log=lambda *_: None, windows=False)


def rows_of(ssp, scenario, **changes):
    """(rows after each of STEPS steps, columns, perturbed inputs as set) of a co-simulation."""
    with CoSimulation(ssp, scenario.parameters(), replace(run_options(scenario), **changes)) as sim:
        rows = np.empty((STEPS, len(sim.columns)))
        sim.advance(rows)
        return rows, sim.columns, sim.perturbed_inputs


@pytest.mark.parametrize("ordering", ["gauss-seidel", "jacobi"])
def test_the_plant_steps_with_the_controllers_force_plus_the_perturbation(native, ordering):
    scenario = load(PAPER, [f'ordering="{ordering}"'])
    d = 5.0 * np.sin(np.arange(STEPS) * 0.3)
    rows, columns, applied = rows_of(native["fmi2"]["ssp"], scenario, perturb={"plant.F2": d,
                                                                               "plant.F3": lambda t: 2.0 * t})
    assert set(applied) == {"plant.F2", "plant.F3"} and all(len(v) == STEPS for v in applied.values())
    # the controller's force the plant got in step k: the row after it (Gauss-Seidel: the controller
    # steps first) or the row before it (Jacobi: the outputs at t_k)
    for name, dk in (("plant.F2", d), ("plant.F3", 2.0 * (scenario.start_time + scenario.step * np.arange(STEPS)))):
        y = rows[:, columns.index("controller." + name.split(".")[1])]
        if ordering == "gauss-seidel":
            assert np.array_equal(applied[name], y + dk)
        else:
            assert np.array_equal(applied[name][1:], y[:-1] + dk[1:])


def test_a_zero_perturbation_changes_no_bit_of_the_run(native):
    scenario = load(PAPER)
    plain, _, none = rows_of(native["fmi2"]["ssp"], scenario)
    zero, _, applied = rows_of(native["fmi2"]["ssp"], scenario, perturb={"plant.F1": np.zeros(STEPS)})
    assert none == {} and np.array_equal(plain, zero) and len(applied["plant.F1"]) == STEPS


@pytest.mark.parametrize("changes, message", [
    (dict(perturb={"plant.F7": [1.0]}), "perturb: 'plant.F7' is not an input of the system in SSP file"),
    (dict(perturb={"plant.F1": [1.0, math.nan]}), "perturb['plant.F1'] = list is invalid: allowed is a callable"),
    (dict(perturb={"plant.F1": [1.0]}, stepper="compiled"), "stepper = 'compiled' is unavailable with perturb"),
    (dict(perturb={"plant.F1": [1.0]}, event_mode=True), "perturb is invalid with event_mode = true"),
], ids=["unknown input", "not finite", "compiled stepper", "event mode"])
def test_a_perturbation_the_master_cannot_apply_is_refused_by_name(native, changes, message):
    scenario = load(PAPER)
    ssp = native["fmi3" if changes.get("event_mode") else "fmi2"]["ssp"]
    with pytest.raises(CoSimulationError, match=message.replace("[", r"\[").replace("]", r"\]")):
        with CoSimulation(ssp, scenario.parameters(), replace(run_options(scenario), **changes)):
            pass

