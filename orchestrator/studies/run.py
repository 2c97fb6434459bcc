"""Running a study: lock its folder, then a sweep (grid or Monte Carlo) or a tuning.

Kept apart from study.py so the layers stay one-way: study (specification, cases,
the runner) <- study_plots <- tuning <- run.
"""

import sys
import time
from contextlib import nullcontext
from pathlib import Path

from ..tool.folders import output_lock, write_json
from .study import (MAX_CASES, STATUSES, STUDY_CSV, STUDY_JSON, CaseRunner, Shipping, Study, StudyError,
                    StudyTable, cases, drop_failed_rows, fingerprint, prepare)
from .study_plots import plot_study
from .tuning import run_tuning


def run_study(study: Study, ssp: Path, client, out: Path | None = None, resume: bool = False,
              overwrite: bool = False, progress: bool = True, command: str = "", write_docs: bool = False,
              remote: dict | None = None, max_cases: int = MAX_CASES, case_list: list | None = None,
              retry_failed: bool = False, reference: dict | None = None, batch_size: int = 0,
              results_url: str = "") -> dict:
    """Run a study on a Dask client; returns a summary (counts by status, paths, wall time,
    bytes of case files received, the batch size, the CPU of the thread that ran the cases and
    of this whole process meanwhile [s]). The output folder is locked for the whole study
    (results.OutputInUseError if in use).
    write_docs: a tuning writes its presets and comparison into its write_to folder (else out/tuning).
    remote: for a client of a running scheduler, {"address": str, "data": bool (False: the workers
    share the client's files, --shared-fs), "timeout": how long to wait for a worker [s]}; the
    workers are checked before the first case (orchestrator.studies.remote.shipping).
    max_cases: a grid / Monte Carlo study with more cases is refused (StudyError). case_list: the
    study's cases (study.cases) if the caller has listed them already. retry_failed (with resume, a
    grid / Monte Carlo study): the cases whose row says "failed" run again, their rows replaced.
    reference: a tuning's published rows for comparison.md, laid out as
    orchestrator.tool.report.comparison_tables takes them (the caller's: studies know no paper).
    batch_size: cases per Dask task of a grid / Monte Carlo study, 0 for the rule of
    orchestrator.studies.batches.batch_size (the summary's "batch_size" is the one used).
    results_url: a grid / Monte Carlo study's case files written there by the workers
    (orchestrator.studies.publish, checked before the first case), not into out/cases."""
    ssp = Path(ssp)
    if not ssp.is_file():
        raise StudyError(f"SSP file {ssp} does not exist: build the FMUs first (bash build_fmus.sh, or "
                         "tapmp build) or pass --ssp")
    out = Path(out or study.output)
    if results_url:
        if study.tune:
            raise StudyError("--results-url is for a grid or Monte Carlo study: a tuning reads its cases' files")
        from .publish import check_location
        check_location(results_url)
    if not study.tune and case_list is None:
        case_list = cases(study, max_cases)  # before anything is written or sent
    if remote:
        from .remote import shipping
        ship = shipping(client, ssp, remote["address"], remote["data"], remote["timeout"])
    else:
        ship = nullcontext(Shipping())
    with output_lock(out), ship as ship:  # one writer per study folder (cases lock their own folders)
        if study.tune:
            return run_tuning(study, ssp, client, out, resume, overwrite, progress, command, write_docs, ship,
                              reference)
        return _run_cases(study, case_list, ssp, client, out, resume, overwrite, progress, command, ship,
                          retry_failed, batch_size, results_url)


def _run_cases(study: Study, case_list: list, ssp: Path, client, out: Path, resume: bool, overwrite: bool,
               progress: bool, command: str, ship: Shipping, retry_failed: bool = False, batch_size: int = 0,
               results_url: str = "") -> dict:
    """run_study for a grid / Monte Carlo study, in the locked output folder ``out``."""
    fp = fingerprint(study, case_list)
    prepare(study, out, resume, overwrite, fp)
    if resume and retry_failed:
        drop_failed_rows(out / STUDY_CSV)
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / STUDY_JSON, {"name": study.name, "source": study.source, "kind": study.kind,
                                  "fingerprint": fp, "command": command, "cases": case_list})
    params = list(case_list[0]["params"])
    table = StudyTable(out / STUDY_CSV, params)
    if table.dropped:
        print(f"note: the last row of {out / STUDY_CSV} was cut ({len(table.dropped)} characters without a line "
              "end, e.g. the study was killed while writing it): dropped, its case runs again", file=sys.stderr)
    done_before = len(table.rows)
    start = time.perf_counter()
    runner = CaseRunner(client, study.base_scenario(), ssp, out, table, study.keep_results, progress, study.name,
                        ship, batch_size, results_url)
    try:
        rows = runner.run(case_list, announce=progress)
    finally:
        table.close()
    wall = time.perf_counter() - start
    if progress:
        print(f"{study.name}: the figures -> {out}", file=sys.stderr, flush=True)  # seconds on a loaded machine
    figures = plot_study(out, study, params)
    counts = {s: sum(r["status"] == s for r in rows) for s in STATUSES}
    # ran, but the stability check finds their sampled loop unstable (study.csv's flag column)
    unstable = sum("unstable" in str(r.get("flag") or "").split("+") for r in rows)
    return {"out": out, "cases": len(case_list), "ran": len(case_list) - done_before, "counts": counts,
            "unstable": unstable, "wall_time_s": wall, "figures": figures, "bytes_received": runner.bytes_received,
            "batch_size": runner.used_batch_size, "client_cpu_s": runner.thread_cpu_s,
            "client_process_cpu_s": runner.process_cpu_s}
