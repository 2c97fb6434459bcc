"""The master with the plant as a Model Exchange FMU (``model_exchange``, the scenario's
``plant_interface = "me"``): CVODE integrates the native FMI 2.0 and 3.0 plants between
communication points in the paper's closed loop, and the run agrees with the Co-Simulation plant's
RK4 closed loop.

The tolerance. Over 0.05 s of the paper scenario (500 steps of 0.1 ms) each integrator's error is
estimated from the runs themselves: RK4's by Richardson extrapolation from the Co-Simulation plant at
one and at two RK4 substeps per step (error(h) ~ 16/15 |y_h - y_h/2|, ~1e-14 of dB's range: RK4
at 0.1 ms is exact to round-off here), CVODE's from the same closed loop at its tolerance TOL and
at TOL / 10 (error(TOL) ~ 10/9 |y_TOL - y_TOL/10|, CVODE's global error being about proportional to
its tolerance; at TOL = 1e-12 up to 2e-7 of a state's range, on Z, restarting at each of the 500
input jumps). A state agrees if |ME - CS| <= 2 x (RK4's error + CVODE's error) (2: the proportionality
is not exact; measured |ME - CS| / (RK4's + CVODE's) <= 1.14). The controller's commands and the encoder positions
are then the same doubles: the plants' true positions differ by ~4e-12 m, far below one encoder
count (0.1 um), so no count flips within the 0.05 s (at TOL = 1e-10 one does, after 43 ms).
"""

import numpy as np
import pytest

from orchestrator.cli import main
from orchestrator.engine.master import CoSimulation, CoSimulationError, RunOptions
from orchestrator.engine.model_exchange import ModelExchangeUnit
from orchestrator.tool.roles import ROLES
from orchestrator.tool.scenario import load
from pathlib import Path

pytestmark = pytest.mark.slow  # builds the native FMUs and runs closed loops

ROOT = Path(__file__).resolve().parents[3]
PAPER = ROOT / "scenarios" / "paper_simulation.toml"
TOL = 1e-12
STATES = tuple(f"plant.{s}" for s in ("X", "Z", "B", "dX", "dZ", "dB", "q1_true", "q2_true", "q3_true"))
EXACT = ("controller.F1", "controller.F2", "controller.F3", "plant.q1", "plant.q2", "plant.q3")


@pytest.fixture(scope="module")
def native(tmp_path_factory):
    """The native FMI 2.0 and 3.0 FMUs and their SSPs, built for this machine."""
    from orchestrator.builder.build_native import build_native
    return build_native(tmp_path_factory.mktemp("native"), log=lambda *_: None, windows=False)


def closed_loop(ssp, model_exchange=(), substeps=1, **kw):
    """The paper scenario's closed loop for 0.05 s: (columns, rows after each step, the plant unit)."""
    scenario = load(PAPER, ["stop_time=0.05"])
    parameters = scenario.parameters()
    parameters.setdefault("plant", {})["substeps"] = substeps
    with CoSimulation(ssp, parameters, RunOptions(start_time=scenario.start_time, step_size=scenario.step,
                                                  ordering=scenario.ordering, roles=ROLES,
                                                  model_exchange=model_exchange, **kw)) as sim:
        rows = np.zeros((scenario.n_steps, len(sim.columns)))
        sim.advance(rows)
        return sim.columns, rows, sim.units["plant"]


@pytest.mark.parametrize("family", ["fmi2", "fmi3"])
def test_the_model_exchange_plant_in_the_closed_loop_agrees_with_the_rk4_plant(native, family):
    ssp = native[family]["ssp"]
    columns, cs, _ = closed_loop(ssp)
    _, cs2, _ = closed_loop(ssp, substeps=2)
    _, me, plant = closed_loop(ssp, ("plant",), me_tolerance=TOL)
    _, me_tighter, _ = closed_loop(ssp, ("plant",), me_tolerance=TOL / 10)
    assert isinstance(plant, ModelExchangeUnit) and plant.fmi3 == (family == "fmi3")
    assert plant.n_reinit >= 500  # CVODE restarted at every input jump
    at = [columns.index(c) for c in STATES]
    rk4_error = 16.0 / 15.0 * np.abs(cs[:, at] - cs2[:, at]).max(axis=0)
    cvode_error = 10.0 / 9.0 * np.abs(me[:, at] - me_tighter[:, at]).max(axis=0)
    diff = np.abs(me[:, at] - cs[:, at]).max(axis=0)
    assert np.all(diff <= 2.0 * (rk4_error + cvode_error)), dict(zip(STATES, zip(diff, rk4_error, cvode_error)))
    assert np.all(rk4_error <= 1e-12 * np.abs(cs[:, at]).max(axis=0))  # RK4: exact to round-off
    assert diff.max() > 0.0  # another integrator: not the same doubles
    exact = [columns.index(c) for c in EXACT]
    assert np.array_equal(me[:, exact], cs[:, exact])  # no encoder count flips: the same commands


def test_plant_interface_me_in_a_scenario_runs_the_plant_for_model_exchange(native, tmp_path, capsys):
    """`tapmp run --set plant_interface=me` runs and records the interface; a bad value is one line, exit 2."""
    import json
    ssp = native["fmi3"]["ssp"]
    common = ["run", str(PAPER), "--ssp", str(ssp), "--set", "stop_time=0.002", "--no-progress"]
    assert main([*common, "--set", "plant_interface=me", "--out", str(tmp_path / "me")]) == 0
    assert json.loads((tmp_path / "me" / "run.json").read_text())["plant_interface"] == "me"
    capsys.readouterr()
    assert main([*common, "--set", "plant_interface=rk4", "--out", str(tmp_path / "bad")]) == 2
    assert capsys.readouterr().err == "error: plant_interface = 'rk4' is invalid: allowed are cs, me\n"


def test_model_exchange_of_an_fmu_without_it_or_of_no_element_is_refused(native):
    ssp = native["fmi2"]["ssp"]
    with pytest.raises(CoSimulationError) as err:
        closed_loop(ssp, ("controller",))
    assert str(err.value).startswith("controller: TAPMP_Controller offers no Model Exchange interface: allowed are "
                                     "FMUs whose modelDescription.xml has <ModelExchange>")
    with pytest.raises(CoSimulationError, match=r"model_exchange: 'motor' is not an element of the system in SSP "
                                                r"file .*: allowed are controller, plant, trajectory$"):
        closed_loop(ssp, ("motor",))
    with pytest.raises(CoSimulationError, match="stepper = 'compiled' is unavailable with a Model Exchange FMU"):
        closed_loop(ssp, ("plant",), stepper="compiled")


def test_a_time_event_inside_a_macro_step_ends_the_integration_there(native):
    """The plant's external force step at disturbance_time = 12.345 ms, inside the step from 12.3 to
    12.4 ms, is a time event: CVODE stops at it, the event is handled (the start event and this one)
    and CVODE restarts there. So at 12.4 ms the force has acted for 0.055 ms: the velocity change it
    made is 0.55 of the one the Co-Simulation plant makes when the step starts on the grid at
    12.3 ms (it acts from the first communication step that starts at or after disturbance_time),
    to the change of the accelerations over 0.1 ms (measured 1.6e-5)."""
    ssp = native["fmi2"]["ssp"]

    def run(model_exchange, force, time):
        scenario = load(PAPER, ["stop_time=0.02", f"plant.disturbance_force1={force}",
                                f"plant.disturbance_time={time}"])
        with CoSimulation(ssp, scenario.parameters(), RunOptions(start_time=0.0, step_size=scenario.step,
                                                                 ordering=scenario.ordering, roles=ROLES,
                                                                 model_exchange=model_exchange)) as sim:
            rows = np.zeros((scenario.n_steps, len(sim.columns)))
            sim.advance(rows)
            return sim.columns, rows, sim.units["plant"]

    columns, me, plant = run(("plant",), 30.0, 0.012345)
    assert plant.n_events == 2 and plant.n_reinit == 200 + 1  # a restart per step and one at the event
    _, me_without, _ = run(("plant",), 0.0, 0.012345)
    _, cs, _ = run((), 30.0, 0.0123)
    _, cs_without, _ = run((), 0.0, 0.0123)
    k = 123  # the row at 12.4 ms
    assert me[k, 0] == pytest.approx(0.0124) and np.array_equal(me[:k], me_without[:k])  # nothing before
    for name in ("plant.dX", "plant.dZ", "plant.dB", "plant.dq1"):
        j = columns.index(name)
        ratio = (me[k, j] - me_without[k, j]) / (cs[k, j] - cs_without[k, j])
        assert ratio == pytest.approx(0.55, abs=1e-3), (name, ratio)
