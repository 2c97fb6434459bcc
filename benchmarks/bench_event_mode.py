"""Microseconds per macro step of the tapmp master in FMI 3.0 Event Mode, compiled core vs Python loop.

The native FMI 3.0 closed loops (build/native/fmi3/TAPMP.ssp with the event-mode controller,
TAPMP_Clocked.ssp with the clocked one; `tapmp build` first), paper scenario, macro steps of
0.1 ms, the stepping loop only (CoSimulation.advance), fastest of --repeat runs; and whether both
loops gave the same doubles.
"""

import argparse
import time
from pathlib import Path

import numpy as np

from orchestrator.engine.master import CoSimulation, RunOptions
from orchestrator.tool.roles import ROLES
from orchestrator.tool.scenario import load

ROOT = Path(__file__).resolve().parents[1]
FMI3 = ROOT / "build" / "native" / "fmi3"


def timed(ssp: Path, stepper: str, steps: int, repeat: int, parameters: dict):
    """The fastest time per macro step [s] of ``repeat`` runs of ``steps`` steps, and the rows of the last."""
    best = float("inf")
    for _ in range(repeat):
        with CoSimulation(ssp, parameters, RunOptions(start_time=0.0, step_size=1e-4, event_mode=True, stepper=stepper,
                                                      roles=ROLES)) as sim:
            rows = np.zeros((steps, len(sim.columns)))
            start = time.perf_counter()
            sim.advance(rows)
            best = min(best, time.perf_counter() - start)
    return best / steps, rows


def main() -> None:
    """Print the time per macro step [us] for each SSP and stepper."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--ssp", nargs="+", type=Path, default=[FMI3 / "TAPMP.ssp", FMI3 / "TAPMP_Clocked.ssp"])
    ap.add_argument("--steps", type=int, default=10_000, help="macro steps of 0.1 ms per run (default 10000)")
    ap.add_argument("--repeat", type=int, default=5, help="runs per loop (default 5)")
    args = ap.parse_args()
    parameters = load(ROOT / "scenarios" / "paper_simulation.toml").parameters()
    same = True
    for ssp in args.ssp:
        python, rows_p = timed(ssp, "python", args.steps, args.repeat, parameters)
        compiled, rows_c = timed(ssp, "compiled", args.steps, args.repeat, parameters)
        same = same and np.array_equal(rows_p, rows_c)
        print(f"{ssp.name}: python {python * 1e6:.2f} us, compiled {compiled * 1e6:.2f} us per macro step")
    print(f"same doubles: {'yes' if same else 'no'}")


if __name__ == "__main__":
    main()
