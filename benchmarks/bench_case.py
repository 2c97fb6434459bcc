"""A study worker's CPU per case, in one process: the benchmark study's cases through `run_case`
(as a Dask worker runs them, in data mode: each case in a temporary folder whose files are packed
for the client) with the worker's FMUs kept loaded and reset between cases, and the same cases
with the FMUs loaded for each case and freed after it (a cache of its own for each case, closed
after it). The two are interleaved case by case, so both see the same load (not part of the tests;
smoke-run by tests/project/test_benchmarks.py).

Usage (from the repository root, after `tapmp build` or bash build_fmus.sh):

    .venv/bin/python benchmarks/bench_case.py [--study benchmarks/bench_study.toml] [--fmus native]
                                              [--ssp FILE] [--cases 32] [--stop-time S] [--profile]

Prints a table: per mode, the cases run, the CPU [ms] per case of this process (every thread) and
the wall time [ms] per case, with the load average before the run. --profile then prints
cProfile's 25 most expensive calls (cumulative) of the cases on kept FMUs.
"""

import argparse
import dataclasses
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as every tapmp command (cli.single_threaded_blas)

from orchestrator.builder.families import DEFAULT_FAMILY, resolve_ssp  # noqa: E402
from orchestrator.engine import loaded  # noqa: E402
from orchestrator.studies.remote import case_folder, pack_folder, remove_case_folder  # noqa: E402
from orchestrator.studies.study import cases, load_study, run_case, scenario_data  # noqa: E402

MODES = ("kept loaded, reset", "loaded per case")


def data_mode_case(base: dict, changes: dict, ssp: Path) -> dict:
    """One case as a worker runs it in data mode: in a new temporary folder, its files packed
    for the client, the folder removed."""
    folder = case_folder()
    try:
        row = run_case(base, changes, str(ssp), str(folder / "case"))
        row["files"] = pack_folder(folder / "case")
    finally:
        remove_case_folder(folder)
    return row


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--study", default=str(ROOT / "benchmarks" / "bench_study.toml"))
    p.add_argument("--ssp", help="SSP file (default: the built SSP of --fmus)")
    p.add_argument("--fmus", default=DEFAULT_FAMILY, help=f"FMU family (default {DEFAULT_FAMILY})")
    p.add_argument("--cases", type=int, default=32, help="cases per mode (the study's cases, repeated)")
    p.add_argument("--stop-time", type=float, help="stop time of every case [s] (default: the study's)")
    p.add_argument("--profile", action="store_true", help="print cProfile's top calls of the kept mode")
    args = p.parse_args()
    ssp = resolve_ssp(args.ssp, args.fmus)
    if not Path(ssp).exists():
        print(f"error: {ssp} does not exist: run `tapmp build` first", file=sys.stderr)
        return 2
    if args.cases < 1:
        print(f"error: --cases = {args.cases} is invalid: allowed is an integer >= 1", file=sys.stderr)
        return 2
    study = load_study(Path(args.study))
    if args.stop_time:
        study = dataclasses.replace(study, set={**study.set, "stop_time": args.stop_time})
    base = scenario_data(study.base_scenario())
    changes = [c["changes"] for c in cases(study)]
    data_mode_case(base, changes[0], ssp)  # imports, the compiled libraries, first loads: not timed
    profile = None
    if args.profile:
        import cProfile
        profile = cProfile.Profile()
    cpu = {m: 0.0 for m in MODES}
    wall = {m: 0.0 for m in MODES}
    load = os.getloadavg()[0]
    for i in range(args.cases):
        for mode in MODES:
            c0, w0 = time.process_time(), time.perf_counter()
            if profile and mode == MODES[0]:
                profile.enable()
            if mode == MODES[1]:  # a cache of its own for this case, closed after it (the kept one stays)
                kept, loaded._PROCESS = loaded.process_fmus(), loaded.LoadedFMUs()
                try:
                    row = data_mode_case(base, changes[i % len(changes)], ssp)
                finally:
                    loaded._PROCESS.close()  # every instance freed and the extracted files removed
                    loaded._PROCESS = kept
            else:
                row = data_mode_case(base, changes[i % len(changes)], ssp)
            if profile and mode == MODES[0]:
                profile.disable()
            cpu[mode] += time.process_time() - c0
            wall[mode] += time.perf_counter() - w0
            if row["status"] != "completed":
                print(f"error: case {i} ({mode}): {row['status']}: {row['error']}", file=sys.stderr)
                return 1
    print(f"study {args.study}, SSP {ssp}, {args.cases} cases per mode, load average {load:.2f}")
    print(f"{'mode':<22}{'cases':>8}{'CPU/case [ms]':>16}{'wall/case [ms]':>17}")
    for mode in MODES:
        print(f"{mode:<22}{args.cases:>8}{1e3 * cpu[mode] / args.cases:>16.1f}{1e3 * wall[mode] / args.cases:>17.1f}")
    if profile:
        import pstats
        print()
        pstats.Stats(profile, stream=sys.stdout).sort_stats("cumulative").print_stats(25)
    return 0


if __name__ == "__main__":
    sys.exit(main())
