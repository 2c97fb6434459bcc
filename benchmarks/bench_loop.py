"""The FMI-free loop: the readable Python loop (tapmp.closed_loop.simulate, one call into the C
model per model and step) against the same loop stepped in C (tapmp.closed_loop.run), on the
paper's gains at a fine step, timed together (interleaved, the fastest of --repeat). Run from the
repository root:

    .venv/bin/python benchmarks/bench_loop.py [--case "Eq. 40-41"] [--law sc-dc] [--step 1e-6]
                                              [--stop-time 0.05] [--repeat 3]

Prints the wall time and microseconds per step of each loop, whether their rows are the same
doubles, and the ratio Python / C. `tapmp reproduce` runs these loops for its paper-gain table
(orchestrator.paper.paper_gains), 0.5 s per run at 1 us, 10 us and 0.1 ms.
"""

import argparse
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from orchestrator.paper.paper_gains import CASES, LAWS, paper_scenario  # noqa: E402
from tapmp.closed_loop import COLUMNS, run, simulate  # noqa: E402

SIMULATE_COLUMNS = [i for i, c in enumerate(COLUMNS) if not c.startswith("q_d")]


def python_loop(sc) -> tuple[float, np.ndarray]:
    plant, ctrl, traj = sc.plain_models()
    rows = []
    start = time.perf_counter()
    simulate(plant, ctrl, traj, sc.start_time, sc.n_steps, sc.step, sc.ordering,
             lambda t, ref, F, q, q_true: rows.append((t, *ref, *F, *q, *q_true, *plant.state)))
    return time.perf_counter() - start, np.array(rows)


def compiled_loop(sc) -> tuple[float, np.ndarray]:
    plant, ctrl, traj = sc.plain_models()
    blocks = []
    start = time.perf_counter()
    run(plant, ctrl, traj, sc.start_time, sc.n_steps, sc.step, sc.ordering, blocks.append)
    return time.perf_counter() - start, np.concatenate(blocks)[:, SIMULATE_COLUMNS]


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--case", default="Eq. 40-41", choices=list(CASES))
    p.add_argument("--law", default="sc-dc", choices=list(LAWS))
    p.add_argument("--step", type=float, default=1e-6, help="macro step [s] (default 1e-6)")
    p.add_argument("--stop-time", type=float, default=0.05, help="horizon [s] (default 0.05)")
    p.add_argument("--repeat", type=int, default=3, help="runs of each loop, interleaved (default 3)")
    args = p.parse_args()
    sc = paper_scenario(args.case, args.law, args.step, args.stop_time)
    best = {"python": float("inf"), "compiled": float("inf")}
    same = True
    for _ in range(args.repeat):
        wall_py, rows_py = python_loop(sc)
        wall_c, rows_c = compiled_loop(sc)
        best["python"], best["compiled"] = min(best["python"], wall_py), min(best["compiled"], wall_c)
        same = same and rows_py.shape == rows_c.shape and np.array_equal(rows_py.view(np.int64),
                                                                           rows_c.view(np.int64))
    print(f"{args.case} {args.law}, step {args.step:g} s, {sc.n_steps} steps, fastest of {args.repeat}, "
          f"load average {os.getloadavg()[0]:.2f}")
    print(f"{'loop':10s}  {'wall [s]':>8s}  {'us/step':>8s}")
    for name, wall in best.items():
        print(f"{name:10s}  {wall:8.3f}  {1e6 * wall / sc.n_steps:8.2f}")
    print(f"same doubles: {'yes' if same else 'NO'}")
    print(f"python / compiled: {best['python'] / best['compiled']:.1f}")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
