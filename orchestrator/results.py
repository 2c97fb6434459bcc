"""Run a scenario through the master algorithm and write its result folder.

A result folder holds results.csv (streamed while the run goes), run.json (the
resolved scenario, FMU GUIDs, versions, step, ordering, wall time, status, exit code
and the reason of a failure) and metrics.json. JSON files are written atomically
(a uniquely named temporary file in the same folder, then os.replace). Memory stays
bounded: rows go to disk and into the streaming metrics in blocks of BLOCK steps,
whatever the simulated time.

One writer per output folder: a run holds an exclusive lock (fcntl.flock on
OUT/.tapmp.lock, which records the holder's pid) from before it looks at the folder
until its last file is written; a second writer is refused (OutputInUseError), also
with overwrite. The lock is re-entrant within one thread (a command may lock a folder
and then run into it) and released by the kernel if the process dies.
"""

import csv
import fcntl
import json
import os
import tempfile
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


LOCK_FILE = ".tapmp.lock"  # in every output folder while a tapmp writer holds it
_HELD = {}  # (real path of a locked folder, thread id) -> [fd, depth]: re-entrant per thread


class OutputExistsError(RuntimeError):
    """The output folder already holds results and overwriting was not asked for."""


class OutputInUseError(RuntimeError):
    """Another tapmp process (or thread) is writing into the output folder."""


def write_json(path: Path, data) -> None:
    """Write JSON atomically: a reader sees the old file or the whole new one. The
    temporary file has a unique name in the same folder and is removed on failure."""
    path = Path(path)
    text = json.dumps(data, indent=2, default=str) + "\n"
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as f:
            os.fchmod(f.fileno(), 0o644)  # mkstemp makes 0600; results are for everyone to read
            f.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def one_line(err) -> str:
    """The text of an error on one line (an FMU's log message may hold line breaks)."""
    return " ".join(str(err).splitlines()) or type(err).__name__


def _lock_holder(fd: int) -> str:
    """The pid recorded in a lock file held by someone else ("unknown" if not yet written)."""
    for _ in range(20):  # the holder writes its pid right after taking the lock
        text = os.pread(fd, 32, 0).decode(errors="replace").strip()
        if text:
            return text
        time.sleep(0.05)
    return "unknown"


@contextmanager
def output_lock(folder):
    """Hold the exclusive lock of the output folder ``folder`` (created if missing) for the
    duration; OutputInUseError names the holder's pid if another writer holds it."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    key = (os.path.realpath(folder), threading.get_ident())
    if key in _HELD:  # this thread holds it already
        _HELD[key][1] += 1
        try:
            yield folder
        finally:
            _HELD[key][1] -= 1
        return
    if any(path == key[0] for path, _ in _HELD):
        raise OutputInUseError(f"output folder {folder} is in use by another thread of this process "
                               f"(pid {os.getpid()}): allowed is one writer per output folder")
    fd = os.open(folder / LOCK_FILE, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise OutputInUseError(f"output folder {folder} is in use by tapmp (pid {_lock_holder(fd)}): "
                                   "allowed is one writer per output folder; wait for it to end or choose "
                                   "another --out") from None
        try:
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        except OSError:
            pass  # a full disk: the lock holds all the same, only the pid is not on record
        _HELD[key] = [fd, 1]
        try:
            yield folder
        finally:
            del _HELD[key]
            try:
                os.ftruncate(fd, 0)  # no stale pid on record once released
            except OSError:
                pass
    finally:
        os.close(fd)  # releases the lock


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
    """Create the output folder; refuse one that holds results unless overwrite.
    Call it holding the folder's output_lock."""
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
    error is raised again (CoSimulationError, or KeyboardInterrupt after SIGINT). The
    output folder is locked for the whole run (OutputInUseError if another writer has it).
    """
    with output_lock(out):
        return _run_locked(scenario, ssp, prepare_output(out, overwrite), progress)


def _run_locked(scenario: Scenario, ssp: Path, out: Path, progress) -> dict:
    """run_scenario's body, in the locked and prepared output folder ``out``."""
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
        info.update(status=status, exit_code=EXIT_CODES[status], error=one_line(err),
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
