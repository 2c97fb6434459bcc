"""Study throughput at scale on the local cluster `tapmp study --workers N` starts (a Dask
LocalCluster: the scheduler in this process, N single-threaded worker processes under nannies):
many short cases and many paper cases, in batches (orchestrator.studies.batches). Not part of
the tests; smoke-run by tests/project/test_benchmarks.py.

Usage (from the repository root, after bash build_fmus.sh --host or tapmp build):

    .venv/bin/python benchmarks/bench_study_scale.py [--workers 2] [--short 10000] [--paper 1000]
                                                     [--short-stop 0.05] [--paper-stop 0.5] [--ssp FILE]
                                                     [--batch-size 0] [--remote]

For each study (a grid of the paper scenario over gain_overrides.D, every case completing) it warms
the workers up (one small study, not timed), runs the cases with run_study (as `tapmp study`
does) into a temporary folder and prints one row: cases, wall time (first submission to the last
row; the study's figures are not timed), cases/s, the batch size used, and the CPU per case [ms]
of the client listing and validating the cases before the run (study.cases), of the client's
thread running them (submitting, collecting, writing study.csv), of the whole client process
meanwhile (with the LocalCluster's scheduler and Dask's event loop) and of the workers (with
their nannies), with the load average before. Then the client process's CPU as a share of one
core, and the estimate for 50 workers from the per-case costs: 50 workers, each a core of its own,
give 50 / (workers' CPU per case) cases/s; the client's thread that runs the cases gives at most
1 / (its CPU per case); the estimate is the smaller.
"""

import argparse
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))  # --remote: throughput.py's loopback cluster
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as every tapmp command (cli.single_threaded_blas)

from orchestrator.builder.families import DEFAULT_FAMILY, resolve_ssp  # noqa: E402
from orchestrator.studies.run import run_study  # noqa: E402
from orchestrator.studies.study import cases as case_list  # noqa: E402
from orchestrator.studies.study import close_client, load_study, open_client  # noqa: E402


def process_cpu() -> float:
    """User + system CPU [s] of this process (every thread: the scheduler's too)."""
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def workers_cpu(client) -> float:
    """User + system CPU [s] of every worker process and its nanny."""
    import psutil  # a dependency of dask.distributed
    total = 0.0
    for pid in client.run(os.getpid).values():
        try:
            proc = psutil.Process(pid)
            procs = [proc, proc.parent()]  # the worker and its nanny
        except psutil.NoSuchProcess:
            continue
        for p in procs:
            t = p.cpu_times()
            total += t.user + t.system
    return total


def study_file(folder: Path, name: str, n: int, stop_time: float) -> Path:
    """A grid study of ``n`` cases of ``stop_time`` [s] on the paper scenario (D from 400 to 1399 N s/m...)."""
    values = ", ".join(f"{400.0 + 1000.0 * i / n:.6f}" for i in range(n))
    path = folder / f"{name}.toml"
    path.write_text(f'[study]\nname = "{name}"\nbase = "{ROOT / "scenarios" / "paper_simulation.toml"}"\n'
                    f'output = "{folder / name}"\n[set]\nstop_time = {stop_time}\n'
                    f'[grid]\n"gain_overrides.D" = [{values}]\n')
    return path


def measure(client, ssp: Path, folder: Path, name: str, n: int, stop_time: float, batch_size: int,
            remote: dict | None = None) -> dict:
    """One study of ``n`` cases of ``stop_time`` [s] (on the scheduler ``remote``, as run_study
    takes it, if given): its row's numbers."""
    study = load_study(study_file(folder, name, n, stop_time))
    load = os.getloadavg()[0]
    w0, t0 = workers_cpu(client), time.thread_time()
    cases = case_list(study)  # as `tapmp study` lists and validates them before a cluster starts
    t1 = time.thread_time()
    summary = run_study(study, ssp, client, folder / name, progress=False, batch_size=batch_size, case_list=cases,
                        remote=remote)
    w1 = workers_cpu(client)
    done = summary["counts"]["completed"]
    if done != n:
        raise SystemExit(f"{name}: {done} of {n} cases completed: {summary['counts']}")
    wall = summary["wall_time_s"]  # first submission to the last row
    return {"name": name, "cases": n, "stop": stop_time, "wall": wall, "rate": n / wall,
            "batch": summary["batch_size"], "list_ms": 1e3 * (t1 - t0) / n,
            "main_ms": 1e3 * summary["client_cpu_s"] / n, "process_ms": 1e3 * summary["client_process_cpu_s"] / n,
            "worker_ms": 1e3 * (w1 - w0) / n, "load": load}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--short", type=int, default=10_000, help="short cases (default 10000)")
    p.add_argument("--paper", type=int, default=1_000, help="paper cases (default 1000)")
    p.add_argument("--short-stop", type=float, default=0.05, help="stop time of a short case [s]")
    p.add_argument("--paper-stop", type=float, default=0.5, help="stop time of a paper case [s]")
    p.add_argument("--batch-size", type=int, default=0, help="cases per task (default 0: the automatic size)")
    p.add_argument("--ssp", help="SSP file (default: the built SSP of the native family)")
    p.add_argument("--remote", action="store_true", help="a loopback `dask scheduler` and `dask worker` processes "
                   "instead (benchmarks/throughput.py's), the SSP and case files travelling as data, as with "
                   "tapmp study --scheduler")
    args = p.parse_args()
    ssp = resolve_ssp(args.ssp, DEFAULT_FAMILY)
    if not ssp.exists():
        print(f"error: {ssp} does not exist: run `bash build_fmus.sh --host` first", file=sys.stderr)
        return 2
    kind = ("loopback scheduler and dask worker processes, data mode" if args.remote
            else "LocalCluster")
    print(f"{ssp.relative_to(ROOT) if ssp.is_relative_to(ROOT) else ssp}, {os.cpu_count()} cores, {kind} "
          f"of {args.workers} workers")
    rows = []
    with tempfile.TemporaryDirectory(prefix="tapmp_scale_") as tmp:
        cluster, remote = None, None
        if args.remote:
            from dask.distributed import Client
            from throughput import LoopbackCluster
            cluster = LoopbackCluster(args.workers, Path(tmp))
            remote = {"address": cluster.address, "data": True, "timeout": 60.0}
            client = Client(cluster.address, timeout=60)
        else:
            client = open_client(workers=args.workers)
        try:
            client.wait_for_workers(args.workers, timeout=120)
            # imports, the SSP sent, FMUs loaded: not timed
            measure(client, ssp, Path(tmp), "warm", 4 * args.workers, 0.01, 1, remote)
            for name, n, stop in (("short", args.short, args.short_stop), ("paper", args.paper, args.paper_stop)):
                if n:
                    rows.append(measure(client, ssp, Path(tmp), name, n, stop, args.batch_size, remote))
        finally:
            close_client(client)
            if cluster is not None:
                cluster.stop()
    print("| study | cases | stop time [s] | wall [s] | cases/s | batch size | client, listing [ms/case] "
          "| client, running: main thread [ms/case] | client process [ms/case] | workers [ms/case] | load average |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['name']} | {r['cases']} | {r['stop']:g} | {r['wall']:.1f} | {r['rate']:.1f} | {r['batch']} "
              f"| {r['list_ms']:.2f} | {r['main_ms']:.2f} | {r['process_ms']:.2f} | {r['worker_ms']:.1f} "
              f"| {r['load']:.2f} |")
    print()
    print("| study | client process [% of a core] | workers' limit, 50 workers [cases/s] | client's limit "
          "[cases/s] | estimate, 50 workers [cases/s] | limited by |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        busy = r["process_ms"] * r["rate"] / 10.0  # [ms/case] x [cases/s] / 1000 x 100 %
        workers_limit = 50 * 1e3 / r["worker_ms"]  # each worker a core of its own, as fast as here per case
        client_limit = 1e3 / r["main_ms"]  # the thread that submits, collects and writes: one case after another
        print(f"| {r['name']} | {busy:.1f} | {workers_limit:.0f} | {client_limit:.0f} "
              f"| {min(workers_limit, client_limit):.0f} "
              f"| {'the workers' if workers_limit < client_limit else 'the client'} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
