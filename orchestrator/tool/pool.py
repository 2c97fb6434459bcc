"""Independent runs on every core: the runs of `tapmp compare` and `tapmp reproduce` go to a
pool of processes (``--jobs``, default one per core), each writing its own run folder.

A run that fails ends the whole set with its own error (message and exit code as if it
had run alone; runs not yet started are cancelled, those running finish). A stop signal to
the command (SIGINT, SIGTERM, SIGHUP) is passed on to the workers: their runs end at the next
block of steps with status "interrupted", as a run in the foreground does.
"""

import os
import signal
from contextlib import ExitStack
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from multiprocessing import get_context
from pathlib import Path

from ..engine.master import CoSimulationError
from ..errors import UsageError
from .folders import OutputExistsError, OutputInUseError, ResultsWriteError, output_lock
from .results import one_line
from .stops import Interrupted

KEEP_ROWS_BYTES = 64 << 20  # a run's rows come back for the figures up to this size, else they are read


def cores() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def parse_jobs(value) -> int:
    """--jobs as an integer in 1 .. cores(); ValueError (one line) otherwise. None: cores()."""
    n = cores()
    if value is None:
        return n
    text = str(value).strip()
    if not text.isdigit() or not 1 <= int(text) <= n:
        raise UsageError(f"--jobs = {value!r} is invalid: allowed is a positive integer up to the {n} "
                         f"core{'s' if n > 1 else ''} of this machine")
    return int(text)


# Errors a run raises, rebuilt from their message in the parent (exceptions with more
# arguments than a message do not pickle back into their class).
# A ValueError of a subclass (ScenarioError, ModelInputError, ...) is bad input and comes back as
# UsageError (one line); a plain ValueError comes back as ValueError, a programming error.
_ERRORS = {cls.__name__: cls for cls in (CoSimulationError, ResultsWriteError, OutputExistsError,
                                         OutputInUseError, UsageError, ValueError, OSError)}


def _error_record(err: BaseException) -> dict:
    record = {"error": one_line(err), "type": type(err).__name__, "exit_code": getattr(err, "exit_code", 2)}
    if isinstance(err, Interrupted):
        record["signum"] = err.signum
    elif isinstance(err, KeyboardInterrupt):
        record["signum"] = int(signal.SIGINT)
    else:
        kind = UsageError if isinstance(err, ValueError) and type(err) is not ValueError else type(err)
        record["type"] = next((c.__name__ for c in kind.__mro__ if c.__name__ in _ERRORS), "CoSimulationError")
        for key in ("element", "time"):
            record[key] = getattr(err, key, None)
    return record


def _raise(record: dict):
    """Raise the error a worker reported, as its class (the message unchanged)."""
    if "signum" in record:
        raise Interrupted(record["signum"], record["error"])
    cls = _ERRORS[record["type"]]
    if cls is CoSimulationError:
        raise CoSimulationError(record["error"], record.get("element"), record.get("time"))
    raise cls(record["error"])


_CANCEL = None  # in a worker: the parent's event "start no more runs"
_SHARES = None  # in a worker: the parent's array of each run's share done (0 to 1), for its progress


def _worker_init(cancel, shares=None) -> None:
    """A worker keeps the parent's cancel event (and the array its runs' shares done go into).
    Stop signals reach its run through the command line's handler, which the forked worker
    inherits (an idle worker ignores them). FMUs the parent kept loaded stay the parent's: the
    worker loads its own."""
    global _CANCEL, _SHARES
    _CANCEL, _SHARES = cancel, shares
    from ..engine.loaded import forget_process_fmus
    forget_process_fmus()


def ignore_interrupts() -> None:
    """A helper process's initializer: Ctrl-C (SIGINT to the terminal's process group) is left to
    the command, which ends its helpers itself, so that no helper prints a traceback of its own."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def run_one(scenario, ssp, out, keep: bool, progress=None, held: bool = False) -> dict:
    """One run (results.run_scenario, overwrite; ``held``: its folder's lock is held by the
    parent process, and this is a pool's worker, which keeps the SSP's FMUs loaded for its next
    run) as a record: {"metrics", "rows"} ("rows": the recorded rows if ``keep`` and they fit
    KEEP_ROWS_BYTES, else None) or {"error", ...} for a failure, never an exception."""
    from ..engine.loaded import process_fmus
    from .results import run_scenario, run_scenario_held
    if _CANCEL is not None and _CANCEL.is_set():  # the set failed or was stopped: start nothing more
        return {"error": "not run", "type": "CoSimulationError", "exit_code": 2, "skipped": True}
    rows = [] if keep else None
    try:
        if held:
            metrics = run_scenario_held(scenario, Path(ssp), Path(out), progress, keep_rows=rows,
                                        keep_bytes=KEEP_ROWS_BYTES, loaded=process_fmus())
        else:
            metrics = run_scenario(scenario, Path(ssp), Path(out), True, progress, keep_rows=rows,
                                   keep_bytes=KEEP_ROWS_BYTES)
    except BaseException as err:  # noqa: B902  (reported to the parent, which raises it)
        return _error_record(err)
    if rows:
        import numpy as np
        rows = np.vstack(rows)
    return {"metrics": metrics, "rows": rows if keep and len(rows) else None}


def _run_shared(index: int, scenario, ssp, out, keep: bool) -> dict:
    """run_one in a pool's worker, its share of steps done going into the parent's array at ``index``."""
    def share(done, total):
        _SHARES[index] = done / total if total else 1.0
    return run_one(scenario, ssp, out, keep, share if _SHARES is not None else None, True)


def run_many(tasks: dict, jobs: int, keep=True, progress=None, label: str = "", first=(),
             on_record=None, idle=None) -> dict:
    """Run ``tasks`` ({name: (scenario, ssp, out folder)}) on ``jobs`` processes (in this
    process if jobs == 1 or there is one task); {name: record of run_one} in the order of
    ``tasks``. ``keep``: whether the runs' rows come back (run_one), True or False for every
    task or the names of the tasks whose rows do. The first failure is raised (see the module
    docstring). ``progress(name)`` makes a per-run progress callback when running in this
    process; a pool shows one bar
    of completed runs instead (when ``progress`` is given). Every run folder is locked by this
    process from the start to the end of the set (a pool's workers run in them).
    ``first``: names of tasks to start before the others; ``on_record(name, record)`` is called
    here as each run succeeds; ``idle()``, if given, is called here while a pool's runs are
    still running (one short piece of work per call, e.g. one figure: this process is otherwise
    only waiting)."""
    with ExitStack() as locks:
        for _, _, out in tasks.values():
            locks.enter_context(output_lock(out))
        return _run_many(tasks, jobs, keep, progress, label, first, on_record, idle)


def _run_many(tasks: dict, jobs: int, keep, progress, label: str, first=(), on_record=None,
              idle=None) -> dict:
    kept = set(tasks) if keep is True else set() if keep is False else set(keep)
    records = {}
    if jobs == 1 or len(tasks) == 1:
        for name, (sc, ssp, out) in tasks.items():
            update, close = progress(name) if progress else (None, lambda: None)
            try:
                records[name] = run_one(sc, ssp, out, name in kept, update)
            finally:
                close()
            if "error" in records[name]:
                _raise(records[name])
            if on_record:
                on_record(name, records[name])
        return records
    bar = None
    context = get_context("fork")
    # the runs' shares of steps done, written by the workers: the progress moves with the runs' steps
    shares = context.Array("d", len(tasks), lock=False)
    if progress:
        from .progress import Progress  # a bar on a terminal only
        bar = Progress(f"{label} runs", "run", len(tasks), every_s=10.0, count=lambda: round(sum(shares), 1))
    cancel = context.Event()  # queued runs that a worker has already taken must not start either
    pool = ProcessPoolExecutor(max_workers=min(jobs, len(tasks)), mp_context=context,
                               initializer=_worker_init, initargs=(cancel, shares))
    order = [n for n in first if n in tasks] + [n for n in tasks if n not in first]
    index = {name: i for i, name in enumerate(tasks)}
    futures = {pool.submit(_run_shared, index[name], *tasks[name][:3], name in kept): name for name in order}
    try:
        pending = set(futures)
        while pending:
            done, pending = wait(pending, return_when=FIRST_COMPLETED, timeout=0.2)
            if bar is not None:
                bar(round(sum(shares), 1))
            for f in done:
                record = records[futures[f]] = f.result()
                if bar is not None:
                    shares[index[futures[f]]] = 1.0  # a failed or skipped run is done too
                    bar(round(sum(shares), 1))
                if "error" in record:
                    cancel.set()
                    for p in pending:
                        p.cancel()
                    wait(pending)
                    _raise(record)
                if on_record:
                    on_record(futures[f], record)
            if pending and idle:
                idle()
    except BaseException as err:
        cancel.set()
        if isinstance(err, KeyboardInterrupt):  # a stop signal here: stop the runs in the workers too
            signum = getattr(err, "signum", int(signal.SIGINT))
            for proc in list(getattr(pool, "_processes", {}).values()):
                try:
                    os.kill(proc.pid, signum)
                except OSError:
                    pass
        pool.shutdown(wait=True, cancel_futures=True)
        raise
    finally:
        if bar is not None:
            bar.close()
    pool.shutdown(wait=True)
    return {name: records[name] for name in tasks}
