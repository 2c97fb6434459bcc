"""The orderings' delay through the real master: with Jacobi the plant
steps from t_k on the force command the controller published at t_k (computed in the step
before: one sample of delay); with Gauss-Seidel on the command the controller computed in
the same macro step, from the measurement at t_k. Read back from the plant FMU's own inputs."""

import numpy as np
import pytest
from tests.support.runs import paper_scenario

from orchestrator.engine.master import CoSimulation, RunOptions
from orchestrator.tool.roles import ROLES

FORCES = [f"controller.F{i}" for i in (1, 2, 3)]


def plant_inputs_and_commands(ssp, ordering, steps=300):
    """Per macro step k: the F1..F3 the plant FMU holds after stepping from t_k, and the
    controller's published commands at t_k and at t_{k+1} [N]."""
    sc = paper_scenario(steps * 1e-4)
    applied, before, after = [], [], []
    with CoSimulation(ssp, sc.parameters(), RunOptions(start_time=sc.start_time, step_size=sc.step, ordering=ordering,
                                                       roles=ROLES)) as sim:
        plant = sim.units["plant"]
        vrs = [v.valueReference for v in plant.md.modelVariables if v.name in ("F1", "F2", "F3")]
        cols = [sim.columns.index(f) for f in FORCES]
        for _ in range(steps):
            row = sim.row()
            before.append([row[i] for i in cols])
            sim.step()
            applied.append(plant.slave.getReal(vrs))
            row = sim.row()
            after.append([row[i] for i in cols])
    return np.array(applied), np.array(before), np.array(after)


@pytest.mark.parametrize("ordering, same_step", [("gauss-seidel", True), ("jacobi", False)])
def test_the_plant_steps_on_the_command_of_this_or_the_previous_sample(built, ordering, same_step):
    applied, before, after = plant_inputs_and_commands(built["ssp"], ordering)
    assert np.abs(after[1:] - before[1:]).max() > 1.0   # the command changes from sample to sample [N]
    expected, other = (after, before) if same_step else (before, after)
    assert np.array_equal(applied, expected)             # exactly, every step, every motor
    assert not np.allclose(applied, other, atol=1e-3)



def test_the_plain_python_loop_offers_the_masters_orderings():
    from orchestrator.engine.schedule import ORDERINGS
    from tapmp.interface import ORDERINGS as PLAIN_LOOP_ORDERINGS  # tapmp.closed_loop's
    assert PLAIN_LOOP_ORDERINGS == ORDERINGS
