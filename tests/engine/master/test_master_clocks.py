"""The master ticks the clocked controller (TAPMP_ControllerClocked, a periodic input clock of interval
T_s) in Event Mode at every tick t0 + k T_s whatever the macro step, and gets the forces of the Event Mode
controller (TAPMP_Controller with eventModeUsed, time events at the same instants) bit for bit."""

import numpy as np
import pytest

from orchestrator.engine.master import CoSimulation, CoSimulationError, RunOptions
from orchestrator.tool.roles import ROLES
from orchestrator.tool.scenario import load
from tests.support.native_fmi3_runs import T_S, fmi3, run  # noqa: F401 (fmi3 is a fixture)
from tests.support.runs import PAPER

pytestmark = pytest.mark.slow  # builds the FMI 3.0 FMUs and runs closed loops


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


def test_the_clocked_controller_with_the_compiled_core_gives_the_python_loops_rows(fmi3):
    rows = {}
    for stepper in ("compiled", "python"):
        scenario = load(PAPER, ["stop_time=0.05"])
        with CoSimulation(fmi3["clocked_ssp"], scenario.parameters(), RunOptions(start_time=0.0, step_size=1e-3,
                                                                                 event_mode=True, stepper=stepper,
                                                                                 roles=ROLES)) as sim:
            rows[stepper] = np.zeros((20, len(sim.columns)))
            sim.advance(rows[stepper])
            assert (sim._core is not None) == (stepper == "compiled")
            assert sim.units["controller"].n_events == 200  # t = 0 and every tick up to 0.0199 s
    np.testing.assert_array_equal(rows["compiled"], rows["python"])
