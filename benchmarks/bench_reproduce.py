"""What the README's tour waits for: `tapmp reproduce --format mat --record-every 10` against one
`tapmp run` of the paper scenario, each a fresh command, timed one after the other (the fastest
of --repeat of each). Run from the repository root after `bash build_fmus.sh`:

    .venv/bin/python benchmarks/bench_reproduce.py [--repeat 2] [--stop-time S] [--paper-gains-stop-time S] [--ssp FILE]

Prints the wall and CPU time (the command and its child processes) of each and the ratio
reproduce / run (target <= 15). --stop-time S runs every scenario for S seconds (a smoke
test: copies of the four paper scenarios with that horizon); --paper-gains-stop-time is passed
on to `tapmp reproduce`; --ssp FILE runs both commands on that SSP file (default: tapmp's, the
built native FMUs).
"""

import argparse
import os
import re
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SCENARIOS = ("paper_simulation", "paper_experiment", "paper_simulation_calibrated", "paper_experiment_calibrated")


def timed(args: list[str]) -> tuple[float, float]:
    """(wall [s], CPU [s] of the command and its children) of one `tapmp` command in a fresh process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "orchestrator", *args, "--no-progress", "--overwrite"], cwd=ROOT,
                          capture_output=True, text=True)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        raise SystemExit(f"tapmp {' '.join(args)} failed (exit {proc.returncode}):\n{proc.stderr[-3000:]}")
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def short_scenarios(folder: Path, stop_time: float) -> Path:
    """Copies of the paper scenarios with stop_time = ``stop_time`` [s] in ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    for name in SCENARIOS:
        text, n = re.subn(r"(?m)^stop_time = [0-9.]+", f"stop_time = {stop_time}",
                          (ROOT / "scenarios" / f"{name}.toml").read_text())
        if n != 1:
            raise SystemExit(f"scenarios/{name}.toml: no single stop_time line to shorten")
        (folder / f"{name}.toml").write_text(text)
    return folder


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=2, help="runs of each command (default 2)")
    ap.add_argument("--stop-time", type=float, help="run every scenario for this many seconds (smoke test)")
    ap.add_argument("--paper-gains-stop-time", type=float, help="passed on to tapmp reproduce")
    ap.add_argument("--ssp", help="SSP file of both commands (default: tapmp's)")
    args = ap.parse_args(argv)
    best = {"tapmp run": (float("inf"), 0.0), "tapmp reproduce": (float("inf"), 0.0)}
    with tempfile.TemporaryDirectory(prefix="tapmp_bench_reproduce_") as tmp:
        scenario = str(ROOT / "scenarios" / "paper_simulation.toml")
        extra = []
        if args.stop_time:
            folder = short_scenarios(Path(tmp) / "scenarios", args.stop_time)
            scenario, extra = str(folder / "paper_simulation.toml"), ["--scenarios", str(folder)]
        if args.paper_gains_stop_time:
            extra += ["--paper-gains-stop-time", str(args.paper_gains_stop_time)]
        ssp = ["--ssp", args.ssp] if args.ssp else []
        extra += ssp
        commands = {"tapmp run": ["run", scenario, "--out", f"{tmp}/run", *ssp],
                    "tapmp reproduce": ["reproduce", "--format", "mat", "--record-every", "10",
                                        "--results", f"{tmp}/results", *extra]}
        for r in range(args.repeat):
            for name, cmd in commands.items():
                wall, cpu = timed(cmd)
                if wall < best[name][0]:
                    best[name] = (wall, cpu)
                print(f"run {r + 1}/{args.repeat} {name:16s} {wall:7.2f} s", file=sys.stderr)
    print(f"paper scenarios{' stop_time=%g' % args.stop_time if args.stop_time else ''}, fastest of {args.repeat}")
    print(f"{'command':16s}  {'wall [s]':>8s}  {'CPU [s]':>8s}  {'load':>5s}")
    load = os.getloadavg()[0]
    for name, (wall, cpu) in best.items():
        print(f"{name:16s}  {wall:8.2f}  {cpu:8.2f}  {load:5.2f}")
    print(f"reproduce / run: {best['tapmp reproduce'][0] / best['tapmp run'][0]:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
