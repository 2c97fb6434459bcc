"""What a user waits for: `tapmp compare` against one `tapmp run` of the same scenario, each a
fresh command (interpreter start, imports, checks, runs, files, figures), interleaved, the
fastest of --repeat. Run from the repository root after `bash build_fmus.sh`:

    .venv/bin/python benchmarks/bench_compare.py [--scenario scenarios/paper_simulation.toml] [--repeat 3]
                                                 [--jobs N] [--stop-time S] [--ssp FILE]

Prints the wall time of each command (`tapmp run`, `tapmp compare`, `tapmp compare --no-figures`,
`tapmp compare --no-noise`) and the ratios compare / run (target <= 3), compare --no-figures / run
and compare --no-noise / run. --stages
instead times the stages of one comparison in this process (imports, stability checks, the
runs, the figures): "runs" without the figures this process drew while the runs went on,
"figures" all of them, "figures during the runs" the part drawn meanwhile.
"""

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def timed(args: list[str]) -> float:
    """Wall seconds of one `tapmp` command in a fresh process; exits if it fails."""
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "orchestrator", *args, "--no-progress", "--overwrite"],
                          cwd=ROOT, capture_output=True, text=True)
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        raise SystemExit(f"tapmp {' '.join(args)} failed (exit {proc.returncode}):\n{proc.stderr}")
    return wall


def stages(scenario: str, jobs: int, stop_time: float | None, ssp: str | None) -> None:
    """Print the wall time of each stage of one `tapmp compare` run in this process."""
    start = time.perf_counter()
    sys.path.insert(0, str(ROOT))
    from orchestrator.builder.families import resolve_ssp
    from orchestrator.tool import compare, plots, pool
    from orchestrator.tool.scenario import load
    times = {"imports": time.perf_counter() - start}
    during = [False]  # inside run_many: figures drawn there are taken out of the runs' time

    def timed(owner, name, stage):
        original = getattr(owner, name)

        def wrapper(*a, **k):
            t = time.perf_counter()
            inside = during[0]
            if stage == "runs":
                during[0] = True
            try:
                return original(*a, **k)
            finally:
                wall = time.perf_counter() - t
                if stage == "runs":
                    during[0] = False
                times[stage] = times.get(stage, 0.0) + wall
                if stage == "figures" and inside:
                    times["runs"] = times.get("runs", 0.0) - wall
                    times["figures during the runs"] = times.get("figures during the runs", 0.0) + wall
        setattr(owner, name, wrapper)
    timed(compare, "check_runs", "stability checks")
    timed(pool, "run_many", "runs")
    for method in ("__init__", "draw_next", "draw_rest"):  # the figures, during the runs and after them
        timed(plots.FigureSet, method, "figures")
    sc = load(scenario, [f"stop_time={stop_time}"] if stop_time else [])
    ssp = resolve_ssp(ssp, sc.fmus)
    with tempfile.TemporaryDirectory(prefix="tapmp_bench_compare_") as tmp:
        t = time.perf_counter()
        compare.run_comparison(sc, ssp, Path(tmp) / "compare", True, False, "bench_compare", jobs)
        times["whole comparison"] = time.perf_counter() - t
    times.setdefault("figures during the runs", 0.0)
    order = ("imports", "stability checks", "runs", "figures", "figures during the runs", "whole comparison")
    print(f"{'stage':24s}  {'wall [s]':>8s}")
    for stage in order:
        print(f"{stage:24s}  {times.get(stage, 0.0):8.2f}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenario", default=str(ROOT / "scenarios" / "paper_simulation.toml"))
    ap.add_argument("--repeat", type=int, default=3, help="runs of each command (default 3)")
    ap.add_argument("--jobs", help="--jobs of tapmp compare (default: its own, one per core)")
    ap.add_argument("--stop-time", type=float, help="override the scenario's stop_time [s]")
    ap.add_argument("--ssp", help="SSP file (default: tapmp's, the built SSP of the scenario's FMU family)")
    ap.add_argument("--stages", action="store_true", help="time the stages of one comparison in this process")
    args = ap.parse_args(argv)
    extra = ["--set", f"stop_time={args.stop_time}"] if args.stop_time else []
    extra += ["--ssp", args.ssp] if args.ssp else []
    jobs = ["--jobs", args.jobs] if args.jobs else []
    if args.stages:
        sys.path.insert(0, str(ROOT))
        from orchestrator.cli import single_threaded_blas
        single_threaded_blas()  # as the command does, before numpy is loaded
        from orchestrator.tool.pool import parse_jobs
        stages(args.scenario, parse_jobs(args.jobs), args.stop_time, args.ssp)
        return 0
    best = {"tapmp run": float("inf"), "tapmp compare": float("inf"), "tapmp compare --no-figures": float("inf"),
            "tapmp compare --no-noise": float("inf")}
    with tempfile.TemporaryDirectory(prefix="tapmp_bench_compare_") as tmp:
        for r in range(args.repeat):
            for name, cmd in (("tapmp run", ["run", args.scenario, "--out", f"{tmp}/run", *extra]),
                              ("tapmp compare", ["compare", args.scenario, "--out", f"{tmp}/compare", *extra,
                                                 *jobs]),
                              ("tapmp compare --no-figures", ["compare", args.scenario, "--out", f"{tmp}/compare",
                                                              *extra, *jobs, "--no-figures"]),
                              ("tapmp compare --no-noise", ["compare", args.scenario, "--out", f"{tmp}/compare",
                                                            *extra, *jobs, "--no-noise"])):
                wall = timed(cmd)
                best[name] = min(best[name], wall)
                print(f"run {r + 1}/{args.repeat} {name:26s} {wall:7.2f} s", file=sys.stderr)
    print(f"{Path(args.scenario).name}{' stop_time=%g' % args.stop_time if args.stop_time else ''}, "
          f"fastest of {args.repeat}")
    print(f"{'command':26s}  {'wall [s]':>8s}  {'load':>5s}")
    load = os.getloadavg()[0]
    for name, wall in best.items():
        print(f"{name:26s}  {wall:8.2f}  {load:5.2f}")
    print(f"compare / run: {best['tapmp compare'] / best['tapmp run']:.2f}")
    print(f"compare --no-figures / run: {best['tapmp compare --no-figures'] / best['tapmp run']:.2f}")
    print(f"compare --no-noise / run: {best['tapmp compare --no-noise'] / best['tapmp run']:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
