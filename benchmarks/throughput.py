"""Study throughput on a real loopback Dask cluster: a `dask scheduler` process and `dask worker`
processes (one single-threaded worker each, under its nanny), with 1 and with 2 workers, the
client in this process sending the SSP and getting every case's files back as data (not part of
the tests; smoke-run by tests/project/test_benchmarks.py).

Usage (from the repository root, after `tapmp build` or bash build_fmus.sh):

    .venv/bin/python benchmarks/throughput.py [--study benchmarks/bench_study.toml] [--fmus native]
                                              [--ssp FILE] [--workers 1 2] [--stop-time S]

For each worker count it starts the scheduler and the workers, warms every worker up (imports,
the SSP written into its cache, one 10 ms case each; not timed), then runs the study's cases
(`run_study` with the scheduler's address, as `tapmp study --scheduler ADDRESS` does) into a
temporary folder and prints: cases per minute (first submission to last row written; the study's
figures, drawn afterwards, are not timed), the compressed bytes of case files received per case,
and the CPU seconds per case of the client (this process), the scheduler and the workers (each
process with its nanny), read from /proc before and after; with the load average of the machine
before the run. --stop-time shortens every case (the smoke run).
"""

import argparse
import dataclasses
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as every tapmp command (cli.single_threaded_blas)

from orchestrator.builder.families import DEFAULT_FAMILY, resolve_ssp  # noqa: E402
from orchestrator.studies.run import run_study  # noqa: E402
from orchestrator.studies.study import load_study, run_case, scenario_data  # noqa: E402

def cpu_seconds(pid: int) -> float:
    """User + system CPU [s] of process ``pid`` and of its descendants still running (a nanny's worker)."""
    import psutil  # a dependency of dask.distributed
    total = 0.0
    try:
        root = psutil.Process(pid)
        procs = [root, *root.children(recursive=True)]
    except psutil.NoSuchProcess:
        return total
    for proc in procs:
        try:
            t = proc.cpu_times()
        except psutil.NoSuchProcess:  # ended meanwhile
            continue
        total += t.user + t.system
    return total


def client_cpu() -> float:
    """User + system CPU [s] of this process (every thread of the client)."""
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


class LoopbackCluster:
    """`dask scheduler` on 127.0.0.1 (a free port) and one `dask worker` process per worker."""

    def __init__(self, n_workers: int, folder: Path):
        self.procs = []
        scheduler_file = folder / "scheduler.json"
        self.scheduler = self._start("scheduler", "--scheduler-file", str(scheduler_file), "--host", "127.0.0.1",
                                     "--port", "0", "--no-dashboard")
        while not (scheduler_file.exists() and scheduler_file.stat().st_size):
            if self.scheduler.poll() is not None:
                raise SystemExit(f"dask scheduler ended: {self.scheduler.stderr.read()}")
            time.sleep(0.1)
        self.address = json.loads(scheduler_file.read_text())["address"]
        self.workers = [self._start("worker", self.address, "--nworkers", "1", "--nthreads", "1", "--no-dashboard",
                                    "--local-directory", str(folder / f"worker{i}")) for i in range(n_workers)]

    def _start(self, *args) -> subprocess.Popen:
        proc = subprocess.Popen([sys.executable, "-m", "dask", *args], stdout=subprocess.DEVNULL,
                                stderr=subprocess.PIPE, text=True, start_new_session=True)
        self.procs.append(proc)
        return proc

    def cpu(self) -> tuple[float, float]:
        """(scheduler CPU [s], CPU of all worker processes with their nannies [s])."""
        return cpu_seconds(self.scheduler.pid), sum(cpu_seconds(w.pid) for w in self.workers)

    def stop(self) -> None:
        for proc in reversed(self.procs):
            if proc.poll() is None:
                proc.terminate()
        for proc in self.procs:
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def warm_up(client, study, ssp: Path, folder: Path) -> None:
    """One 10 ms case on every worker, so imports and first FMU loads are not timed."""
    base = scenario_data(study.base_scenario())
    workers = list(client.scheduler_info()["workers"])
    futures = [client.submit(run_case, base, {"stop_time": 0.01}, str(ssp), str(folder / f"warm{i}"),
                             workers=[w], pure=False) for i, w in enumerate(workers)]
    rows = client.gather(futures)
    assert all(r["status"] == "completed" for r in rows), rows


def measure(study_path: Path, ssp: Path, n_workers: int, stop_time: float | None) -> dict:
    """One study on a fresh loopback cluster of n_workers workers: wall time [s], cases, cases per
    minute, bytes received per case, CPU per case [s] of client, scheduler and workers, load average."""
    from dask.distributed import Client
    study = load_study(study_path)
    if stop_time:
        study = dataclasses.replace(study, set={**study.set, "stop_time": stop_time})
    with tempfile.TemporaryDirectory(prefix="tapmp_throughput_") as tmp:
        cluster = LoopbackCluster(n_workers, Path(tmp))
        try:
            client = Client(cluster.address, timeout=60)
            try:
                client.wait_for_workers(n_workers, timeout=120)
                warm_up(client, study, ssp, Path(tmp))
                load = os.getloadavg()[0]
                c0, (s0, w0) = client_cpu(), cluster.cpu()
                summary = run_study(study, ssp, client, Path(tmp) / "out", progress=False,
                                    remote={"address": cluster.address, "data": True, "timeout": 60.0})
                c1, (s1, w1) = client_cpu(), cluster.cpu()
            finally:
                client.close()
        finally:
            cluster.stop()
    done = summary["counts"]["completed"]
    wall = summary["wall_time_s"]  # first submission to the last row (the figures are not timed)
    n = max(summary["ran"], 1)
    return {"workers": n_workers, "wall_s": wall, "cases": done, "rate": 60.0 * done / wall,
            "bytes_per_case": summary["bytes_received"] / n, "client_s": (c1 - c0) / n,
            "scheduler_s": (s1 - s0) / n, "worker_s": (w1 - w0) / n, "load": load}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--study", default=str(ROOT / "benchmarks" / "bench_study.toml"))
    p.add_argument("--ssp", help="SSP file (default: the built SSP of --fmus)")
    p.add_argument("--fmus", default=DEFAULT_FAMILY, help=f"FMU family (default {DEFAULT_FAMILY})")
    p.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    p.add_argument("--stop-time", type=float, help="stop time of every case [s] (default: the study's)")
    args = p.parse_args()
    args.ssp = str(resolve_ssp(args.ssp, args.fmus))
    if not Path(args.ssp).exists():
        print(f"error: {args.ssp} does not exist: run `tapmp build` first", file=sys.stderr)
        return 2
    print(f"study {args.study}, {os.cpu_count()} cores, loopback cluster (dask scheduler + dask worker)")
    print("| workers | cases | wall [s] | cases/min | speedup | bytes received/case | CPU/case client [ms] "
          "| scheduler [ms] | worker [ms] | load average |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    first = None
    for n in args.workers:
        r = measure(Path(args.study), Path(args.ssp), n, args.stop_time)
        first = first or r["rate"]
        print(f"| {n} | {r['cases']} | {r['wall_s']:.1f} | {r['rate']:.1f} | x{r['rate'] / first:.2f} "
              f"| {r['bytes_per_case']:.0f} | {1e3 * r['client_s']:.1f} | {1e3 * r['scheduler_s']:.1f} "
              f"| {1e3 * r['worker_s']:.1f} | {r['load']:.2f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
