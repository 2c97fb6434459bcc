"""Run a scenario through the master algorithm and write its result folder.

A run folder holds run.json (kind "run": the resolved scenario, FMU GUIDs, columns,
versions, step, ordering, format, wall time, status, exit code and the reason of a
failure), metrics.json and the rows in one of two formats (scenario key ``format``,
``--format``): results.csv (text, every value as the shortest text that reads back to it)
or results.mat (MATLAB 5 MAT-file: one N x 1 double variable per column, names with
"." as "_", plus ``columns``, the original names in order). A comparison folder holds
comparison.json (kind "comparison") and one run folder per compared law.

JSON files are written atomically (a uniquely named temporary file in the same folder,
then os.replace). Memory stays bounded: rows go to disk and into the streaming metrics
in blocks of BLOCK steps, whatever the simulated time; a block is formatted in one
operation (one %-format of the whole block for CSV, raw float64 bytes for MAT).

One writer per output folder: a run holds an exclusive lock (fcntl.flock on
OUT/.tapmp.lock, which records the holder's pid) from before it looks at the folder
until its last file is written; a second writer is refused (OutputInUseError), also
with overwrite. The lock is re-entrant within one thread (a command may lock a folder
and then run into it) and released by the kernel if the process dies. A folder whose
run completed is never reused without overwrite; one whose run failed, was interrupted
or never finished is (its old files are removed first); a folder of the other kind
(run / comparison) is refused even with overwrite.

Abnormal ends leave no half state: SIGINT, SIGTERM and SIGHUP end a run at the next
step boundary (run.json: status "interrupted", the signal's name, exit code 128 +
its number); a failed write (e.g. a full disk) ends it with ResultsWriteError, and
results.csv, written in whole blocks of rows, is cut back to its last whole block.
A MAT run streams its blocks into results.part.npy (a valid .npy file whose header is
updated after every whole block) and writes results.mat from it atomically when the
run ends for any reason Python sees; only a killed process (SIGKILL, power loss)
leaves results.part.npy, which read_results reads as well.
"""

import csv
import fcntl
import json
import os
import platform
import re
import signal
import sys
import tempfile
import threading
import time
from contextlib import contextmanager
from importlib import metadata
from itertools import chain
from pathlib import Path

import numpy as np
import orjson

from . import metrics
from ..engine.master import CoSimulation
from .scenario import Scenario

BLOCK = 1000  # steps between writes of results.csv and metric updates
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)  # end a run at a step boundary


FORMATS = {"csv": "results.csv", "mat": "results.mat"}  # scenario key format / --format -> file
PART_FILE = "results.part.npy"  # a MAT run's rows while it runs (see _MatBlocks)
RUN_FILES = (*FORMATS.values(), PART_FILE, "run.json", "metrics.json")
COMPARISON_JSON = "comparison.json"  # marks a comparison folder (kind "comparison")
KINDS = ("run", "comparison")

LOCK_FILE = ".tapmp.lock"  # in every output folder while a tapmp writer holds it
_HELD = set()  # (real path, thread id) of the folders this process has locked: re-entrant per thread


class OutputExistsError(RuntimeError):
    """The output folder already holds results and overwriting was not asked for."""


class OutputInUseError(RuntimeError):
    """Another tapmp process (or thread) is writing into the output folder."""


class ResultFolderError(ValueError):
    """A folder given to read or plot is missing or holds no readable results."""


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


def _read_json(path: Path):
    """The JSON content of ``path``, or None if it is missing or unreadable."""
    try:
        return json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None


def folder_kind(folder) -> str | None:
    """What a result folder holds: "comparison" (comparison.json, or legacy: no run files
    of its own and run folders below), "run" (any of RUN_FILES) or None (nothing of tapmp's)."""
    folder = Path(folder)
    if (folder / COMPARISON_JSON).is_file():
        return "comparison"
    if any((folder / f).exists() for f in RUN_FILES):
        return "run"
    if folder.is_dir() and any((p / "run.json").is_file() for p in folder.iterdir() if p.is_dir()):
        return "comparison"
    return None


def folder_completed(folder) -> bool:
    """Whether a result folder holds a completed run or comparison: status "completed"
    in run.json / comparison.json; a run's metrics.json (written only on completion) or an
    unreadable run.json count as completed too (never reuse what might be good results);
    a legacy comparison without comparison.json is completed if one of its runs is."""
    folder = Path(folder)
    kind = folder_kind(folder)
    if kind == "run":
        info = _read_json(folder / "run.json")
        if (folder / "metrics.json").exists() or ((folder / "run.json").exists() and info is None):
            return True
        return isinstance(info, dict) and info.get("status") == "completed"
    if kind == "comparison":
        info = _read_json(folder / COMPARISON_JSON)
        if info is not None:
            return info.get("status") == "completed"
        return any(folder_completed(p) for p in folder.iterdir() if p.is_dir())
    return False


def prepare_output(out: Path, overwrite: bool, kind: str = "run") -> Path:
    """Create the output folder for a result of ``kind`` ("run" or "comparison"). Refused
    (OutputExistsError, one line naming --out, and --overwrite where it would help): a
    folder holding the other kind, and one holding a completed result unless overwrite.
    A folder of the same kind whose result failed, was interrupted or never finished is
    reused: its run files (and figures of a run) are removed. Call it holding the
    folder's output_lock."""
    out = Path(out)
    existing = folder_kind(out) if out.exists() else None
    if existing is not None and existing != kind:
        marker = COMPARISON_JSON if existing == "comparison" else "run.json"
        what = {"run": "a single run", "comparison": "a comparison"}
        raise OutputExistsError(f"output folder {out} holds {what[existing]} ({marker}), not {what[kind]}: "
                                f"choose another folder with --out")
    if existing is not None and folder_completed(out) and not overwrite:
        raise OutputExistsError(f"output folder {out} already holds results of a completed {kind}: "
                                "choose another with --out or pass --overwrite")
    if kind == "run":
        for f in RUN_FILES:
            (out / f).unlink(missing_ok=True)
        for fig in out.glob("run_fig*.png") if out.exists() else ():
            fig.unlink()
    out.mkdir(parents=True, exist_ok=True)
    return out


def write_comparison_status(out: Path, scenario_name: str, runs: dict, status: str, **extra) -> None:
    """comparison.json of a comparison folder: kind, scenario, the compared runs
    {folder name: law}, status ("running", "completed", "failed", "interrupted")."""
    _write_result(Path(out) / COMPARISON_JSON, {"kind": "comparison", "scenario": scenario_name,
                                               "runs": dict(runs), "status": status, **extra})


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
                 progress=None, stop_token: str | None = None, keep_rows: list | None = None,
                 keep_bytes: int = 0) -> dict:
    """Run one scenario; write run.json, metrics.json and results.csv or results.mat
    (``scenario.format``) into ``out`` (prepare_output: a completed run there is kept
    unless ``overwrite``, a failed or interrupted one is replaced).

    ``progress(n_done, n_total)`` is called every BLOCK steps. Returns the metrics,
    computed from every step (the result file keeps every ``scenario.record_every``-th
    step and the last). The output folder is locked for the whole run (OutputInUseError
    if another writer has it).

    SIGINT, SIGTERM and SIGHUP (and request_stop(stop_token)) end the run at the next
    step boundary with Interrupted. On any failure the whole rows so far stay in
    the result file, run.json records the status, exit code and reason (if it can be
    written) and the error is raised again: CoSimulationError, Interrupted, or
    ResultsWriteError if a result file cannot be written (it is then cut back to its
    last whole block of rows).

    ``keep_rows``, a list, receives the recorded rows block by block (arrays) as they are
    written, for a caller that plots them, as long as they total at most ``keep_bytes``;
    beyond that it is emptied (read the result file instead).
    """
    with output_lock(out):
        out = prepare_output(out, overwrite)
        return _run_locked(scenario, ssp, out, progress, stop_token, keep_rows, keep_bytes)


def run_scenario_held(scenario: Scenario, ssp: Path, out: Path, progress=None, stop_token: str | None = None,
                      keep_rows: list | None = None, keep_bytes: int = 0) -> dict:
    """run_scenario (overwrite) into ``out`` whose output_lock another process of this command
    holds for it (a worker of `tapmp compare`'s pool: the command locks every run folder)."""
    out = prepare_output(out, True)
    return _run_locked(scenario, ssp, out, progress, stop_token, keep_rows, keep_bytes)


def _write_result(path: Path, data) -> None:
    """write_json, with an OSError (e.g. a full disk) as ResultsWriteError naming the file."""
    try:
        write_json(path, data)
    except OSError as err:
        raise ResultsWriteError(f"cannot write {path}: {err.strerror or err} (errno {err.errno})") from err


def _run_locked(scenario: Scenario, ssp: Path, out: Path, progress, stop_token, keep_rows=None,
                keep_bytes: int = 0) -> dict:
    """run_scenario's body, in the locked and prepared output folder ``out``."""
    fmt = getattr(scenario, "format", "csv")
    info = {"kind": "run", "format": fmt, "results_file": FORMATS[fmt],
            "scenario": scenario.to_dict(), "ssp": str(ssp), "step": scenario.step,
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
                info["columns"] = list(sim.columns)
                if fmt == "mat":  # results.part.npy needs its column names on record (a killed run)
                    _write_result(out / "run.json", info)
                stats = _simulate(sim, scenario, out, fmt, stop, progress, keep_rows, keep_bytes)
            result = stats.result()
            if "not_computed" in result:
                print(f"note: metrics not computed: {result['not_computed']}", file=sys.stderr)
            _write_result(out / "metrics.json", result)
            wall = time.perf_counter() - start
            info.update(status="completed", exit_code=0, wall_time_s=wall,
                        real_time_factor=wall / (scenario.stop_time - scenario.start_time))
            _write_result(out / "run.json", info)
        except BaseException as err:
            _record_failure(out / "run.json", info, err, sim, start)
            raise
    return result


def _as_block(rows: list) -> np.ndarray:
    """Rows (lists of equal length) as one float64 array; np.fromiter over the chained rows
    is about a third faster than np.array on a list of lists."""
    return np.fromiter(chain.from_iterable(rows), float, count=len(rows) * len(rows[0])).reshape(len(rows), -1)


def _recorded(block: np.ndarray, first: int, every: int, n: int) -> np.ndarray:
    """The rows of ``block`` (steps first, first + 1, ...) that a run keeps: every
    ``every``-th step and the last step ``n``."""
    if every == 1:
        return block
    steps = np.arange(first, first + block.shape[0])
    return block[(steps % every == 0) | (steps == n)]


def _simulate(sim: CoSimulation, scenario: Scenario, out: Path, fmt: str, stop: _StopRequest, progress,
              keep_rows: list | None = None, keep_bytes: int = 0):
    """The step loop: rows to the result file in whole blocks, metrics over every step;
    returns the metrics.ErrorStatistics. Stops at a block boundary when ``stop`` is set.
    The rows of a block are stored by CoSimulation.advance (the compiled core or the
    Python loop) into one preallocated array."""
    n, every = scenario.n_steps, scenario.record_every
    base_writer = (_CsvBlocks if fmt == "csv" else _MatBlocks)(out, sim.columns)
    writer = base_writer if keep_rows is None else _Keeping(base_writer, keep_rows, keep_bytes)
    buffer = np.empty((BLOCK, len(sim.columns)))
    filled, first = 0, 0  # rows of buffer (steps first, first + 1, ...) not yet written
    try:
        stats = metrics.ErrorStatistics(sim.columns, metrics.saturation_limit(sim.parameters),
                                        metrics.force_step(sim.parameters, scenario.start_time, scenario.stop_time),
                                        metrics.move_spec(sim.parameters, scenario.settling_bands))
        buffer[0] = sim.row()
        filled, k = 1, 0
        while k < n:
            if stop.signal is not None:
                stop.check(sim.time)
            m = min(BLOCK - filled, n - k)
            try:
                sim.advance(buffer[filled:filled + m])
            except BaseException:
                filled += sim.filled  # the rows stored before the failure
                raise
            filled, k = filled + m, k + m
            if filled == BLOCK:
                block = buffer[:filled]
                writer.write(_recorded(block, first, every, n))
                stats.add(block)
                first, filled = first + BLOCK, 0
                if progress:
                    progress(k, n)
        stop.check(sim.time)
        if filled:
            block = buffer[:filled]
            writer.write(_recorded(block, first, every, n))
            stats.add(block)
            filled = 0
        writer.finish()
        if progress:
            progress(n, n)
        return stats
    except ResultsWriteError:
        writer.finish(quiet=True)
        raise
    except BaseException:
        if filled:  # the whole rows so far stay
            writer.write(_recorded(buffer[:filled], first, every, n), quiet=True)
        writer.finish(quiet=True)
        raise
    finally:
        writer.close()


class _Keeping:
    """A result writer that also keeps copies of the blocks it writes in ``rows`` while they
    total at most ``limit`` bytes (then ``rows`` is emptied and nothing more is kept)."""

    def __init__(self, writer, rows: list, limit: int):
        self.writer, self.rows, self.limit, self.size = writer, rows, limit, 0

    def write(self, block: np.ndarray, quiet: bool = False) -> None:
        self.writer.write(block, quiet)
        if self.size <= self.limit:
            self.size += block.nbytes
            if self.size <= self.limit:
                self.rows.append(block.copy())
            else:
                self.rows.clear()

    def finish(self, quiet: bool = False) -> None:
        self.writer.finish(quiet)

    def close(self) -> None:
        self.writer.close()


def _write_error(path: Path, err: OSError, detail: str = "") -> ResultsWriteError:
    return ResultsWriteError(f"cannot write {path}: {err.strerror or err} (errno {err.errno}){detail}")


class _Blocks:
    """A result file written in whole blocks of rows (one os.write per block); after a
    failed write (e.g. a full disk) the file is cut back to the end of its last whole block."""

    def __init__(self, path: Path, columns):
        self.path = Path(path)
        self.columns = list(columns)
        try:
            self.fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_CLOEXEC, 0o644)
        except OSError as err:
            raise _write_error(self.path, err) from err
        self.size = 0            # bytes of whole blocks on disk
        self.rows = 0            # rows on disk
        self.last_time = None    # time [s] of the last row on disk

    def _append(self, data: bytes, rows: int, last_time, quiet: bool) -> bool:
        """Append one block of bytes; on failure cut back to whole blocks and raise
        ResultsWriteError (or return False if ``quiet``)."""
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
                return False
            kept = (f"the rows up to t = {self.last_time:.6g} s" if self.last_time is not None
                    else "no rows")
            raise _write_error(self.path, err, f": it keeps {kept}, whole rows only") from err
        self.size += len(data)
        self.rows += rows
        if last_time is not None:
            self.last_time = last_time
        return True

    def close(self) -> None:
        os.close(self.fd)


class _CsvBlocks(_Blocks):
    """results.csv: a header of column names, then one line per row, every value as the
    shortest decimal text that reads back to the same double (the digits of Python's repr;
    small and large magnitudes in plain or exponent notation, e.g. 0.00001, -2.5e-7,
    1e+16). A block is formatted in one call to orjson's numpy serializer (compiled,
    about 20x faster than Python's %-formatting of every value) and its JSON rows turned
    into lines; a block holding a non-finite value (never written by the master, which
    stops before) is formatted with Python's repr."""

    def __init__(self, out: Path, columns):
        super().__init__(Path(out) / FORMATS["csv"], columns)
        self.header = (",".join(self.columns) + "\n").encode()
        self.line = ",".join(["%r"] * len(self.columns)) + "\n"

    def write(self, block: np.ndarray, quiet: bool = False) -> None:
        """Append the rows of ``block`` (n x columns); the header goes with the first block."""
        if not block.shape[0]:
            return
        data = (self.header if self.size == 0 else b"") + format_csv_rows(block, self.line)
        self._append(data, block.shape[0], float(block[-1, 0]), quiet)

    def finish(self, quiet: bool = False) -> None:
        """Nothing left to do: every block is on disk as it is written."""


def format_csv_rows(block: np.ndarray, line: str | None = None) -> bytes:
    """The rows of ``block`` (n x columns, float64) as CSV lines, every value the shortest
    text that reads back to the same double (see _CsvBlocks); ``line`` is the %-format of
    one row used for a block with a non-finite value (orjson writes those as null)."""
    block = np.ascontiguousarray(block, dtype=np.float64)
    if not np.isfinite(block).all():
        line = line or ",".join(["%r"] * block.shape[1]) + "\n"
        return ((line * block.shape[0]) % tuple(block.ravel().tolist())).encode()
    text = orjson.dumps(block, option=orjson.OPT_SERIALIZE_NUMPY)  # b"[[a,b],[c,d]]"
    return text[2:-2].replace(b"],[", b"\n") + b"\n"


def mat_names(columns) -> list[str]:
    """MATLAB variable names of result columns: "." and anything else not allowed as "_",
    a leading "v_" if the name does not start with a letter, at most 63 characters,
    and "_2", "_3", ... for a name that would repeat an earlier one."""
    names, seen = [], set()
    for col in columns:
        base = re.sub(r"\W", "_", col, flags=re.ASCII)
        base = base if base[:1].isalpha() and base.isascii() else "v_" + base
        name, k = base[:63], 2
        while name in seen:
            name, k = f"{base[:60]}_{k}", k + 1
        seen.add(name)
        names.append(name)
    return names


class _MatBlocks(_Blocks):
    """results.mat via results.part.npy: each block is appended to the .npy file as raw
    little-endian float64 rows and its fixed-size header is rewritten with the new row
    count, so the part file is a valid .npy of the whole blocks at every moment. finish()
    writes results.mat from it (scipy.io.savemat, under a temporary name, then os.replace)
    and removes it."""

    HEADER = 128  # bytes of the .npy header (magic, version 1.0, length, padded dict)

    def __init__(self, out: Path, columns):
        super().__init__(Path(out) / PART_FILE, columns)
        self.mat = Path(out) / FORMATS["mat"]
        self._append(self._header(0), 0, None, quiet=False)

    def _header(self, rows: int) -> bytes:
        text = repr({"descr": "<f8", "fortran_order": False, "shape": (rows, len(self.columns))})
        body = text.ljust(self.HEADER - 10 - 1) + "\n"
        return b"\x93NUMPY\x01\x00" + len(body).to_bytes(2, "little") + body.encode("latin1")

    def write(self, block: np.ndarray, quiet: bool = False) -> None:
        """Append the rows of ``block`` (n x columns) and record them in the header."""
        if not block.shape[0]:
            return
        data = np.ascontiguousarray(block, dtype="<f8").tobytes()
        if self._append(data, block.shape[0], float(block[-1, 0]), quiet):
            try:
                os.pwrite(self.fd, self._header(self.rows), 0)
            except OSError as err:  # the header is rewritten in place: it never needs new space
                if not quiet:
                    raise _write_error(self.path, err) from err

    def finish(self, quiet: bool = False) -> None:
        """Write results.mat from the whole blocks on disk and remove the part file; if that
        fails, results.part.npy stays (ResultsWriteError unless ``quiet``)."""
        try:
            write_mat(self.mat, self.columns, np.load(self.path, mmap_mode="r"))
        except (OSError, ValueError) as err:
            if quiet:
                return
            if isinstance(err, OSError):
                raise _write_error(self.mat, err, f": the rows stay in {self.path}") from err
            raise
        self.path.unlink(missing_ok=True)


def write_mat(path: Path, columns, data: np.ndarray) -> None:
    """Write rows ``data`` (n x columns) as a MAT-file (version 5, uncompressed, readable
    by MATLAB's load, scipy.io.loadmat): one n x 1 double variable per column (mat_names)
    and ``columns``, the original names as a char matrix (MATLAB: cellstr(columns)).
    Written under a temporary name in the same folder, then os.replace."""
    from scipy.io import savemat
    path = Path(path)
    variables = {name: data[:, j:j + 1] for j, name in enumerate(mat_names(columns))}
    variables["columns"] = np.array(list(columns))
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            os.fchmod(f.fileno(), 0o644)
            savemat(f, variables, do_compression=False, oned_as="column")
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


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


def _read_csv_rows(path: Path, n_columns: int) -> np.ndarray:
    """The rows of results.csv (n x n_columns): parsed as one JSON array by orjson (exact
    decimal-to-double conversion, about 3x faster than np.loadtxt); a file orjson cannot
    read that way (inf or nan written by repr, a ragged row) goes through np.loadtxt."""
    with open(path, "rb") as f:
        f.readline()
        text = f.read().rstrip(b"\n")
    try:
        flat = np.array(orjson.loads(b"[" + text.replace(b"\n", b",") + b"]"), dtype=float)
        if text and flat.size % n_columns == 0 and flat.size == (text.count(b"\n") + 1) * n_columns:
            return flat.reshape(-1, n_columns)
    except (orjson.JSONDecodeError, ValueError, TypeError):
        pass
    return np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)


def read_results(folder: Path) -> tuple[list[str], np.ndarray]:
    """Columns and rows (n x columns, SI units, time [s] first) of a run folder, from
    results.mat, results.csv or (a killed MAT run) results.part.npy with the columns
    recorded in run.json. ResultFolderError names the folder if it holds none."""
    folder = Path(folder)
    mat, csv_path, part = folder / FORMATS["mat"], folder / FORMATS["csv"], folder / PART_FILE
    if mat.is_file():
        from scipy.io import loadmat
        content = loadmat(mat)
        columns = [str(c).rstrip() for c in content["columns"]]
        return columns, np.hstack([content[n] for n in mat_names(columns)]).astype(float)
    if csv_path.is_file():
        with open(csv_path) as f:
            columns = next(csv.reader(f))
        return columns, _read_csv_rows(csv_path, len(columns))
    if part.is_file():
        info = _read_json(folder / "run.json") or {}
        if "columns" not in info:
            raise ResultFolderError(f"{part} has no column names: run.json records none")
        return list(info["columns"]), np.array(np.load(part, mmap_mode="r"))
    raise ResultFolderError(f"{folder} holds no results ({', '.join(FORMATS.values())}): "
                            "allowed is a run folder written by tapmp run")


# Output size and wall time of runs, estimated before they start.
RECORDED_COLUMNS = 40  # time + 15 plant, 12 trajectory and 12 controller outputs (the FMUs' model descriptions)
BYTES_PER_VALUE = {"csv": 21, "mat": 8}  # csv: shortest round-trip text and a comma (measured: 20.5 on a 11 s run)
SECONDS_PER_STEP = 1.3e-5  # wall time of one 0.1 ms step of the native FMUs (measured: 1.37 s for 111112 steps)
SHOW_BYTES = 100e6  # print the estimate above this size [bytes]
WARN_BYTES = 1e9  # and a warning line above this one


class DiskSpaceError(OSError):
    """The runs would write more than the free space of the output folder's disk."""


def recorded_rows(scenario: Scenario) -> int:
    """Rows a run of ``scenario`` writes: step 0, every ``record_every``-th step and the last."""
    n, every = scenario.n_steps, scenario.record_every
    return n // every + 1 + (1 if n % every else 0)


def output_estimate(scenarios) -> tuple[int, float]:
    """(bytes, seconds): the result files of the runs of ``scenarios`` (rows x
    RECORDED_COLUMNS x BYTES_PER_VALUE of each one's format) and their summed wall time
    at SECONDS_PER_STEP per step (one process)."""
    size = sum(recorded_rows(s) * RECORDED_COLUMNS * BYTES_PER_VALUE[getattr(s, "format", "csv")]
               for s in scenarios)
    return size, sum(s.n_steps for s in scenarios) * SECONDS_PER_STEP


def human_bytes(n: float) -> str:
    """``n`` bytes as kB, MB, GB or TB (powers of 1000), three significant digits."""
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= scale:
            return f"{n / scale:.3g} {unit}"
    return f"{int(n)} B"


def _existing_parent(path: Path) -> Path:
    path = Path(path).absolute()
    while not path.exists():
        path = path.parent
    return path


def check_output_size(scenarios, out: Path, label: str, processes: int = 1, stream=None) -> int:
    """Before runs start: their estimated output size [bytes] (returned). Above SHOW_BYTES one
    line with the size and the wall time on ``stream`` (stderr), above WARN_BYTES a
    ``warning:`` line too; DiskSpaceError if the disk of ``out`` (its nearest existing
    folder) has less free space than the runs need (a MAT run holds its rows twice while it
    writes results.mat)."""
    import shutil
    scenarios = list(scenarios)
    stream = stream or sys.stderr
    size, seconds = output_estimate(scenarios)
    need = sum(output_estimate([s])[0] * (2 if getattr(s, "format", "csv") == "mat" else 1) for s in scenarios)
    free = shutil.disk_usage(_existing_parent(out)).free
    # TAPMP_NO_DISK_CHECK=1: run anyway (a disk whose free space is misreported; the tests of a
    # disk that fills up while a run writes)
    if need > free and os.environ.get("TAPMP_NO_DISK_CHECK") != "1":
        raise DiskSpaceError(f"{label}: the runs would write about {human_bytes(need)} into {out} but its disk has "
                             f"{human_bytes(free)} free: shorten stop_time, record fewer rows (--record-every N) or "
                             "write MAT (--format mat)")
    if size > SHOW_BYTES:
        rows = sum(recorded_rows(s) for s in scenarios)
        fmts = "/".join(sorted({getattr(s, "format", "csv") for s in scenarios}))
        print(f"{label}: about {human_bytes(size)} of results ({rows} rows x {RECORDED_COLUMNS} columns, {fmts}) "
              f"and about {seconds / max(1, min(processes, len(scenarios))):.0f} s of runs", file=stream, flush=True)
    if size > WARN_BYTES:
        print(f"warning: {label}: the results will take about {human_bytes(size)} of {human_bytes(free)} free; "
              "--record-every N keeps every N-th step, --format mat writes about 40 % of it", file=stream, flush=True)
    return size


class Progress:
    """Progress of a long task on stderr: a tqdm bar on a terminal; otherwise one line at
    each 10 % of a task that has run for more than ``quiet_s`` seconds (none for short ones)."""

    def __init__(self, desc: str, unit: str = "step", total: int | None = None, quiet_s: float = 2.0):
        self.desc, self.unit, self.total, self.quiet_s = desc, unit, total, quiet_s
        self.start, self.shown, self.done = time.monotonic(), 0, 0
        self.bar = None
        if sys.stderr.isatty():
            from tqdm import tqdm
            self.bar = tqdm(total=total, desc=desc, unit=unit, delay=1.0, mininterval=0.5, leave=False)

    def __call__(self, done: int, total: int | None = None) -> None:
        """Set the count done (of ``total`` if given)."""
        if total is not None:
            self.total = total
        self.done = done
        if self.bar is not None:
            self.bar.total, self.bar.n = self.total, done
            self.bar.refresh()
            return
        if not self.total:
            return
        tenth = int(10 * done / self.total)
        if tenth > self.shown and time.monotonic() - self.start > self.quiet_s:
            self.shown = tenth
            print(f"{self.desc}: {10 * tenth} % ({done}/{self.total} {self.unit}s)", file=sys.stderr, flush=True)

    def update(self, n: int = 1) -> None:
        """Add ``n`` to the count done."""
        self(self.done + n)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
