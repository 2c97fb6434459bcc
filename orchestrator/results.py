"""Run a scenario through the master algorithm and write its result folder.

A result folder holds results.csv (streamed while the run goes), run.json (the
resolved scenario, FMU GUIDs, versions, step, ordering, wall time, status, exit code
and the reason of a failure) and metrics.json. JSON files are written atomically
(temporary file + rename). Memory stays bounded: rows go to disk and into the
streaming metrics in blocks of BLOCK steps, whatever the simulated time.
"""

import csv
import json
import os
import platform
import signal
import threading
import time
from contextlib import contextmanager
from importlib import metadata
from pathlib import Path

import numpy as np

from . import metrics
from .master import CoSimulation
from .scenario import Scenario

BLOCK = 1000  # steps between flushes of results.csv and metric updates
EXIT_CODES = {"completed": 0, "failed": 2, "interrupted": 130}  # as the `tapmp` command exits


class OutputExistsError(RuntimeError):
    """The output folder already holds results and overwriting was not asked for."""


def write_json(path: Path, data) -> None:
    """Write JSON atomically: a reader sees the old file or the whole new one."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(data, indent=2, default=str) + "\n")
    os.replace(tmp, path)


def versions() -> dict:
    """Versions of the packages a result depends on."""
    out = {"python": platform.python_version()}
    for pkg in ("tapmp-cosim", "fmpy", "pythonfmu", "numpy"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = None
    return out


def prepare_output(out: Path, overwrite: bool) -> Path:
    """Create the output folder; refuse one that holds results unless overwrite."""
    out = Path(out)
    if out.exists() and any((out / f).exists() for f in ("results.csv", "run.json", "metrics.json")):
        if not overwrite:
            raise OutputExistsError(f"output folder {out} already holds results: "
                                    "choose another with --out or pass --overwrite")
        for f in ("results.csv", "run.json", "metrics.json"):
            (out / f).unlink(missing_ok=True)
    out.mkdir(parents=True, exist_ok=True)
    return out


class _StopRequest:
    """Set by SIGINT; the run loop stops at the next step boundary (never inside an FMU)."""

    def __init__(self):
        self.signal = None

    def __call__(self, signum, frame):
        self.signal = signum


@contextmanager
def _sigint_stops(stop: _StopRequest):
    """Route SIGINT to ``stop`` for the duration (main thread only; elsewhere a no-op).

    A plain KeyboardInterrupt could be raised inside an FMU's Python code, which would
    turn it into a failed FMI call; a flag checked between steps ends the run cleanly.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, stop)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def run_scenario(scenario: Scenario, ssp: Path, out: Path, overwrite: bool = False,
                 progress=None) -> dict:
    """Run one scenario; write results.csv, run.json, metrics.json into ``out``.

    ``progress(n_done, n_total)`` is called every BLOCK steps. Returns the metrics,
    computed from every step (results.csv keeps every ``scenario.record_every``-th
    step and the last). On a failure the rows so far stay in results.csv (flushed, so
    it is valid CSV), run.json records the status, exit code and reason, and the
    error is raised again (CoSimulationError, or KeyboardInterrupt after SIGINT).
    """
    out = prepare_output(out, overwrite)
    info = {"scenario": scenario.to_dict(), "ssp": str(ssp), "step": scenario.step,
            "ordering": scenario.ordering, "record_every": scenario.record_every,
            "clock": scenario.clock, "connection_start": scenario.connection_start,
            "versions": versions(), "status": "running"}
    write_json(out / "run.json", info)
    n, every = scenario.n_steps, scenario.record_every
    start = time.perf_counter()
    stop = _StopRequest()
    sim = None
    try:
        with _sigint_stops(stop), \
                CoSimulation(ssp, scenario.parameters(), scenario.start_time, scenario.step,
                             scenario.ordering, limits=scenario.limit_values(), clock=scenario.clock,
                             connection_start=scenario.connection_start,
                             open_inputs=scenario.open_inputs) as sim, \
                open(out / "results.csv", "w", newline="") as f:
            info["guids"] = sim.guids
            writer = csv.writer(f)
            writer.writerow(sim.columns)
            stats = metrics.ErrorStatistics(sim.columns)
            block = [sim.row()]
            writer.writerow(block[0])
            try:
                for k in range(1, n + 1):
                    sim.step()
                    row = sim.row()
                    block.append(row)
                    if k % every == 0 or k == n:
                        writer.writerow(row)
                    if len(block) == BLOCK:
                        stats.add(block)
                        block = []
                        f.flush()
                        if progress:
                            progress(k, n)
                    if stop.signal is not None:
                        raise KeyboardInterrupt(f"interrupted by SIGINT at t = {sim.time:.6g} s")
            finally:
                f.flush()
        stats.add(block)
        if progress:
            progress(n, n)
    except BaseException as err:
        status = "interrupted" if isinstance(err, KeyboardInterrupt) else "failed"
        info.update(status=status, exit_code=EXIT_CODES[status], error=str(err) or type(err).__name__,
                    wall_time_s=time.perf_counter() - start,
                    failed_at_s=getattr(err, "time", sim.time if sim is not None else None))
        for key in ("element", "signal", "value"):
            if getattr(err, key, None) is not None:
                info[f"failed_{key}"] = getattr(err, key)
        write_json(out / "run.json", info)
        raise
    info.update(status="completed", exit_code=0, wall_time_s=time.perf_counter() - start)
    result = stats.result()
    write_json(out / "metrics.json", result)
    info["real_time_factor"] = info["wall_time_s"] / (scenario.stop_time - scenario.start_time)
    write_json(out / "run.json", info)
    return result


def read_results(folder: Path) -> tuple[list[str], np.ndarray]:
    """Columns and data of a results.csv."""
    path = Path(folder) / "results.csv"
    with open(path) as f:
        columns = next(csv.reader(f))
    return columns, np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
