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

Abnormal ends leave no half state: SIGINT, SIGTERM and SIGHUP end a run at the next
step boundary (run.json: status "interrupted", the signal's name, exit code 128 +
its number); a failed write (e.g. a full disk) ends it with ResultsWriteError, and
results.csv, written in whole blocks of rows, is cut back to its last whole block.
"""

import csv
import fcntl
import io
import json
import os
import platform
import signal
import tempfile
import threading
import time
from contextlib import contextmanager
from importlib import metadata
from pathlib import Path

import numpy as np

from . import metrics
from ..engine.master import CoSimulation
from .scenario import Scenario

BLOCK = 1000  # steps between writes of results.csv and metric updates
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)  # end a run at a step boundary


LOCK_FILE = ".tapmp.lock"  # in every output folder while a tapmp writer holds it
_HELD = set()  # (real path, thread id) of the folders this process has locked: re-entrant per thread


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
    if key in _HELD:  # this thread holds it already (e.g. a study, then its run)
        yield folder
        return
    if any(path == key[0] for path, _ in list(_HELD)):
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
        _HELD.add(key)
        try:
            yield folder
        finally:
            _HELD.discard(key)
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


class Interrupted(KeyboardInterrupt):
    """A run or command stopped by a signal (SIGINT, SIGTERM, SIGHUP) at a step boundary;
    ``exit_code`` = 128 + the signal's number, as a shell reports a process the signal ended."""

    def __init__(self, signum: int, message: str = ""):
        self.signum = int(signum)
        self.signal_name = signal.Signals(self.signum).name
        self.exit_code = 128 + self.signum
        super().__init__(message or f"interrupted by {self.signal_name}")


class ResultsWriteError(RuntimeError):
    """A result file could not be written (e.g. the disk is full); the message names it."""


class _StopRequest:
    """Set by a stop signal or request_stop; the run loop stops at the next step boundary
    (never inside an FMU call: an exception there would turn into a failed FMI call)."""

    def __init__(self):
        self.signal = None   # the signal number that asked to stop
        self.reason = ""     # why, if not a signal to this process
        self.handled = False  # the run loop has acted on it

    def __call__(self, signum, frame):
        if self.signal is None:
            self.signal = signum

    def check(self, t: float) -> None:
        """Raise Interrupted if a stop was asked for; ``t`` is the current time [s]."""
        if self.signal is not None:
            self.handled = True
            name = signal.Signals(self.signal).name
            raise Interrupted(self.signal, f"interrupted by {name}{self.reason} at t = {t:.6g} s")


_stop_lock = threading.Lock()
_STOPPED = {}  # stop token -> signal number, for runs of a stopped study (in a worker process)
_ACTIVE = {}   # stop token -> the _StopRequest of every run of this process started with it


def request_stop(token: str, signum: int = signal.SIGTERM) -> None:
    """Stop every run of this process started with ``stop_token=token`` at its next step
    boundary, and any that starts later: a study's client calls this on every worker when
    it is stopped, so the cases end cleanly (FMUs freed, temporary folders removed)."""
    with _stop_lock:
        _STOPPED[token] = int(signum)
        for stop in _ACTIVE.get(token, ()):
            stop.reason = " (the study was stopped)"
            stop(signum, None)


def stop_requested(token: str | None) -> bool:
    """Whether request_stop(token) was called in this process."""
    return token is not None and token in _STOPPED


@contextmanager
def _stops(stop: _StopRequest, token: str | None):
    """Route SIGINT, SIGTERM and SIGHUP (main thread only) and request_stop(token) to ``stop``
    for the duration. A signal that came after the run loop's last check is delivered again
    to the previous handler on the way out, so it is never lost."""
    with _stop_lock:
        if token is not None:
            _ACTIVE.setdefault(token, []).append(stop)
            if token in _STOPPED:
                stop.reason = " (the study was stopped)"
                stop(_STOPPED[token], None)
    main = threading.current_thread() is threading.main_thread()
    previous = {s: signal.signal(s, stop) for s in STOP_SIGNALS} if main else {}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, signal.SIG_DFL if handler is None else handler)
        with _stop_lock:
            if token is not None:
                _ACTIVE[token].remove(stop)
                if not _ACTIVE[token]:
                    del _ACTIVE[token]
        if stop.signal in previous and not stop.handled and not stop.reason:
            signal.raise_signal(stop.signal)


def run_scenario(scenario: Scenario, ssp: Path, out: Path, overwrite: bool = False,
                 progress=None, stop_token: str | None = None) -> dict:
    """Run one scenario; write results.csv, run.json, metrics.json into ``out``.

    ``progress(n_done, n_total)`` is called every BLOCK steps. Returns the metrics,
    computed from every step (results.csv keeps every ``scenario.record_every``-th
    step and the last). The output folder is locked for the whole run (OutputInUseError
    if another writer has it).

    SIGINT, SIGTERM and SIGHUP (and request_stop(stop_token)) end the run at the next
    step boundary with Interrupted. On any failure the whole rows so far stay in
    results.csv, run.json records the status, exit code and reason (if it can be
    written) and the error is raised again: CoSimulationError, Interrupted, or
    ResultsWriteError if a result file cannot be written (results.csv is then cut back
    to its last whole block of rows).
    """
    with output_lock(out):
        out = prepare_output(out, overwrite)
        return _run_locked(scenario, ssp, out, progress, stop_token)


def _write_result(path: Path, data) -> None:
    """write_json, with an OSError (e.g. a full disk) as ResultsWriteError naming the file."""
    try:
        write_json(path, data)
    except OSError as err:
        raise ResultsWriteError(f"cannot write {path}: {err.strerror or err} (errno {err.errno})") from err


def _run_locked(scenario: Scenario, ssp: Path, out: Path, progress, stop_token) -> dict:
    """run_scenario's body, in the locked and prepared output folder ``out``."""
    info = {"scenario": scenario.to_dict(), "ssp": str(ssp), "step": scenario.step,
            "ordering": scenario.ordering, "record_every": scenario.record_every,
            "clock": scenario.clock, "connection_start": scenario.connection_start,
            "versions": versions(), "status": "running"}
    _write_result(out / "run.json", info)
    start = time.perf_counter()
    stop = _StopRequest()
    sim = None
    with _stops(stop, stop_token):  # a signal after the last check is raised after the run
        try:
            stop.check(scenario.start_time)
            with CoSimulation(ssp, scenario.parameters(), scenario.start_time, scenario.step,
                              scenario.ordering, limits=scenario.limit_values(), clock=scenario.clock,
                              connection_start=scenario.connection_start,
                              open_inputs=scenario.open_inputs, order=scenario.order) as sim:
                info["guids"] = sim.guids
                stats = _simulate(sim, scenario, out / "results.csv", stop, progress)
            result = stats.result()
            _write_result(out / "metrics.json", result)
            wall = time.perf_counter() - start
            info.update(status="completed", exit_code=0, wall_time_s=wall,
                        real_time_factor=wall / (scenario.stop_time - scenario.start_time))
            _write_result(out / "run.json", info)
        except BaseException as err:
            _record_failure(out / "run.json", info, err, sim, start)
            raise
    return result


def _simulate(sim: CoSimulation, scenario: Scenario, path: Path, stop: _StopRequest, progress):
    """The step loop: results.csv in whole blocks, metrics over every step; returns the
    metrics.ErrorStatistics. Stops at a step boundary when ``stop`` is set."""
    n, every = scenario.n_steps, scenario.record_every
    csv_file = _CsvBlocks(path)
    try:
        row = sim.row()
        csv_file.add(sim.columns, None)
        csv_file.add(row, row[0])
        stats = metrics.ErrorStatistics(sim.columns)
        block = [row]
        for k in range(1, n + 1):
            if stop.signal is not None:
                stop.check(sim.time)
            sim.step()
            row = sim.row()
            block.append(row)
            if k % every == 0 or k == n:
                csv_file.add(row, row[0])
            if len(block) == BLOCK:
                stats.add(block)
                block = []
                csv_file.flush()
                if progress:
                    progress(k, n)
        stop.check(sim.time)
        csv_file.flush()
        stats.add(block)
        if progress:
            progress(n, n)
        return stats
    except ResultsWriteError:
        raise
    except BaseException:
        csv_file.flush(quiet=True)  # the whole rows so far stay
        raise
    finally:
        csv_file.close()


class _CsvBlocks:
    """results.csv written in whole blocks of rows (one write per block); after a failed
    write (e.g. a full disk) the file is cut back to the end of its last whole block."""

    def __init__(self, path: Path):
        self.path = Path(path)
        try:
            self.fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_CLOEXEC, 0o644)
        except OSError as err:
            raise ResultsWriteError(f"cannot write {self.path}: {err.strerror or err} (errno {err.errno})") from err
        self.buffer = io.StringIO(newline="")
        self.writer = csv.writer(self.buffer)
        self.size = 0            # bytes of whole blocks on disk
        self.last_time = None    # time [s] of the last row on disk
        self.pending_time = None  # time [s] of the last row in the buffer

    def add(self, row, t: float | None) -> None:
        """Buffer one row (the header with t = None)."""
        self.writer.writerow(row)
        if t is not None:
            self.pending_time = t

    def flush(self, quiet: bool = False) -> None:
        """Write the buffered rows as one block; ResultsWriteError (unless ``quiet``) if it fails."""
        data = self.buffer.getvalue().encode()
        self.buffer.seek(0)
        self.buffer.truncate()
        if not data:
            return
        try:
            view = memoryview(data)
            while view:
                view = view[os.write(self.fd, view):]
        except OSError as err:
            try:
                os.ftruncate(self.fd, self.size)  # whole rows only
            except OSError:
                pass
            if quiet:
                return
            kept = (f"the rows up to t = {self.last_time:.6g} s" if self.last_time is not None
                    else "no rows")
            raise ResultsWriteError(f"cannot write {self.path}: {err.strerror or err} (errno {err.errno}): "
                                    f"it keeps {kept}, whole rows only") from err
        self.size += len(data)
        self.last_time = self.pending_time

    def close(self) -> None:
        os.close(self.fd)


def _record_failure(path: Path, info: dict, err: BaseException, sim, start: float) -> None:
    """Record a failed or interrupted run in run.json, if it can be written."""
    interrupted = isinstance(err, KeyboardInterrupt)
    info.update(status="interrupted" if interrupted else "failed",
                exit_code=getattr(err, "exit_code", 130 if interrupted else 2), error=one_line(err),
                wall_time_s=time.perf_counter() - start,
                failed_at_s=getattr(err, "time", sim.time if sim is not None else None))
    if interrupted:
        info["signal"] = getattr(err, "signal_name", "SIGINT")
    for key in ("element", "signal", "value"):
        if not interrupted and getattr(err, key, None) is not None:
            info[f"failed_{key}"] = getattr(err, key)
    try:
        write_json(path, info)
    except OSError:
        pass  # e.g. still a full disk: the error itself is raised all the same


def read_results(folder: Path) -> tuple[list[str], np.ndarray]:
    """Columns and data of a results.csv."""
    path = Path(folder) / "results.csv"
    with open(path) as f:
        columns = next(csv.reader(f))
    return columns, np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
