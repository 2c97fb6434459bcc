"""Cost of writing results: `tapmp run` end to end against the co-simulation alone.
Run from the repository root after `bash build_fmus.sh`:

    .venv/bin/python benchmarks/bench_run.py [--fmus native] [--stop-time 2.5] [--repeat 3] [--profile FORMAT]

On the paper scenario (scenarios/paper_simulation.toml), in one process, interleaved, the
fastest of --repeat runs of each:
  * cosim:     CoSimulation opened and stepped stop_time / step times as tapmp run steps it
               (CoSimulation.advance, blocks of rows in memory), nothing written
               (the floor: what the master and the FMUs cost);
  * run csv:   orchestrator.cli.main(["run", ..., "--format", "csv"]): scenario, plausibility
               and stability checks, the co-simulation, every row to results.csv, metrics.json;
  * run mat:   the same with --format mat (results.mat).
Prints wall times, microseconds per macro step, the ratio run / cosim (target <= 1.3) and
the size of each result file. --profile FORMAT prints the cProfile of one run in that format.
"""

import argparse
import contextlib
import cProfile
import io
import os
import pstats
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as every tapmp command (cli.single_threaded_blas)

import numpy as np  # noqa: E402

from orchestrator.cli import main  # noqa: E402
from orchestrator.builder.families import resolve_ssp  # noqa: E402
from orchestrator.engine.master import CoSimulation  # noqa: E402
from orchestrator.tool.results import BLOCK, run_options  # noqa: E402
from orchestrator.tool.scenario import load  # noqa: E402

SCENARIO = ROOT / "scenarios" / "paper_simulation.toml"


def cosim_alone(scenario, ssp) -> float:
    """Wall time [s] of opening the co-simulation and stepping it to stop_time."""
    start = time.perf_counter()
    with CoSimulation(ssp, scenario.parameters(), run_options(scenario)) as sim:  # the options of tapmp run
        block = np.empty((BLOCK, len(sim.columns)))
        left = scenario.n_steps
        while left:  # the stepping of tapmp run: blocks of rows, compiled core unless TAPMP_STEPPER=python
            left -= sim.advance(block[:min(left, BLOCK)])
    return time.perf_counter() - start


def tapmp_run(args: list[str], out: Path, fmt: str) -> float:
    """Wall time [s] of `tapmp run` in this process, --format fmt into ``out``."""
    start = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()):
        code = main(["run", str(SCENARIO), *args, "--out", str(out), "--format", fmt, "--overwrite",
                     "--no-progress"])
    wall = time.perf_counter() - start
    if code != 0:
        raise SystemExit(f"tapmp run --format {fmt} failed with exit code {code}")
    return wall


def main_bench() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--fmus", default="native", help="FMU family (default native)")
    p.add_argument("--ssp", help="SSP file (default: the built SSP of --fmus)")
    p.add_argument("--stop-time", type=float, default=2.5, help="simulated time [s] (default 2.5)")
    p.add_argument("--repeat", type=int, default=3, help="runs of each configuration (default 3)")
    p.add_argument("--profile", choices=("csv", "mat"), help="print the cProfile of one run in this format")
    a = p.parse_args()
    scenario = load(SCENARIO, [f"stop_time={a.stop_time}"])
    ssp = resolve_ssp(a.ssp, a.fmus)
    args = ["--ssp", str(ssp), "--set", f"stop_time={a.stop_time}"]
    with tempfile.TemporaryDirectory(prefix="bench_run_") as tmp:
        tmp = Path(tmp)
        if a.profile:
            prof = cProfile.Profile()
            prof.enable()
            tapmp_run(args, tmp / "profile", a.profile)
            prof.disable()
            pstats.Stats(prof).sort_stats("cumulative").print_stats(25)
            return
        best = {"cosim": float("inf"), "run csv": float("inf"), "run mat": float("inf")}
        for _ in range(a.repeat):
            best["cosim"] = min(best["cosim"], cosim_alone(scenario, ssp))
            for fmt in ("csv", "mat"):
                best[f"run {fmt}"] = min(best[f"run {fmt}"], tapmp_run(args, tmp / fmt, fmt))
        sizes = {fmt: (tmp / fmt / f"results.{fmt}").stat().st_size for fmt in ("csv", "mat")}
    n = scenario.n_steps
    print(f"paper scenario, {a.stop_time:g} s = {n} steps, {a.fmus} FMUs, fastest of {a.repeat}")
    print(f"{'configuration':<10} {'wall [s]':>9} {'us/step':>8} {'x cosim':>8}  result file")
    for name, wall in best.items():
        fmt = name.split()[-1]
        size = f"results.{fmt}: {sizes[fmt] / 1e6:.2f} MB" if name != "cosim" else "-"
        print(f"{name:<10}  {wall:9.3f}  {wall / n * 1e6:8.1f}  {wall / best['cosim']:8.2f}  {size}")


if __name__ == "__main__":
    main_bench()
