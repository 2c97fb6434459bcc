"""Run a scenario through the master algorithm into its result folder.

A run folder (folders.py) holds run.json (kind "run": the resolved scenario, FMU GUIDs,
columns, versions, step, ordering, format, wall time, status, exit code and the reason of
a failure), metrics.json and the rows in the scenario's format (writers.py). Memory stays
bounded: rows go to disk and into the streaming metrics in blocks of BLOCK steps,
whatever the simulated time. The output folder is locked for the whole run.

Abnormal ends leave no half state: a stop (stops.py: a signal the command line delivers,
or a study's request_stop) ends a run at the next step boundary (run.json: status
"interrupted", the signal's name, exit code 128 + its number); a failed write (e.g. a
full disk) ends it with ResultsWriteError, the result file cut back to its last whole
block of rows; a failure of the co-simulation keeps the whole rows before it.

A paced run (``pacing``, engine.pacing: `tapmp run --real-time`) steps on a thread of its own and
hands its rows to this one, which records them in the same blocks of BLOCK steps as any run, so
its result files and metrics are the unpaced run's to the bit; run.json gets its statistics under
"real_time", also when it fails, and real_time.png (realtime_plots.py) is drawn beside.
"""

import functools
import platform
import sys
import time
from importlib import metadata
from pathlib import Path

import numpy as np

from . import metrics
from ..engine.master import CoSimulation
from ..engine.options import RunOptions
from ..engine.tempdirs import remove_stale_folders
from .envelope import envelope
from .folders import (FORMATS, MANIFEST, PART_FILE, ResultsWriteError, announcing, atomic_file, check_output,
                      output_lock, prepare_output, record_files, stream_record, write_json, write_result)
from .roles import ROLES, SCENARIO_TABLES
from .scenario import Scenario
from .stops import StopRequest, stop_scope
from .writers import CsvBlocks, Keeping, MatBlocks

BLOCK = 1000  # steps between writes of results.csv and metric updates


def one_line(err) -> str:
    """The text of an error on one line (an FMU's log message may hold line breaks)."""
    return " ".join(str(err).splitlines()) or type(err).__name__


def versions() -> dict:
    """Versions of the packages a result depends on (looked up once per process: a study worker
    records them in every case's run.json)."""
    return dict(_versions())


@functools.lru_cache(maxsize=1)
def _versions() -> dict:
    out = {"python": platform.python_version()}
    for pkg in ("tapmp-cosim", "fmpy", "pythonfmu", "numpy"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = None
    return out


def run_scenario(scenario: Scenario, ssp: Path, out: Path, overwrite: bool = False,
                 progress=None, stop_token: str | None = None, keep_rows: list | None = None,
                 keep_bytes: int = 0, loaded=None, pacing=None) -> dict:
    """Run one scenario; write run.json, metrics.json and results.csv or results.mat
    (``scenario.format``) into ``out`` (prepare_output: a completed run there is kept
    unless ``overwrite``, a failed or interrupted one is replaced).

    ``progress(n_done, n_total)`` is called every BLOCK steps. Returns the metrics,
    computed from every step (the result file keeps every ``scenario.record_every``-th
    step and the last). The output folder is locked for the whole run (OutputInUseError
    if another writer has it).

    A stop (SIGINT, SIGTERM or SIGHUP delivered by the command line's handler, or
    request_stop(stop_token)) ends the run at the next step boundary with Interrupted. On any failure the whole rows so far stay in
    the result file, run.json records the status, exit code and reason (if it can be
    written) and the error is raised again: CoSimulationError, Interrupted, or
    ResultsWriteError if a result file cannot be written (it is then cut back to its
    last whole block of rows).

    ``keep_rows``, a list, receives the recorded rows block by block (arrays) as they are
    written, for a caller that plots them, as long as they total at most ``keep_bytes``;
    beyond that it is emptied (read the result file instead).

    ``loaded`` (engine.loaded.LoadedFMUs, e.g. a study worker's): take the FMUs loaded from it
    and give them back reset (the same rows as FMUs loaded for this run alone).

    ``pacing`` (engine.pacing.Pacing): keep the steps to the wall clock (the module docstring).
    """
    check_output(out, overwrite, unmarked_only=True)  # before the lock file is made: a refused folder is left as it was
    with output_lock(out):
        out = prepare_output(out, overwrite)
        return _run_locked(scenario, ssp, out, progress, stop_token, keep_rows, keep_bytes, loaded, pacing)


def run_scenario_held(scenario: Scenario, ssp: Path, out: Path, progress=None, stop_token: str | None = None,
                      keep_rows: list | None = None, keep_bytes: int = 0, loaded=None) -> dict:
    """run_scenario (overwrite) into ``out`` whose output_lock another process of this command
    holds for it (a worker of `tapmp compare`'s pool: the command locks every run folder)."""
    out = prepare_output(out, True)
    return _run_locked(scenario, ssp, out, progress, stop_token, keep_rows, keep_bytes, loaded)


def run_options(scenario: Scenario) -> RunOptions:
    """How the master steps ``scenario``: its start time and step [s], ordering and order, clock,
    connection start, event mode and open inputs, the TAPMP roles and tables, the platform envelope
    as the output check, and the plant as Model Exchange with plant_interface = "me"."""
    return RunOptions(start_time=scenario.start_time, step_size=scenario.step, ordering=scenario.ordering,
                      order=scenario.step_order(), clock=scenario.clock, connection_start=scenario.connection_start,
                      event_mode=scenario.event_mode, open_inputs=scenario.open_inputs, check=envelope(scenario),
                      roles=ROLES, other_tables=SCENARIO_TABLES,
                      model_exchange=("plant",) if scenario.plant_interface == "me" else ())


def _run_locked(scenario: Scenario, ssp: Path, out: Path, progress, stop_token, keep_rows=None,
                keep_bytes: int = 0, loaded=None, pacing=None) -> dict:
    """run_scenario's body, in the locked and prepared output folder ``out``."""
    fmt = getattr(scenario, "format", "csv")
    info = {"kind": "run", "format": fmt, "results_file": FORMATS[fmt],
            "scenario": scenario.to_dict(), "ssp": str(ssp), "step": scenario.step,
            "ordering": scenario.ordering, "record_every": scenario.record_every,
            "clock": scenario.clock, "connection_start": scenario.connection_start,
            "event_mode": scenario.event_mode, "plant_interface": scenario.plant_interface,
            "versions": versions(), "status": "running", MANIFEST: {}}
    write_result(out / "run.json", info)
    written = {FORMATS[fmt], PART_FILE, "metrics.json"} if fmt == "mat" else {FORMATS[fmt], "metrics.json"}

    writers = []

    def announce(name: str, inode: int) -> None:  # a file of the run on record before it has its name
        info[MANIFEST][name] = stream_record(inode)
        write_result(out / "run.json", info)

    def opened(writer) -> None:  # the result file's writer: its hash is the file's record at the end
        writers.append(writer)

    def record(names) -> None:  # the files' records, a CSV file's as its writer hashed it
        record_files(out, info[MANIFEST], names, {w.path.name: w.record() for w in writers})

    start = time.perf_counter()
    stop = StopRequest()
    sim = None
    with stop_scope(stop, stop_token), announcing(out, announce):  # a signal after the last check: after the run
        try:
            stop.check(scenario.start_time)
            remove_stale_folders()  # of processes killed before they could remove their own
            with CoSimulation(ssp, scenario.parameters(), run_options(scenario), loaded=loaded) as sim:
                info["guids"] = sim.guids
                info["columns"] = list(sim.columns)  # on record with the result file (announce)
                stats = _simulate(sim, scenario, out, fmt, stop, progress, keep_rows, keep_bytes, opened, pacing,
                                  info)
            written |= _real_time_files(out, info)
            result = stats.result()
            if "not_computed" in result:
                print(f"note: metrics not computed: {result['not_computed']}", file=sys.stderr)
            write_result(out / "metrics.json", result)
            wall = time.perf_counter() - start
            record(written)
            info.update(status="completed", exit_code=0, wall_time_s=wall,
                        real_time_factor=wall / (scenario.stop_time - scenario.start_time))
            write_result(out / "run.json", info)
        except BaseException as err:
            if getattr(err, "real_time", None) is not None:
                info["real_time"] = err.real_time
            written |= _real_time_files(out, info, quiet=True)
            record(set(info[MANIFEST]) | written)
            _record_failure(out / "run.json", info, err, sim, start)
            raise
    return result


def _recorded(block: np.ndarray, first: int, every: int, n: int) -> np.ndarray:
    """The rows of ``block`` (steps first, first + 1, ...) that a run keeps: every
    ``every``-th step and the last step ``n``."""
    if every == 1:
        return block
    steps = np.arange(first, first + block.shape[0])
    return block[(steps % every == 0) | (steps == n)]


def _real_time_files(out: Path, info: dict, quiet: bool = False) -> set:
    """A paced run's trace (if kept) into real_time_trace.csv and its figure real_time.png; the names
    written. ``quiet``: a failed run's, whose own error is the one to raise."""
    rt = info.get("real_time")
    if rt is None:
        return set()
    names = set()
    try:
        trace = rt.pop("trace", None)
        if trace is not None:
            with atomic_file(out / "real_time_trace.csv") as f:
                f.write("step,lateness_s,execution_s\n")
                for i, (late, run) in enumerate(zip(trace["lateness_ns"].tolist(), trace["execution_ns"].tolist())):
                    f.write(f"{i + 1},{late * 1e-9!r},{run * 1e-9!r}\n")  # step i + 1 reaches t0 + (i + 1) h
            names.add("real_time_trace.csv")
        from .realtime_plots import plot_real_time
        plot_real_time(rt, out / "real_time.png", info.get("scenario", {}).get("start_time", 0.0))
        names.add("real_time.png")
    except Exception:
        if not quiet:
            raise
    return names


def _simulate(sim: CoSimulation, scenario: Scenario, out: Path, fmt: str, stop: StopRequest, progress,
              keep_rows: list | None = None, keep_bytes: int = 0, opened=None, pacing=None, info=None):
    """The step loop: rows to the result file in whole blocks, metrics over every step;
    ``opened(writer)`` is called once the result file (``writer.path``) is made, before its first row;
    returns the metrics.ErrorStatistics. Stops at a block boundary when ``stop`` is set.
    The rows of a block are stored by CoSimulation.advance (the compiled core or the
    Python loop) into one preallocated array."""
    n, every = scenario.n_steps, scenario.record_every
    base_writer = (CsvBlocks if fmt == "csv" else MatBlocks)(out, sim.columns)
    writer = base_writer if keep_rows is None else Keeping(base_writer, keep_rows, keep_bytes)
    buffer = np.empty((BLOCK, len(sim.columns)))
    filled, first = 0, 0  # rows of buffer (steps first, first + 1, ...) not yet written
    try:
        if opened:
            opened(base_writer)
        stats = metrics.ErrorStatistics(sim.columns, metrics.saturation_limit(sim.parameters),
                                        metrics.force_step(sim.parameters, scenario.start_time, scenario.stop_time),
                                        metrics.move_spec(sim.parameters, scenario.settling_bands))
        buffer[0] = sim.row()
        filled, k = 1, 0

        def take(rows) -> None:  # a paced run's rows, into the blocks of an unpaced one
            nonlocal filled, first
            i = 0
            while i < len(rows):
                m = min(BLOCK - filled, len(rows) - i)
                buffer[filled:filled + m] = rows[i:i + m]
                filled, i = filled + m, i + m
                if filled == BLOCK:
                    writer.write(_recorded(buffer, first, every, n))
                    stats.add(buffer)
                    first, filled = first + BLOCK, 0
                    if progress:
                        progress(first - 1, n)
        if pacing is not None and n:
            from ..engine.pacing import run_paced
            info["real_time"] = run_paced(sim, n, pacing, take, lambda: stop.signal is not None)
            k = n
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
