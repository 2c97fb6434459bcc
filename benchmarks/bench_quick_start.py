"""Time of the quick start's build on this machine, as a new user meets it. Run from the
repository root after `pip install -e .`:

    .venv/bin/python benchmarks/bench_quick_start.py [--all-platforms] [--warm-only]

Runs the build of the README's first command, `bash build_fmus.sh --host` (with --all-platforms:
`bash build_fmus.sh`, every platform), into a temporary folder, twice:
  * cold: Zig's cache (ZIG_GLOBAL_CACHE_DIR) and tapmp's compiled-code cache (TAPMP_CACHE) empty,
          as on a machine that never built: Zig builds each target's C runtime;
  * warm: again, with the caches the cold run filled (the build of every later quick start).
--warm-only skips the cold run and uses this machine's caches. Prints the wall time of each and
the load average (1 min) before and after, since the machine may be shared.
"""

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def load() -> float:
    """The 1-minute load average."""
    return os.getloadavg()[0]


def build(out: Path, env: dict, all_platforms: bool) -> float:
    """Wall time [s] of one `bash build_fmus.sh` into ``out``; SystemExit with its output if it fails."""
    cmd = ["bash", str(ROOT / "build_fmus.sh"), *([] if all_platforms else ["--host"]), str(out)]
    start = time.perf_counter()
    res = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True)
    took = time.perf_counter() - start
    if res.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed:\n{res.stdout[-2000:]}{res.stderr[-2000:]}")
    return took


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--all-platforms", action="store_true", help="every platform (bash build_fmus.sh)")
    p.add_argument("--warm-only", action="store_true", help="no cold run: this machine's caches as they are")
    args = p.parse_args(argv)
    what = "bash build_fmus.sh" + ("" if args.all_platforms else " --host")
    print(f"{what} on {os.cpu_count()} cores")
    print(f"{'cache':<6}  {'time [s]':>8}  {'load before':>11}  {'load after':>10}")
    with tempfile.TemporaryDirectory(prefix="bench_quick_start_") as tmp:
        env = {k: v for k, v in os.environ.items() if k != "ZIG_LOCAL_CACHE_DIR"}
        runs = ["warm"]
        if not args.warm_only:
            env.update(ZIG_GLOBAL_CACHE_DIR=str(Path(tmp) / "zig"), TAPMP_CACHE=str(Path(tmp) / "tapmp"))
            runs = ["cold", "warm"]
        for i, run in enumerate(runs):
            before = load()
            took = build(Path(tmp) / f"fmus{i}", env, args.all_platforms)
            print(f"{run:<6}  {took:>8.1f}  {before:>11.2f}  {load():>10.2f}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
