"""The compare workflow (`tapmp compare`, and every comparison of `tapmp reproduce`): run a
scenario with SC-DC, APD-DC and the fair baselines (orchestrator.tool.baselines) into one
comparison folder, each run in its subfolder, then write comparison.md and the figures.
"""

import json
import sys
from contextlib import contextmanager
from pathlib import Path

from .estimate import check_output_size
from .folders import ResultsWriteError, check_output, output_lock, prepare_output, write_comparison_status
from .progress import progress_bar, say
from .results import one_line


@contextmanager
def comparison_folder(out: Path, overwrite: bool, scenario, runs: dict, written_by: str = "compare"):
    """Hold and prepare ``out`` as a comparison folder of ``runs`` ({folder name: scenario})
    for the duration; comparison.json records "running", then "completed", or "failed" /
    "interrupted" with the error. A completed comparison there is kept unless ``overwrite``;
    an unfinished one is replaced, its runs with it; a folder tapmp did not mark is refused
    unless empty (see folders.check_output). comparison.json records ``written_by``, the command
    ("compare" or "reproduce") that wrote it."""
    laws = {name: sc.law for name, sc in runs.items()}
    # before the lock file is made: a refused folder stays as it was
    check_output(out, overwrite, "comparison", laws, unmarked_only=True)
    with output_lock(out):
        prepare_output(out, overwrite, "comparison", laws)
        write_comparison_status(out, scenario.name, laws, "running", written_by=written_by)
        try:
            yield out
        except BaseException as err:
            status = "interrupted" if isinstance(err, KeyboardInterrupt) else "failed"
            try:
                write_comparison_status(out, scenario.name, laws, status, error=one_line(err),
                                        written_by=written_by)
            except (OSError, ResultsWriteError):
                pass  # e.g. a full disk: the error itself is raised all the same
            raise
        write_comparison_status(out, scenario.name, laws, "completed", written_by=written_by)


def check_runs(runs: dict) -> dict:
    """The stability pre-check of every run ({name: StabilityReport}); one warning line on stderr
    for each run that is not stable (it runs anyway)."""
    from .stability import check, radius_text
    checks = {}
    for name, sc in runs.items():
        r = checks[name] = check(sc)
        if not r.stable:
            print(f"warning: {sc.name} {name}: the sampled closed loop is {r.verdict} (spectral radius "
                  f"{radius_text(r.spectral_radius)}, stable needs < 1 - 1e-6); it runs anyway", file=sys.stderr, flush=True)
    return checks


def run_columns(folder: Path) -> list:
    """The columns a run recorded (its run.json)."""
    return json.loads((Path(folder) / "run.json").read_text())["columns"]


def run_comparison(scenario, ssp, out: Path, overwrite: bool, progress: bool, command: str, jobs: int = 1,
                   show: list | None = None, figures: bool = True, written_by: str = "compare",
                   reference: dict | None = None):
    """Run every compare run of ``scenario`` on the SSP file ``ssp`` into out/<run> (on ``jobs``
    processes, a progress bar each if ``progress``), write out/comparison.md (naming ``command``)
    and, if ``figures``, the figures (of the runs ``show``, default see plots.select_runs);
    returns (runs, results, checks, comparison.md text). ``written_by``: the command, recorded in
    comparison.json (`tapmp reproduce` replaces only the comparisons it wrote); ``reference``: rows
    shown beside ours in comparison.md (report.comparison_tables)."""
    from .baselines import compare_runs  # on first use: the command line starts without the models' algebra
    from .pool import run_many
    from .report import write_comparison

    runs = compare_runs(scenario)
    check_output_size(runs.values(), out, scenario.name, jobs)  # before anything is written
    checks = check_runs(runs)
    with comparison_folder(out, overwrite, scenario, runs, written_by):  # runs in subfolders; comparison.md, figures here
        say(f"{scenario.name}: {len(runs)} runs of {scenario.stop_time - scenario.start_time:g} s "
            f"({scenario.n_steps} steps, {scenario.format}) on {min(jobs, len(runs))} process(es) -> {out}")
        bars = (lambda name: progress_bar(f"{scenario.name} {name}", True)) if progress else None
        drawing = _FiguresDuringRuns(out, list(runs), show) if figures else None
        # without figures the runs' rows stay in the workers (no copy back to this process)
        records = run_many({name: (sc, ssp, out / name) for name, sc in runs.items()}, jobs, figures, bars,
                           scenario.name, first=drawing.needed if drawing else (),
                           on_record=drawing.record if drawing else None, idle=drawing.idle if drawing else None)
        results = {name: r["metrics"] for name, r in records.items()}
        text = write_comparison(out / "comparison.md", scenario, results, command, runs, checks, reference)
        if not figures:
            return runs, results, checks, text
        say(f"{scenario.name}: figures")
        drawing.finish(jobs)
    return runs, results, checks, text


class _FiguresDuringRuns:
    """A comparison's figures drawn as soon as the runs they show have ended: the pool starts
    those runs first, and this process, which otherwise only waits, draws one figure at a time
    while the other runs go on; what is left is drawn on every core when all have ended."""

    def __init__(self, out: Path, names: list, show):
        from .plots import figure_runs
        self.out, self.names, self.show = out, names, show
        self.needed = figure_runs(names, show)
        self.rows = {}
        self.figures = None
        self.failed = False  # a figure failed while the runs went on: it is drawn (and fails) again at the end

    def record(self, name: str, record: dict) -> None:
        if record.get("rows") is not None:
            self.rows[name] = (run_columns(self.out / name), record["rows"])

    def _ready(self) -> bool:
        if self.figures is None and all(n in self.rows for n in self.needed):
            from .plots import FigureSet
            self.figures = FigureSet(self.out, self.rows, self.show, self.names)
        return self.figures is not None

    def idle(self) -> None:
        if self.failed:
            return
        try:
            if self._ready():
                self.figures.draw_next()
        except Exception:  # noqa: B902  (raised at the end, after comparison.md, where it always was)
            self.failed = True

    def finish(self, jobs: int) -> None:
        from .plots import FigureSet
        if self.figures is None or self.failed:  # rows too large to keep (read from the files), or a failure
            self.figures = FigureSet(self.out, self.rows, self.show, self.names)
        self.figures.draw_rest(jobs)
