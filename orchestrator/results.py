"""Run a scenario through the master algorithm and write its result folder.

A result folder holds results.csv (streamed while the run goes), run.json (the
resolved scenario, FMU GUIDs, versions, step, ordering, wall time, exit status)
and metrics.json. JSON files are written atomically (temporary file + rename).
"""

import csv
import json
import os
import platform
import time
from importlib import metadata
from pathlib import Path

import numpy as np

from . import metrics
from .master import CoSimulation
from .scenario import Scenario

FLUSH_EVERY = 1000  # rows between flushes of results.csv


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


def run_scenario(scenario: Scenario, ssp: Path, out: Path, overwrite: bool = False,
                 progress=None) -> dict:
    """Run one scenario; write results.csv, run.json, metrics.json into ``out``.

    ``progress(n_done, n_total)`` is called now and then. Returns the metrics.
    On a failure the rows so far stay in results.csv, run.json records the reason,
    and CoSimulationError is raised.
    """
    out = prepare_output(out, overwrite)
    info = {"scenario": scenario.to_dict(), "ssp": str(ssp), "step": scenario.step,
            "ordering": scenario.ordering, "clock": scenario.clock,
            "connection_start": scenario.connection_start, "versions": versions(), "status": "running"}
    write_json(out / "run.json", info)
    n = scenario.n_steps
    start = time.perf_counter()
    columns = None
    try:
        with CoSimulation(ssp, scenario.parameters(), scenario.start_time, scenario.step,
                          scenario.ordering, clock=scenario.clock,
                          connection_start=scenario.connection_start) as sim, \
                open(out / "results.csv", "w", newline="") as f:
            info["guids"] = sim.guids
            columns = sim.columns
            writer = csv.writer(f)
            writer.writerow(columns)
            writer.writerow(sim.row())
            try:
                for k in range(n):
                    sim.step()
                    writer.writerow(sim.row())
                    if (k + 1) % FLUSH_EVERY == 0:
                        f.flush()
                        if progress:
                            progress(k + 1, n)
            finally:
                f.flush()
        if progress:
            progress(n, n)
    except BaseException as err:
        info.update(status="failed" if not isinstance(err, KeyboardInterrupt) else "interrupted",
                    error=str(err) or type(err).__name__, wall_time_s=time.perf_counter() - start,
                    failed_at_s=getattr(err, "time", None))
        write_json(out / "run.json", info)
        raise
    info.update(status="completed", wall_time_s=time.perf_counter() - start)
    data = np.loadtxt(out / "results.csv", delimiter=",", skiprows=1, ndmin=2)
    result = metrics.compute(columns, data)
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
