"""The master ticks the clocked controller (TAPMP_ControllerClocked, a periodic input clock of interval
T_s) in Event Mode at every tick t0 + k T_s whatever the macro step, and gets the forces of the Event Mode
controller (TAPMP_Controller with eventModeUsed, time events at the same instants) bit for bit."""

from pathlib import Path

import numpy as np
import pytest

from orchestrator.engine.master import CoSimulation, CoSimulationError
from orchestrator.tool.roles import ROLES
from orchestrator.tool.scenario import load

pytestmark = pytest.mark.slow  # builds the FMI 3.0 FMUs and runs closed loops

ROOT = Path(__file__).resolve().parents[3]
PAPER = ROOT / "scenarios" / "paper_simulation.toml"
T_S = 1e-4
FORCES = ("controller.F1", "controller.F2", "controller.F3")


@pytest.fixture(scope="module")
def fmi3(tmp_path_factory):
    """The native FMI 3.0 FMUs, their SSP and the SSP with the clocked controller, built for this machine."""
    from orchestrator.engine.build_native import build_native
    return build_native(tmp_path_factory.mktemp("native"), families=("fmi3",), log=lambda *_: None,
                        windows=False)["fmi3"]


def run(ssp, step, n, **kw):
    """Rows (time and every output) at t0 and after each of n macro steps of ``step`` [s], the column
    names and the controller's updates (samples)."""
    scenario = load(PAPER, ["stop_time=0.05"])
    rows = []
    with CoSimulation(ssp, scenario.parameters(), 0.0, step, "gauss-seidel", **kw, roles=ROLES) as sim:
        rows.append(sim.row())
        for _ in range(n):
            sim.step()
            rows.append(sim.row())
        return np.array(rows), sim.columns, sim.units["controller"].n_events


@pytest.mark.parametrize("step, n", [(T_S, 500), (1e-3, 50), (2.5e-4, 200)])
def test_ticking_the_clocked_controller_gives_the_event_mode_run_bit_for_bit(fmi3, step, n):
    events, columns, n_events = run(fmi3["ssp"], step, n, event_mode=True)
    clocked, clocked_columns, n_ticks = run(fmi3["clocked_ssp"], step, n, event_mode=True)
    assert clocked_columns == columns
    assert n_ticks == n_events == 500  # t = 0 and every tick up to 0.0499 s; the one at 0.05 s is due next
    np.testing.assert_array_equal(clocked, events)


def test_the_clocked_controller_without_event_mode_is_refused(fmi3):
    with pytest.raises(CoSimulationError) as err:
        run(fmi3["clocked_ssp"], T_S, 1)
    assert str(err.value) == (
        f"event_mode = false is invalid for SSP file {fmi3['clocked_ssp']}: the FMU TAPMP_ControllerClocked of "
        "element controller has the input clock(s) sample_clock, which tick only in Event Mode: allowed is "
        "event_mode = true")


def test_the_clocked_controller_with_the_compiled_core_is_refused(fmi3):
    with pytest.raises(CoSimulationError) as err:
        run(fmi3["clocked_ssp"], T_S, 1, event_mode=True, stepper="compiled")
    assert str(err.value) == ("stepper = 'compiled' is unavailable with event_mode = true: allowed are 'python' or "
                              "'auto' (event mode runs in the Python loop)")
