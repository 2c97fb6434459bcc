"""The native FMI 3.0 FMUs built for this machine (a module fixture) and the master's rows of the
paper scenario (0.05 s) macro step by macro step, for the tests of Event Mode and clock ticks."""

import numpy as np
import pytest

from .runs import PAPER

T_S = 1e-4  # the controller's sample interval [s]
FORCES = ("controller.F1", "controller.F2", "controller.F3")


@pytest.fixture(scope="module")
def fmi3(tmp_path_factory):
    """The native FMI 3.0 FMUs, their SSP and the SSP with the clocked controller, built for this machine."""
    from orchestrator.builder.build_native import build_native
    return build_native(tmp_path_factory.mktemp("native"), families=("fmi3",), log=lambda *_: None,
                        windows=False)["fmi3"]


def run(ssp, step, n, ordering="gauss-seidel", **kw):
    """Rows (time [s] and every output) at t0 and after each of n macro steps of ``step`` [s], the
    column names and the controller's events handled (None without a controller element); the
    controller samples every T_s = 0.1 ms. ``kw`` are CoSimulation's options (event_mode, stepper)."""
    from orchestrator.engine.master import CoSimulation, RunOptions
    from orchestrator.tool.roles import ROLES
    from orchestrator.tool.scenario import load
    scenario = load(PAPER, ["stop_time=0.05"])
    rows = []
    with CoSimulation(ssp, scenario.parameters(), RunOptions(start_time=0.0, step_size=step, ordering=ordering, **kw,
                                                             roles=ROLES)) as sim:
        rows.append(sim.row())
        for _ in range(n):
            sim.step()
            rows.append(sim.row())
        events = sim.units["controller"].n_events if "controller" in sim.units else None
        return np.array(rows), sim.columns, events
