"""Running a study: lock its folder, then a sweep (grid or Monte Carlo) or a tuning.

Kept apart from study.py so the layers stay one-way: study (specification, cases,
the runner) <- study_plots <- tuning <- run.
"""

import sys
import time
from pathlib import Path

from ..experiments.folders import output_lock, write_json
from .study import (STATUSES, STUDY_CSV, STUDY_JSON, CaseRunner, Study, StudyError, StudyTable, cases,
                    fingerprint, prepare)
from .study_plots import plot_study
from .tuning import run_tuning


def run_study(study: Study, ssp: Path, client, out: Path | None = None, resume: bool = False,
              overwrite: bool = False, progress: bool = True, command: str = "", write_docs: bool = False) -> dict:
    """Run a study on a Dask client; returns a summary (counts, paths, wall time). The
    output folder is locked for the whole study (results.OutputInUseError if in use).
    write_docs: a tuning writes its presets and comparison into its write_to folder (else out/tuning)."""
    ssp = Path(ssp)
    if not ssp.exists():
        raise StudyError(f"SSP file {ssp} does not exist: build the FMUs first (bash build_fmus.sh, or "
                         "tapmp build) or pass --ssp")
    out = Path(out or study.output)
    with output_lock(out):  # one writer per study folder (cases lock their own folders)
        if study.tune:
            return run_tuning(study, ssp, client, out, resume, overwrite, progress, command, write_docs)
        return _run_cases(study, ssp, client, out, resume, overwrite, progress, command)


def _run_cases(study: Study, ssp: Path, client, out: Path, resume: bool, overwrite: bool, progress: bool,
               command: str) -> dict:
    """run_study for a grid / Monte Carlo study, in the locked output folder ``out``."""
    case_list = cases(study)
    fp = fingerprint(study, case_list)
    prepare(study, out, resume, overwrite, fp)
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
    try:
        rows = CaseRunner(client, study.base_scenario(), ssp, out, table, study.keep_results,
                          progress, study.name).run(case_list)
    finally:
        table.close()
    wall = time.perf_counter() - start
    figures = plot_study(out, study, params)
    counts = {s: sum(r["status"] == s for r in rows) for s in STATUSES}
    return {"out": out, "cases": len(case_list), "ran": len(case_list) - done_before, "counts": counts,
            "wall_time_s": wall, "figures": figures}
