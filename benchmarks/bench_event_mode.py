"""Microseconds per macro step of the tapmp master in FMI 3.0 Event Mode, compiled core vs Python loop.

The native FMI 3.0 closed loops (build/native/fmi3/TAPMP.ssp with the event-mode controller,
TAPMP_Clocked.ssp with the clocked one; `tapmp build` first), paper scenario, 10,000 macro steps of
0.1 ms, the stepping loop only (CoSimulation.advance), fastest of 5 runs.
"""

import time
from pathlib import Path

import numpy as np

from orchestrator.engine.master import CoSimulation
from orchestrator.tool.roles import ROLES
from orchestrator.tool.scenario import load

ROOT = Path(__file__).resolve().parents[1]
STEPS, REPEAT = 10_000, 5


def main() -> None:
    """Print the time per macro step [us] for each SSP and stepper."""
    parameters = load(ROOT / "scenarios" / "paper_simulation.toml").parameters()
    for name in ("TAPMP.ssp", "TAPMP_Clocked.ssp"):
        ssp = ROOT / "build" / "native" / "fmi3" / name
        for stepper in ("python", "compiled"):
            best = float("inf")
            for _ in range(REPEAT):
                with CoSimulation(ssp, parameters, 0.0, 1e-4, event_mode=True, stepper=stepper, roles=ROLES) as sim:
                    rows = np.zeros((STEPS, len(sim.columns)))
                    start = time.perf_counter()
                    sim.advance(rows)
                    best = min(best, time.perf_counter() - start)
            print(f"{name}, {stepper}: {best / STEPS * 1e6:.2f} us per macro step")


if __name__ == "__main__":
    main()
