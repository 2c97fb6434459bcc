"""Studies: many independent co-simulations of one base scenario, run on Dask.

A study file (TOML; its models and loading are in orchestrator.studies.study_file) names a base
scenario and what varies:

* ``[grid]``: dotted scenario keys with a list of values each; every combination is a case;
* ``[monte_carlo]``: ``samples`` draws of the factors in ``[monte_carlo.vary.NAME]`` from
  stated distributions with a ``seed`` (combined with a grid: the same draws for every
  grid point, so the laws of a robustness study see the same plants);
* ``[tune]``: minimize the objective over the gains of each law (orchestrator.studies.tuning).

Every case runs through the real FMUs (orchestrator.tool.results.run_scenario) in a Dask
worker process, into its own folder ``OUTPUT/cases/CASE``. Workers get only plain data
(the base scenario as a dict, the changes, paths); each loads the FMUs itself. Rows
(parameters, metrics, status, wall time) are appended to ``OUTPUT/study.csv`` as cases
finish; a failing case is a row with its error. ``--resume`` runs only the cases that
have no row yet, in a folder whose study.json holds this study's fingerprint (prepare), and
with ``--retry-failed`` also those whose row says failed (drop_failed_rows).

The objective of a case is the mean over the three motors of the tracking MAE and the
synchronization MAE, averaged: (mean(tracking_mae_um) + mean(sync_mae_um)) / 2 [um].
"""

import csv
import dataclasses
import hashlib
import itertools
import json
import math
import os
import shutil
import signal
import sys
import tempfile
import time
from multiprocessing import resource_tracker
from pathlib import Path

import numpy as np

from ..tool.config import require
from ..tool.folders import refuse_link
from ..tool.scenario import Scenario
from .remote import (Shipping, case_folder, gain_values_of, pack_folder, remove_case_folder, retired_since,
                     this_plugin, unpack_folder)
from .study_file import Study, StudyError, apply_changes, base_value, expand_baseline, load_study

STUDY_CSV = "study.csv"
STUDY_JSON = "study.json"
STATUSES = ("completed", "diverged", "failed", "rejected")  # a study.csv row's status
METRIC_COLUMNS = ("objective", "tracking_mae_um_mean", "sync_mae_um_mean",
                  "tracking_mae_um_1", "tracking_mae_um_2", "tracking_mae_um_3",
                  "sync_mae_um_1", "sync_mae_um_2", "sync_mae_um_3", "saturation_fraction_max")
TAIL_COLUMNS = ("spectral_radius", "flag", "wall_time_s", "worker", "error")
SATURATION_FLAG = 0.01  # a case whose force commands sit at the limit in > 1 % of samples is "saturated"
def _require(cond: bool, message: str) -> None:
    require(cond, message, StudyError)


PENALTY_UM = 1e3  # objective of a rejected (not stable) or failed candidate [um]


MAX_CASES = 100_000  # a study's case count above which it is refused unless --max-cases allows it


def case_count(study: Study) -> int:
    """How many cases a grid / Monte Carlo study has (computed, not listed)."""
    return math.prod(len(v) for v in study.grid.values()) * (study.samples or 1)


# What the client holds per case at the peak of listing a study [bytes]: the case dict (cases()) and
# its text in study.json and in the fingerprint. Measured with tracemalloc on grids of the paper's
# scenario: 2545 B per case with one grid key, 2987 B with three (1000 cases each), so 2324 B + 221 B
# per key. A lower bound: the Dask futures and the scheduler's tasks come on top.
CASE_BYTES = 2324
KEY_BYTES = 221  # and per parameter or changed key of a case [bytes]


def case_memory(study: Study) -> int:
    """Estimated memory the client needs for the study's cases while it runs them [bytes]
    (CASE_BYTES and KEY_BYTES per case, computed from the counts, nothing listed)."""
    keys = len(study.grid) + len(study.factors) + sum(len(f.targets) for f in study.factors)
    return case_count(study) * (CASE_BYTES + KEY_BYTES * max(keys, 1))


def free_memory() -> int:
    """Memory this machine can give a process without swapping [bytes] (psutil's "available")."""
    import psutil
    return psutil.virtual_memory().available


def check_case_count(study: Study, limit: int = MAX_CASES) -> int:
    """The study's case count; StudyError naming it and how to allow it if it is above ``limit``,
    or naming the estimated memory (case_memory) and the free memory if it does not fit. A
    higher --max-cases is suggested only when the cases fit."""
    from ..tool.estimate import human_bytes
    n = case_count(study)
    sizes = [f"{len(v)} values of {k}" for k, v in study.grid.items()] + (
        [f"{study.samples} samples"] if study.samples else [])
    need, free = case_memory(study), free_memory()
    memory = (f"listing them needs about {human_bytes(need)} of memory and this machine has {human_bytes(free)} "
              "free: make the grid smaller or split it into studies")
    _require(n <= limit, f"{study.name} has {n} cases ({' x '.join(sizes)}): allowed are at most {limit} cases; "
             + (f"pass --max-cases {n} to run them all" if need <= free else memory))
    _require(need <= free, f"{study.name} has {n} cases ({' x '.join(sizes)}): {memory}")
    return n


def cases(study: Study, limit: int = MAX_CASES) -> list[dict]:
    """The cases of a grid / Monte Carlo study, in a fixed order (StudyError if more than
    ``limit``, checked before any is made).

    Each is {"case": id, "params": {column: value}, "changes": {dotted key: value}}.
    """
    check_case_count(study, limit)
    base = study.base_scenario()
    grid_keys = list(study.grid)
    combos = list(itertools.product(*study.grid.values())) if grid_keys else [()]
    draws = []
    if study.samples:
        rng = np.random.default_rng(study.seed)
        columns = {f.name: f.draw(rng, study.samples) for f in study.factors}
        draws = [{n: float(columns[n][i]) for n in columns} for i in range(study.samples)]
    out = []
    for combo in combos:
        point = expand_baseline(base, dict(zip(grid_keys, combo)))  # once per grid point: the same gains for every draw
        scenario = apply_changes(base, point, "grid") if point else base
        for draw in (draws or [{}]):
            params = dict(zip(grid_keys, combo))
            changes = dict(point)
            for f in study.factors:
                value = draw[f.name]
                params[f.name] = value
                for t in f.targets:
                    if f.relative:
                        b = base_value(scenario, t)
                        changes[t] = [value * x for x in b] if isinstance(b, list) else value * b
                    else:
                        changes[t] = value
            out.append({"case": f"c{len(out):04d}", "params": params, "changes": changes})
    return out


def objective(metrics: dict) -> float:
    """(mean tracking MAE + mean synchronization MAE) / 2 over the three motors [um]."""
    return 0.5 * (float(np.mean(metrics["tracking_mae_um"])) + float(np.mean(metrics["sync_mae_um"])))


def case_value(row) -> float:
    """Objective of a study.csv row [um]; PENALTY_UM for a case that did not complete."""
    v = row.get("objective")
    if row.get("status") != "completed" or v in (None, ""):
        return PENALTY_UM
    return float(v)


def run_case(base: dict, changes: dict, ssp, case_dir: str | None, keep_results: bool = False,
             reject_unstable: bool = False, stop_token: str | None = None, gain_files: dict | None = None,
             plugin: str = "", publish: dict | None = None) -> dict:
    """Run one case in this process (a Dask worker): returns its row as plain data.

    base: the base scenario as scenario_data; changes: dotted keys; gain_files: {path: preset
    or error text} of the gain preset files the case names (read by the client, case_scenario);
    ssp: the SSP's path, or None to take it from the study's worker plugin ``plugin`` (data
    mode: the SSP in this worker's cache); case_dir: the case's folder, or None to run in a
    worker-local temporary folder whose files come back in the row's "files" ({name: zlib
    bytes}, remote.pack_folder). With a ``plugin`` the worker is first checked against the
    client (remote.StudyPlugin.setup): a worker that failed it gives the case back to the
    scheduler (Dask's Reschedule) while it is retired. Never raises for a failing case: the row's status is
    "diverged" (the run left the envelope or stopped being finite), "failed" with the error,
    or "rejected" (not run) when reject_unstable and the stability check finds the loop not
    stable. ``publish`` ({"url", "case", "ssp"}): the case runs in a worker-local temporary folder
    and its files are written to URL/CASE/ by the worker (orchestrator.studies.publish), none come
    back; a case whose files cannot be written there is failed. The row carries the full metrics
    under "metrics" (not a CSV column). After
    stops.request_stop(stop_token) (the study was stopped) the case ends at a step boundary,
    or does not start, with status "interrupted" (never a study.csv row).
    """
    from ..engine.errors import DivergenceError
    from ..engine.loaded import process_fmus
    from ..tool.results import run_scenario
    from ..tool.stops import stop_requested
    from ..tool.stability import cached_check

    start = time.perf_counter()
    row = {"status": "failed", "error": "", "worker": f"{os.uname().nodename}:{os.getpid()}"}
    if stop_requested(stop_token):
        return dict(row, status="interrupted", error="not run: the study was stopped", wall_time_s=0.0)
    folder = None
    if plugin and getattr(this_plugin(plugin), "failed", None):
        from distributed import Reschedule
        raise Reschedule()  # this worker failed the study's check and is being retired: another runs the case
    try:
        if plugin:
            shipped = this_plugin(plugin)
            if shipped is None:
                raise StudyError(f"Dask worker {row['worker']} has not received the study's data (plugin {plugin}): "
                                 "it is not a worker of this study's scheduler")
            if ssp is None:
                ssp = shipped.ssp_path()
        if case_dir is None:  # data mode, or files published by this worker: a worker-local folder
            folder = case_folder()
            case_dir = folder / "case"
        scenario = case_scenario(base, changes, gain_files or {})
        report = cached_check(scenario)
        row["spectral_radius"] = report.spectral_radius
        if reject_unstable and not report.stable:
            row.update(status="rejected", error=f"not run: {report.verdict} (spectral radius "
                       f"{report.spectral_radius:.4g})")
        else:
            if not keep_results:  # rows that would be deleted: keep the first and last only (the metrics
                scenario = with_record_every(scenario, scenario.n_steps)  # use every step regardless)
            # the FMUs stay loaded in this worker and are reset between cases (engine.loaded)
            m = run_scenario(scenario, Path(ssp), Path(case_dir), overwrite=True, stop_token=stop_token,
                             loaded=process_fmus())
            row.update(_metric_columns(m), status="completed", metrics=m)
            if not keep_results:
                for name in ("results.csv", "results.mat"):  # either format (scenario key format)
                    (Path(case_dir) / name).unlink(missing_ok=True)
    except KeyboardInterrupt as err:  # the study was stopped (Dask lets this through and dies)
        row.update(status="interrupted", error=" ".join(str(err).split()))
    except Exception as err:  # a case's failure is its row, never the end of the study
        row["error"] = reason(err)
        if isinstance(err, DivergenceError):
            row["status"] = "diverged"
    if folder is not None:
        try:
            if publish:
                _publish(row, Path(case_dir), publish)
            else:
                row["files"] = pack_folder(Path(case_dir))
        finally:
            remove_case_folder(folder)
    row["flag"] = case_flag(row.get("spectral_radius"), row.get("saturation_fraction_max"))
    row["wall_time_s"] = time.perf_counter() - start
    return row


def run_batch(tasks: list, common: dict) -> list:
    """Run the cases of one batch in this process (a Dask worker), one after another; returns
    their rows in order. ``tasks``: per case {"changes", "case_dir", "gain_files", "publish"}; ``common``:
    the keyword arguments every case shares (study.run_case's base, ssp, keep_results,
    reject_unstable, stop_token, plugin). A case that fails is its row (run_case never raises for
    a case), so it fails alone; after a stop the remaining cases return "interrupted" at once."""
    return [run_case(changes=t["changes"], case_dir=t["case_dir"], gain_files=t["gain_files"],
                     publish=t.get("publish"), **common) for t in tasks]


def replace_fields(scenario: Scenario, **fields) -> Scenario:
    """A copy of ``scenario`` with top-level fields replaced and validated again, keeping the
    gains_file's values it has (Scenario.with_changes would read the file again)."""
    from ..tool.config import build
    from ..tool.scenario import ScenarioError
    return build(dataclasses.replace, ScenarioError, scenario, **fields)


def _publish(row: dict, folder: Path, publish: dict) -> None:
    """Write the case's files to publish["url"] (publish.publish_folder); on failure the row is
    failed, naming the location (its password hidden) and the error."""
    from .publish import publish_folder, shown
    if not folder.is_dir():
        return
    try:
        row["published_bytes"] = publish_folder(folder, publish["url"], publish["case"], publish["ssp"])
    except Exception as err:  # the location refused them: this case failed, the study goes on
        row.update(status="failed", error=f"its files could not be written to {shown(publish['url'])}: {reason(err)}")


def with_record_every(scenario: Scenario, every: int) -> Scenario:
    """A copy of the validated ``scenario`` recording every ``every``-th step (1 <= every <= its
    n_steps, valid by construction), without validating it all again (replace_fields: about 4 ms
    of a short case's worker time)."""
    import copy
    out = copy.copy(scenario)
    object.__setattr__(out, "record_every", int(every))  # object's: a pydantic dataclass validates on setattr
    return out


def reason(err: BaseException) -> str:
    """An error as one line for a row: its type and message (never empty)."""
    text = " ".join(str(err).split())
    return f"{type(err).__name__}: {text}" if text else f"{type(err).__name__} (no message)"


def case_scenario(base: dict, changes: dict, gain_files: dict) -> Scenario:
    """The case's scenario: ``base`` (scenario_data) with the dotted-key ``changes``, validated
    (ScenarioError "case: ..." names the key), reading no file: a gains_file the changes name
    takes its values from ``gain_files`` ({path: preset, or the error text of reading it}), the
    base's own from base["gain_file_values"]."""
    from ..tool.config import build
    from ..tool.scenario import ScenarioError
    fields = dict(base)
    for key, value in changes.items():
        section, dot, name = key.partition(".")
        if not dot:
            fields[key] = value
            continue
        table = dict(fields[section])
        table[name] = list(value) if isinstance(value, (list, tuple)) else value
        fields[section] = table
    if "gains_file" in changes:
        values = gain_files.get(changes["gains_file"], {}) if changes["gains_file"] else {}
        if isinstance(values, str):
            raise ScenarioError(f"case: {values}")
        fields["gain_file_values"] = values
    try:
        return build(Scenario, ScenarioError, **fields)
    except ScenarioError as err:
        raise ScenarioError(f"case: {err}") from None


def case_flag(spectral_radius: float | None, saturation_fraction_max: float | None) -> str:
    """The study.csv flag of a case: "unstable" (or "marginal") by the stability verdict of its
    spectral radius, "saturated" if a motor's force command is at the limit in more than
    SATURATION_FLAG of the samples; joined with "+", "" for neither (or unknown)."""
    from ..tool.stability import verdict_for
    flags = []
    if spectral_radius is not None and verdict_for(spectral_radius) != "stable":
        flags.append(verdict_for(spectral_radius))
    if saturation_fraction_max is not None and saturation_fraction_max > SATURATION_FLAG:
        flags.append("saturated")
    return "+".join(flags)


def _metric_columns(m: dict) -> dict:
    out = {"objective": objective(m), "tracking_mae_um_mean": float(np.mean(m["tracking_mae_um"])),
           "sync_mae_um_mean": float(np.mean(m["sync_mae_um"]))}
    for i in range(3):
        out[f"tracking_mae_um_{i + 1}"] = m["tracking_mae_um"][i]
        out[f"sync_mae_um_{i + 1}"] = m["sync_mae_um"][i]
    out["saturation_fraction_max"] = max(m["saturation_fraction"])
    return out


def scenario_data(scenario: Scenario) -> dict:
    """A scenario as plain data that crosses process boundaries (scenario.create(**data) rebuilds it)."""
    return dataclasses.asdict(scenario)


def open_client(scheduler: str | None = None, workers: int | None = None, timeout: float = 60.0):
    """A Dask client: on the cluster at ``scheduler`` (address; StudyError if it cannot be reached
    within ``timeout`` [s]), or on a new LocalCluster of ``workers`` single-threaded worker
    processes (default: one per core). Close it when done."""
    import dask
    from dask.distributed import Client, LocalCluster
    if scheduler:
        try:
            return Client(scheduler, timeout=timeout)
        except (OSError, ValueError, TypeError) as err:
            raise StudyError(f"--scheduler {scheduler}: cannot reach a Dask scheduler there within {timeout:g} s "
                             f"({reason(err)}): start one with `dask scheduler` and pass the address it prints "
                             "(tcp://HOST:8786)") from None
    n = workers or os.cpu_count() or 1
    _require(n >= 1, f"--workers = {n} is invalid: allowed is an integer >= 1")
    scratch = tempfile.mkdtemp(prefix="tapmp_dask_")  # Dask's scratch space, removed by close_client
    # The worker processes inherit the signal mask of the threads that start them (the cluster's
    # threads are started here): with SIGINT and SIGHUP blocked, a Ctrl-C or hangup sent to the
    # whole process group reaches only this client, which stops the running cases itself
    # (CaseRunner._stop) instead of workers dying with tracebacks. Signals that arrive meanwhile
    # stay pending and are delivered when the mask is restored.
    # multiprocessing's resource tracker (a process) ignores SIGINT and SIGTERM but not SIGHUP,
    # and when it starts it unblocks SIGINT in the thread that starts it: started here, with
    # SIGHUP blocked, it survives a hangup, and it is not started from the cluster's threads.
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, WORKER_BLOCKED_SIGNALS)
    try:
        resource_tracker.ensure_running()
        signal.pthread_sigmask(signal.SIG_BLOCK, WORKER_BLOCKED_SIGNALS)
        with dask.config.set({"temporary-directory": scratch}):  # the scheduler's scratch space too
            cluster = LocalCluster(n_workers=n, processes=True, threads_per_worker=1, dashboard_address=":0",
                                   silence_logs=40, local_directory=scratch)
    except BaseException:
        shutil.rmtree(scratch, ignore_errors=True)
        raise
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)
    client = Client(cluster, direct_to_workers=True)  # rows fetched from the worker, not through the scheduler
    client._tapmp_cluster = cluster  # closed with the client by close_client
    client._tapmp_scratch = scratch
    return client


WORKER_BLOCKED_SIGNALS = {signal.SIGINT, signal.SIGHUP}  # SIGTERM stays: the nanny ends workers with it


def close_client(client) -> None:
    """Close a client from open_client (and its LocalCluster and scratch folder, if it made them)."""
    cluster = getattr(client, "_tapmp_cluster", None)
    try:
        client.close()
        if cluster is not None:
            cluster.close()
    finally:
        scratch = getattr(client, "_tapmp_scratch", None)
        if scratch:
            shutil.rmtree(scratch, ignore_errors=True)


class StudyTable:
    """study.csv: one row per case, appended and flushed as cases finish."""

    def __init__(self, path: Path, param_columns: list):
        self.path = Path(path)
        self.columns = ["case", *param_columns, "status", *METRIC_COLUMNS, *TAIL_COLUMNS]
        self.rows = {}
        refuse_link(self.path)  # rows are appended: never through a link to a file elsewhere
        self.dropped = self._drop_cut_row()
        if self.path.exists():
            with open(self.path, newline="") as f:
                reader = csv.DictReader(f)
                _require(reader.fieldnames == self.columns,
                         f"{self.path} has columns {reader.fieldnames}, not those of this study "
                         f"({self.columns}): it was written by another study; use --overwrite")
                for row in reader:
                    _require(None not in row and None not in row.values(),
                             f"{self.path}: line {reader.line_num} does not have the {len(self.columns)} fields of "
                             "the header: the file is damaged; use --overwrite to start again")
                    self.rows[row["case"]] = row
        new = not self.path.exists()
        self.file = open(self.path, "a", newline="")
        self.writer = csv.DictWriter(self.file, self.columns, extrasaction="ignore")
        if new:
            self.writer.writeheader()
            self.file.flush()

    def _drop_cut_row(self) -> str:
        """Cut off a last row that was not written whole (no line end: the writer was killed or
        the disk was full), keeping the whole rows before it byte for byte; returns the cut text
        ("" if none). A line end is written only after a whole row (no field holds one)."""
        if not self.path.exists():
            return ""
        with open(self.path, "rb+") as f:
            data = f.read()
            keep = data.rfind(b"\n") + 1
            if keep == len(data):
                return ""
            f.truncate(keep)
        if keep == 0:  # not even the header was whole
            self.path.unlink()
        return data[keep:].decode(errors="replace")

    def add(self, case: dict, row: dict, flush: bool = True) -> None:
        """Append the case's row (written to the file by flush: a batch's rows are flushed together)."""
        full = {"case": case["case"], **case["params"], **row}
        self.writer.writerow({k: ("" if full.get(k) is None else full.get(k, "")) for k in self.columns})
        if flush:
            self.file.flush()
        self.rows[case["case"]] = full

    def flush(self) -> None:
        """Hand the rows added so far to the system (a killed client loses none of them; a cut last
        row, if the system itself stops mid-write, is dropped and its case run again by --resume)."""
        self.file.flush()

    def close(self) -> None:
        self.file.close()


STOP_WAIT_S = 60.0  # how long a stopped study waits for its running cases to end [s]
POLL_S = 0.05  # how often the client looks for finished batches when none is ready [s]
# What sets the size of a case's result file (tool.estimate.output_estimate), among the keys a case changes
TIMING_KEYS = ("start_time", "stop_time", "step", "record_every", "format")
FILES_ALLOWANCE_BYTES = 64 * 2**20  # for run.json + metrics.json: 4.0 kB in a 0.5 s case (docs/studies.md)
WATCH_S = 2.0  # how often it asks the scheduler whether any worker is left while it waits [s]


def rows_of_batch(batch: list, result) -> list[dict]:
    """The rows of a batch from what as_completed(with_results=True) gave back for its task: the
    list run_batch returned, or, for a task that could not run (its worker died too often, Dask
    cancelled it), one failed row per case naming what happened."""
    if isinstance(result, list) and len(result) == len(batch):
        return result
    if isinstance(result, tuple) and len(result) == 3 and isinstance(result[1], BaseException):
        error = reason(result[1])  # (type, exception, traceback) of a task that erred (KilledWorker, ...)
    elif isinstance(result, BaseException):
        error = "cancelled by Dask (its worker and its result were lost)"
    else:
        error = f"the worker sent {type(result).__name__} instead of the batch's {len(batch)} rows"
    return [{"status": "failed", "error": error} for _ in batch]


class CaseRunner:
    """Runs cases on a Dask client, in batches (orchestrator.studies.batches), and records their
    rows in a StudyTable.

    Batches are submitted through a bounded window (batches.window: a few per worker thread) and
    their rows gathered as they complete by Dask's as_completed(with_results=True) in the client's
    event loop, straight from the worker that holds them (the client is opened with
    direct_to_workers); the main thread takes whatever batches are done, writes their case files
    (data mode) and appends their rows to study.csv with one flush per batch. A batch's future is
    released as soon as its rows are recorded, so the scheduler forgets it: a worker lost
    afterwards never runs a recorded case again, and a worker lost before reruns only its
    batches not yet collected (Dask runs them again, once, elsewhere). While no worker is
    connected the runner says so once and waits. If the run is left by an exception (e.g.
    Interrupted by SIGTERM), the running cases are asked to stop at their next step boundary
    (stops.request_stop on every worker) and waited for, so they free their FMUs and temporary
    folders before the workers go, and the rows of the batches done meanwhile are recorded.
    ``batch_size``: cases per task, 0 for the rule of batches.batch_size. ``results_url``: the
    workers write the case files there (orchestrator.studies.publish), none come to the client.
    """

    def __init__(self, client, base: Scenario, ssp: Path, out: Path, table: StudyTable,
                 keep_results: bool, progress: bool = True, desc: str = "cases", ship: Shipping | None = None,
                 batch_size: int = 0, results_url: str = ""):
        self.client = client
        self.base_scenario = base
        self.base = scenario_data(base)
        self.ssp = str(Path(ssp).resolve())
        self.out = Path(out).resolve()
        self.table = table
        self.keep_results = keep_results
        self.progress = progress
        self.desc = desc
        self.ship = ship or Shipping()
        self.batch_size = batch_size
        self.results_url = results_url
        self.used_batch_size = 0  # the size of the last run's batches (cases per task)
        self.token = f"study-{os.getpid()}-{os.urandom(8).hex()}"
        self.bytes_received = 0  # compressed case files received (data mode) [bytes]
        self.retired = 0  # workers retired by the study's check (remote.retired_since) warned of so far
        self.threads = 0  # worker threads connected at the last look
        self.thread_cpu_s = 0.0  # CPU of the thread running the cases (submitting, recording rows) [s]
        self.process_cpu_s = 0.0  # CPU of this whole process meanwhile (Dask's event loop, a local scheduler) [s]

    def _submit(self, batch: list, reject_unstable: bool, gain_files: dict):
        from .batches import batch_key
        data = self.ship.data
        local = not (data or self.results_url)  # the worker writes the case's folder at the client's path
        tasks = []
        for case in batch:
            path = case["changes"].get("gains_file")
            tasks.append({"changes": case["changes"], "gain_files": {path: gain_files[path]} if path else None,
                          "case_dir": str(self.out / "cases" / case["case"]) if local else None,
                          "publish": {"url": self.results_url, "case": case["case"], "ssp": self.ssp}
                          if self.results_url else None})
        common = {"base": self.base, "ssp": None if data else self.ssp, "keep_results": self.keep_results,
                  "reject_unstable": reject_unstable, "stop_token": self.token, "plugin": self.ship.plugin}
        return self.client.submit(run_batch, tasks, common, pure=False, key=batch_key([c["case"] for c in batch]))

    def size_for(self, n_cases: int) -> int:
        """Cases per batch for ``n_cases`` cases: the runner's batch_size, else the rule of
        batches.batch_size from the base scenario's steps and the worker threads connected now."""
        from .batches import BATCH_FILES_BYTES, batch_size, case_seconds
        if self.batch_size:
            return self.batch_size
        size = batch_size(n_cases, case_seconds(self.base_scenario.n_steps), self.threads)
        if self.keep_results and self.ship.data and not self.results_url:  # result files come back: bound a batch's
            from ..tool.estimate import output_estimate
            size = min(size, max(1, BATCH_FILES_BYTES // max(output_estimate([self.base_scenario])[0], 1)))
        return size

    def run(self, cases: list, reject_unstable: bool = False, announce: bool = False) -> list:
        """Rows of ``cases`` in their order; cases that have a row already are not run again.
        ``announce``: say on stderr how the cases travel (batch size, tasks, worker threads)."""
        thread0, process0 = time.thread_time(), time.process_time()
        try:
            return self._run(cases, reject_unstable, announce)
        finally:
            self.thread_cpu_s += time.thread_time() - thread0
            self.process_cpu_s += time.process_time() - process0

    def _run(self, cases: list, reject_unstable: bool, announce: bool) -> list:
        """run's body."""
        from dask.distributed import as_completed
        from ..tool.progress import Progress
        from .batches import split, window

        rows = {c["case"]: self.table.rows[c["case"]] for c in cases if c["case"] in self.table.rows}
        todo = [c for c in cases if c["case"] not in rows]
        gain_files = gain_values_of(c["changes"].get("gains_file") for c in todo)
        # a bar on a terminal; elsewhere a line as cases complete (each tenth, or any case 10 s after
        # the last line) and the count again every 10 s while none does
        bar = Progress(self.desc, "case", len(cases), quiet_s=0.0, every_s=10.0) if self.progress else None
        if bar is not None:
            bar(len(rows))
        self.threads = sum(self.client.nthreads().values())
        self.used_batch_size = self.size_for(len(todo))
        if announce and todo:
            tasks = -(-len(todo) // self.used_batch_size)
            print(f"{self.desc}: {len(todo)} cases in batches of {self.used_batch_size} ({tasks} Dask tasks, "
                  f"{self.threads} worker threads{'' if self.batch_size else ', automatic size'})", file=sys.stderr,
                  flush=True)
        pending = iter(split(todo, self.used_batch_size))
        futures = {}  # future -> its batch (list of cases)
        done = as_completed(with_results=True, raise_errors=False)
        try:
            def submit() -> None:  # up to the window (also while no worker is connected: the scheduler queues)
                while len(futures) < window(self.threads):
                    batch = next(pending, None)
                    if batch is None:
                        return
                    fut = self._submit(batch, reject_unstable, gain_files)
                    futures[fut] = batch
                    done.add(fut)

            submit()
            waiting, watched = False, time.monotonic()
            while futures:
                finished = done.next_batch(block=False)
                if time.monotonic() - watched >= WATCH_S:  # also while rows come (a worker joining is checked)
                    waiting, watched = self._watch(waiting, len(todo) - len(rows)), time.monotonic()
                if not finished:
                    time.sleep(POLL_S)
                    continue
                for fut, result in finished:
                    batch = futures.pop(fut)
                    fut.release()
                    recorded = self._record_batch(batch, rows_of_batch(batch, result))
                    for c in recorded:
                        rows[c["case"]] = self.table.rows[c["case"]]
                    if bar is not None and recorded:
                        bar.update(len(recorded))
                submit()
            if self.ship.plugin:  # a worker retired since the last look
                self.retired = retired_since(self.client, self.ship.plugin, self.retired)
        except BaseException as err:
            self._stop(futures, getattr(err, "signum", signal.SIGTERM))
            raise
        finally:
            for fut in futures:
                fut.cancel()
            if bar is not None:
                bar.close()
        return [rows.get(c["case"], {"case": c["case"], "status": "interrupted"}) for c in cases]

    def _record_batch(self, batch: list, batch_rows: list) -> list:
        """Record the rows of a batch (those with a study.csv status: an interrupted case has none,
        --resume runs it) with one flush of study.csv; returns the cases recorded."""
        recorded = []
        for case, row in zip(batch, batch_rows):
            if row.get("status") not in STATUSES or case["case"] in self.table.rows:
                continue
            self._record(case, row, flush=False)
            recorded.append(case)
        self.table.flush()
        return recorded

    def _record(self, case: dict, row: dict, flush: bool = True) -> None:
        """The case's files into its folder (data mode), then its row into study.csv."""
        files = row.pop("files", None)
        if files:
            try:
                self.bytes_received += unpack_folder(files, self.out / "cases" / case["case"], self.ssp,
                                                     self._files_limit(case))
            except StudyError as err:  # the files a worker sent are refused: the case failed
                row = {"status": "failed", "error": str(err), "worker": row.get("worker", "")}
        self.table.add(case, row, flush)

    def _files_limit(self, case: dict) -> int:
        """The most bytes a case's files may hold uncompressed: twice its result file's estimated
        size (tool.estimate) and FILES_ALLOWANCE_BYTES for its run.json and metrics.json."""
        from ..tool.estimate import output_estimate
        timing = {k: case["changes"][k] for k in TIMING_KEYS if k in case["changes"]}
        scenario = replace_fields(self.base_scenario, **timing) if timing else self.base_scenario
        return 2 * output_estimate([scenario])[0] + FILES_ALLOWANCE_BYTES

    def _watch(self, waiting: bool, left: int) -> bool:
        """Say once that no worker is connected (and the study waits for one), and warn of each
        worker retired by the study's check since the last look; returns whether none is connected."""
        if self.ship.plugin:
            self.retired = retired_since(self.client, self.ship.plugin, self.retired)
        self.threads = sum(self.client.nthreads().values())
        none = not self.threads
        if none and not waiting:
            where = f"the scheduler at {self.ship.address}" if self.ship.address else "the cluster"
            print(f"{self.desc}: no Dask worker is connected to {where}; waiting for workers ({left} cases "
                  "left; SIGINT or SIGTERM ends the study, --resume runs the rest)", file=sys.stderr)
        return none

    def _stop(self, futures: dict, signum: int) -> None:
        """Stop the running cases (request_stop on every worker), wait up to STOP_WAIT_S for
        them (not at all when no worker is left), and record the rows of the batches that
        finished meanwhile (each batch's cases that ran before the stop)."""
        from dask.distributed import wait

        from ..tool.stops import request_stop
        try:
            if self.client.nthreads():
                self.client.run(request_stop, self.token, signum, on_error="ignore")
                wait(list(futures), timeout=STOP_WAIT_S)
        except Exception:
            pass  # a worker that does not answer is ended with the cluster
        for fut, batch in futures.items():
            if fut.status == "finished":
                try:
                    result = fut.result(timeout=STOP_WAIT_S / 6)
                except Exception:
                    continue  # its worker is gone: --resume runs the cases
                self._record_batch(batch, rows_of_batch(batch, result))


def fingerprint(study: Study, case_list: list) -> str:
    """A hash of what the study runs: its cases and base scenario (resume refuses another)."""
    text = json.dumps({"base": scenario_data(study.base_scenario()), "cases": case_list,
                       "tune": study.tune, "keep": study.keep_results}, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def prepare(study: Study, out: Path, resume: bool, overwrite: bool, fp: str) -> None:
    """Create the output folder, or check it for --resume; StudyError if it is in the way."""
    csv_path = out / STUDY_CSV
    meta = out / STUDY_JSON
    if resume:
        # only study.json's fingerprint shows that the rows there are this study's: without it, none are taken
        _require(meta.exists(), f"--resume: {out} has no {STUDY_JSON}, so nothing shows that its rows are this "
                 f"study's: run without --resume to start the study (--overwrite replaces a {STUDY_CSV} there)")
        old = _recorded_fingerprint(meta)
        _require(old == fp, f"--resume: {out} holds a different study (fingerprint {old}, this one {fp}); "
                 "the study file or its base scenario changed: run it into another --out or pass --overwrite")
        return
    if csv_path.exists():
        _require(overwrite, f"output folder {out} already holds {STUDY_CSV}: pass --resume to run only the "
                 "missing cases, --overwrite to start again, or --out for another folder")
        csv_path.unlink()
        shutil.rmtree(out / "cases", ignore_errors=True)
    out.mkdir(parents=True, exist_ok=True)


def drop_failed_rows(path: Path) -> int:
    """Remove the rows of status "failed" from the study.csv ``path`` so that --resume runs their
    cases again; the other lines stay byte for byte. The file is replaced atomically (a crash
    leaves the old table or the new one, whose missing cases --resume runs). Returns the rows removed."""
    from ..tool.folders import atomic_file
    if not path.exists():
        return 0
    lines = path.read_bytes().splitlines(keepends=True)  # a line end only ever ends a whole row (StudyTable)
    if not lines:
        return 0
    def failed(line: bytes) -> bool:
        fields = next(csv.reader([line.decode(errors="replace")]), [])
        return len(fields) == len(header) and fields[header.index("status")] == "failed"

    header = next(csv.reader([lines[0].decode(errors="replace")]), [])
    if "status" not in header:
        return 0  # not a study table: StudyTable refuses it
    keep = [line for line in lines if not failed(line)]
    if len(keep) == len(lines):
        return 0
    with atomic_file(path, "wb") as f:
        f.writelines(keep)
    return len(lines) - len(keep)


def _recorded_fingerprint(meta: Path) -> str:
    """The fingerprint recorded in a study.json; StudyError if the file is damaged."""
    try:
        info = json.loads(meta.read_text())
    except (OSError, UnicodeDecodeError, ValueError) as err:
        info = err
    fp = info.get("fingerprint") if isinstance(info, dict) else None
    _require(isinstance(fp, str), f"--resume: {meta} is damaged ("
             + (f"{type(info).__name__}: {' '.join(str(info).split())}" if isinstance(info, Exception)
                else "no fingerprint recorded") + "): the study cannot be matched with it; pass --overwrite to "
             "start again")
    return fp


def read_study_csv(path) -> list[dict]:
    """Rows of a study.csv with numbers as floats (empty cells as None)."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    for row in rows:
        for k, v in row.items():
            if k in ("case", "status", "flag", "error", "worker", "law", "ordering", "gains", "gains_file"):
                continue
            try:
                row[k] = float(v) if v != "" else None
            except ValueError:
                pass
    return rows


__all__ = ["Study", "StudyError", "load_study", "cases", "run_case", "open_client",
           "close_client", "objective", "read_study_csv"]
