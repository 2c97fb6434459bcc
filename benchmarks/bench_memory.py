"""Peak memory of long runs: does it grow with the simulated time?

    .venv/bin/python benchmarks/bench_memory.py [--ssp build/TAPMP.ssp] [--times 6 60] [--json PATH]

Runs `tapmp run` on the paper scenario for 6 s and for 60 s of simulated time (600,000
macro steps; --times gives others), each in a fresh process, storing every 10th step (record_every = 10; the
metrics still use every step), and reports each process's peak resident memory
(ru_maxrss of the child), its wall time and the size of results.csv.
"""

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PAPER = ROOT / "scenarios" / "paper_simulation.toml"


def measure(stop_time: float, ssp: Path, out: Path) -> dict:
    """Peak RSS [MiB], wall time [s] and results.csv size [MB] of one `tapmp run`."""
    child = ("import resource, sys; from orchestrator.cli import main; rc = main(sys.argv[1:]); "
             "print('MAXRSS', resource.getrusage(resource.RUSAGE_SELF).ru_maxrss); sys.exit(rc)")
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", child, "run", str(PAPER), "--ssp", str(ssp), "--out", str(out),
                           "--set", f"stop_time={stop_time}", "--set", "record_every=10", "--no-progress"],
                          capture_output=True, text=True, cwd=ROOT)
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        raise SystemExit(f"run of {stop_time} s failed:\n{proc.stderr}")
    rss_kib = int(next(line.split()[1] for line in proc.stdout.splitlines() if line.startswith("MAXRSS")))
    return {"simulated_s": stop_time, "steps": int(round(stop_time / 1e-4)), "peak_rss_mib": rss_kib / 1024,
            "wall_s": wall, "results_csv_mb": (out / "results.csv").stat().st_size / 1e6}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--ssp", default=str(ROOT / "build" / "TAPMP.ssp"))
    ap.add_argument("--times", type=float, nargs=2, default=[6.0, 60.0], metavar=("SHORT", "LONG"),
                    help="simulated seconds of the two runs (default 6 60)")
    ap.add_argument("--json", default=str(ROOT / "benchmarks" / "results" / "memory.json"))
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="tapmp_mem_") as tmp:
        rows = [measure(t, Path(args.ssp), Path(tmp) / f"run{t:g}") for t in args.times]
    print(f"{'simulated s':>11s} {'steps':>8s} {'peak RSS MiB':>13s} {'wall s':>7s} {'csv MB':>7s}")
    for r in rows:
        print(f"{r['simulated_s']:11g} {r['steps']:8d} {r['peak_rss_mib']:13.1f} {r['wall_s']:7.1f} "
              f"{r['results_csv_mb']:7.1f}")
    growth = rows[1]["peak_rss_mib"] / rows[0]["peak_rss_mib"]
    print(f"peak memory {args.times[1]:g} s / {args.times[0]:g} s: {growth:.3f}")
    path = Path(args.json)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"runs": rows, "growth_long_over_short": growth, "record_every": 10}, indent=2) + "\n")
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
