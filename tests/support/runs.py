"""The paper's scenario shortened, the columns tests compare, and the orchestrator's rows of a run."""

from .shared import ROOT

PAPER = ROOT / "scenarios" / "paper_simulation.toml"
MOTOR_POSITIONS = tuple(f"plant.q{i}_true" for i in (1, 2, 3)) + tuple(f"plant.q{i}" for i in (1, 2, 3))
COMMANDS = tuple(f"controller.F{i}" for i in (1, 2, 3))


def paper_scenario(stop_time=0.2, *overrides):
    """The paper's simulation scenario, shortened (0.2 s = 2,000 steps of 0.1 ms)."""
    from orchestrator.tool.scenario import load
    return load(PAPER, [f"stop_time={stop_time}", *overrides])


def orchestrator_rows(ssp, scenario, names, ordering="jacobi", **conventions):
    """The orchestrator's values of ``names`` ("element.variable") at t_0 ... t_n, one row per
    communication point; ``conventions`` are CoSimulation's clock / connection_start."""
    import numpy as np

    from orchestrator.engine.master import CoSimulation, RunOptions
    from orchestrator.tool.roles import ROLES
    rows = []
    with CoSimulation(ssp, scenario.parameters(), RunOptions(start_time=scenario.start_time, step_size=scenario.step,
                                                             ordering=ordering, **conventions, roles=ROLES)) as sim:
        index = [sim.columns.index(n) for n in names]
        rows.append([sim.row()[i] for i in index])
        for _ in range(scenario.n_steps):
            sim.step()
            row = sim.row()
            rows.append([row[i] for i in index])
    return np.array(rows)
