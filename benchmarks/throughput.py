"""Study throughput with 1 and with 2 Dask workers on the same study (not part of the tests).

Usage (from the repository root, after bash build_fmus.sh):

    .venv/bin/python benchmarks/throughput.py [--study benchmarks/bench_study.toml] [--fmus native]
                                              [--ssp FILE] [--workers 1 2] [--repeat 1]

For each worker count it starts a LocalCluster (processes, one thread each), warms every
worker up (imports, one short case each, not timed), then times the cases of `run_study`
(first submission to last row written; the figures drawn afterwards are not timed) over all
cases of the study into a temporary folder and prints cases per minute and the speedup
over the first worker count.
"""

import argparse
import os
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from orchestrator.engine.families import DEFAULT_FAMILY, resolve_ssp  # noqa: E402
from orchestrator.studies.run import run_study  # noqa: E402
from orchestrator.studies.study import (close_client, load_study, open_client, read_study_csv,  # noqa: E402
                                        run_case, scenario_data)


def warm_up(client, study, ssp: Path, folder: Path) -> None:
    """One 10 ms case on every worker, so imports and first FMU loads are not timed."""
    base = scenario_data(study.base_scenario())
    workers = list(client.scheduler_info()["workers"])
    futures = [client.submit(run_case, base, {"stop_time": 0.01}, str(ssp), str(folder / f"warm{i}"),
                             workers=[w], pure=False) for i, w in enumerate(workers)]
    rows = client.gather(futures)
    assert all(r["status"] == "completed" for r in rows), rows


def measure(study_path: Path, ssp: Path, n_workers: int) -> tuple:
    """(wall time [s], completed cases, cases per minute, mean wall time of a case [s], load average
    of the machine before the run) of the study on n_workers workers."""
    study = load_study(study_path)
    client = open_client(workers=n_workers)
    try:
        client.wait_for_workers(n_workers)
        with tempfile.TemporaryDirectory() as tmp:
            warm_up(client, study, ssp, Path(tmp))
            load = os.getloadavg()[0]
            summary = run_study(study, ssp, client, Path(tmp) / "out", progress=False)
            wall = summary["wall_time_s"]  # from the first submission to the last row (figures not timed)
            rows = read_study_csv(Path(tmp) / "out" / "study.csv")
    finally:
        close_client(client)
    done = summary["counts"]["completed"]
    case_wall = sum(r["wall_time_s"] for r in rows) / len(rows)
    return wall, done, 60.0 * done / wall, case_wall, load


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--study", default=str(ROOT / "benchmarks" / "bench_study.toml"))
    p.add_argument("--ssp", help="SSP file (default: the built SSP of --fmus)")
    p.add_argument("--fmus", default=DEFAULT_FAMILY, help=f"FMU family (default {DEFAULT_FAMILY})")
    p.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    p.add_argument("--repeat", type=int, default=1, help="runs per worker count; the best is kept")
    args = p.parse_args()
    args.ssp = str(resolve_ssp(args.ssp, args.fmus))
    if not Path(args.ssp).exists():
        print(f"error: {args.ssp} does not exist: run bash build_fmus.sh first", file=sys.stderr)
        return 2
    print(f"study {args.study}, {os.cpu_count()} cores")
    first = None
    for n in args.workers:
        best = min((measure(Path(args.study), Path(args.ssp), n) for _ in range(args.repeat)), key=lambda r: r[0])
        wall, done, rate, case_wall, load = best
        first = first or rate
        print(f"{n} worker(s): {done} cases in {wall:.1f} s = {rate:.1f} cases/min, speedup x{rate / first:.2f} "
              f"(a case takes {case_wall:.3f} s on its worker; load average before the run {load:.2f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
