"""The compare workflow (`tapmp compare`, and every comparison of `tapmp reproduce`): run a
scenario with SC-DC, APD-DC and the fair baselines (orchestrator.tool.baselines) into one
comparison folder, each run in its subfolder, then write comparison.md and the figures.
"""

import json
import sys
from contextlib import contextmanager
from pathlib import Path

from .estimate import check_output_size
from .folders import (ResultsWriteError, check_output, output_lock, prepare_output, record_files,
                      write_comparison_status, write_text, writes)
from .progress import progress_bar, say
from .scenario import MAX_INT
from .results import one_line


@contextmanager
def comparison_folder(out: Path, overwrite: bool, scenario, runs: dict, written_by: str = "compare"):
    """Hold and prepare ``out`` as a comparison folder of ``runs`` ({folder name: scenario})
    for the duration; comparison.json records "running", then "completed", or "failed" /
    "interrupted" with the error. A completed comparison there is kept unless ``overwrite``;
    an unfinished one is replaced, its runs with it; a folder tapmp did not mark is refused
    unless empty (see folders.check_output). comparison.json records ``written_by``, the command
    ("compare" or "reproduce") that wrote it, and the files the comparison wrote at the top of the
    folder (folders.writes: comparison.md and the figures; check_output refused any other file of
    those names there, so each one there at the end is the comparison's)."""
    laws = {name: sc.law for name, sc in runs.items()}
    # before the lock file is made: a refused folder stays as it was
    check_output(out, overwrite, "comparison", laws, unmarked_only=True)
    with output_lock(out):
        prepare_output(out, overwrite, "comparison", laws)
        files = {}
        write_comparison_status(out, scenario.name, laws, "running", files, written_by=written_by)
        try:
            yield out
        except BaseException as err:
            status = "interrupted" if isinstance(err, KeyboardInterrupt) else "failed"
            try:
                record_files(out, files, writes("comparison"))
                write_comparison_status(out, scenario.name, laws, status, files, error=one_line(err),
                                        written_by=written_by)
            except (OSError, ResultsWriteError):
                pass  # e.g. a full disk: the error itself is raised all the same
            raise
        record_files(out, files, writes("comparison"))
        write_comparison_status(out, scenario.name, laws, "completed", files, written_by=written_by)


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


NOISE_LEVELS = (20e-9, 100e-9)  # [m] rms of the measurement noise of the noise runs
NOISE_SEED = 1                  # the same noise sequence for every law, so the laws see the same measurements
NOISE_RUNS = ("sc-dc", "apd-dc", "apd-dc-mode-matched", "apd-dc-ms-matched", "pid-dc-full")
NOISE_FOLDER = "noise"          # out/noise/<run>-<level>nm: the noise runs of a comparison folder


def _nm(level: float) -> str:
    return f"{1e9 * level:g}"


def noise_runs(runs: dict) -> dict:
    """{folder name "<run>-<rms>nm": Scenario}: each NOISE_RUNS run of ``runs`` ({name: Scenario},
    compare_runs) again at each NOISE_LEVELS rms [m] of white measurement noise (the plant's
    noise_rms, noise_seed NOISE_SEED), nothing else changed but the recording: only the first and
    last rows are kept on disk (the metrics are computed at every step all the same)."""
    out = {}
    for run in NOISE_RUNS:
        if run in runs:
            sc = runs[run]
            for level in NOISE_LEVELS:
                out[f"{run}-{_nm(level)}nm"] = sc.with_changes(
                    plant={**sc.plant, "noise_rms": level, "noise_seed": NOISE_SEED},
                    record_every=min(sc.n_steps, MAX_INT), format="csv")
    return out


def read_noise(out: Path, results: dict) -> dict:
    """{run: {rms [m]: metrics}} of a comparison folder's noise runs, read from their metrics.json
    (out/noise/<run>-<rms>nm); the rms 0 is the run's own metrics in ``results`` ({run: metrics}).
    Runs without noise runs there are left out."""
    noise = {}
    for run in NOISE_RUNS:
        files = [Path(out) / NOISE_FOLDER / f"{run}-{_nm(level)}nm" / "metrics.json" for level in NOISE_LEVELS]
        if run in results and all(f.is_file() for f in files):
            noise[run] = {0.0: results[run], **{level: json.loads(f.read_text())
                                                 for level, f in zip(NOISE_LEVELS, files)}}
    return noise


def _mean(v) -> float:
    return sum(v) / len(v)


def _reduction(base: float, new: float) -> float:
    return 100.0 * (base - new) / base if base else float("nan")


def noise_table(noise: dict, own_rms: float = 0.0) -> list[str]:
    """Markdown lines: per noise run ({run: {rms [m]: metrics}}, read_noise), mean tracking and sync
    MAE [um] and force RMS above the effort band [N] at each rms, SC-DC's sync reduction against the
    run at each rms [%], and one sentence on SC-DC's advantage over the robustness-matched PD.
    own_rms [m]: the noise_rms of the compared scenario itself (its runs are the first column)."""
    if "sc-dc" not in noise:  # no noise runs (compare --no-noise): no table
        return []
    levels = (0.0, *NOISE_LEVELS)
    head = ", ".join(_nm(x) for x in (own_rms, *NOISE_LEVELS)) + " nm"
    sc = noise["sc-dc"]
    hz = sc[0.0].get("force_rms_above_hz")
    lines = [f"| run | tracking MAE [um] at {head} | sync MAE [um] at {head} | force RMS above "
             + (f"{hz:g} Hz" if hz else "the band") + f" [N], mean over the motors, at {head} "
             f"| SC-DC's sync reduction [%] at {head} |", "|---" * 5 + "|"]
    for run, by in noise.items():
        t = ", ".join(f"{_mean(by[x]['tracking_mae_um']):.4f}" for x in levels)
        y = ", ".join(f"{_mean(by[x]['sync_mae_um']):.4f}" for x in levels)
        f = ", ".join(f"{_mean(by[x]['force_hf_rms_n']):.3g}" if by[x].get("force_hf_rms_n") else "n/a"
                      for x in levels)
        r = ", ".join(f"{_reduction(_mean(by[x]['sync_mae_um']), _mean(sc[x]['sync_mae_um'])):+.1f}" for x in levels)
        lines.append(f"| `{run}` | {t} | {y} | {f} | {r} |")
    if "apd-dc-ms-matched" in noise:
        ms = noise["apd-dc-ms-matched"]
        r0, r1 = (_reduction(_mean(ms[x]["sync_mae_um"]), _mean(sc[x]["sync_mae_um"])) for x in (0.0, levels[-1]))
        lines += ["", f"SC-DC's synchronization advantage over the robustness-matched PD is {r0:+.1f} % "
                  + ("without noise" if not own_rms else f"at {_nm(own_rms)} nm rms (the scenario's own)")
                  + f" and {r1:+.1f} % at {_nm(levels[-1])} nm rms."]
    return lines


def noise_intro() -> str:
    """The sentence that says what the noise runs are (comparison.md, docs/paper-reproduction.md)."""
    return (f"The runs {', '.join(f'`{r}`' for r in NOISE_RUNS)} again with white Gaussian noise on every "
            "measured position before quantization (docs/disturbances.md), rms "
            + " and ".join(f"{_nm(x)} nm" for x in NOISE_LEVELS) + f", seed {NOISE_SEED} (the same noise for "
            f"every law); the first value is the run itself, at its scenario's own noise_rms (0 nm unless the "
            f"scenario sets one). Each noise run is its run with the plant's `noise_rms` and "
            f"`noise_seed` set, nothing else changed (its folder: `{NOISE_FOLDER}/<run>-<rms>nm`).")


def noise_tasks(runs: dict, ssp, out: Path) -> dict:
    """{out/noise/<name> relative name: (scenario, ssp, folder)} of noise_runs(runs) on the SSP
    file ``ssp``, as pool.run_many takes them."""
    return {f"{NOISE_FOLDER}/{name}": (sc, ssp, Path(out) / NOISE_FOLDER / name)
            for name, sc in noise_runs(runs).items()}


def run_comparison(scenario, ssp, out: Path, overwrite: bool, progress: bool, command: str, jobs: int = 1,
                   show: list | None = None, figures: bool = True, written_by: str = "compare",
                   noise: bool = True, reference: dict | None = None):
    """Run every compare run of ``scenario`` on the SSP file ``ssp`` into out/<run> (on ``jobs``
    processes, a progress bar each if ``progress``), and if ``noise`` the noise runs (noise_runs)
    into out/noise/; write out/comparison.md (naming ``command``; with the noise table) and, if
    ``figures``, the figures (of the runs ``show``, default see plots.select_runs); returns (runs,
    results, checks, comparison.md text). ``written_by``: the command, recorded in comparison.json
    (`tapmp reproduce` replaces only the comparisons it wrote); ``reference``: rows shown beside
    ours in comparison.md (report.comparison_tables)."""
    from .baselines import compare_runs  # on first use: the command line starts without the models' algebra
    from .pool import run_many
    from .report import AnalysisAside, write_comparison

    runs = compare_runs(scenario)
    # before anything is written
    check_output_size([*runs.values(), *(noise_runs(runs).values() if noise else ())], out, scenario.name, jobs)
    checks = check_runs(runs)
    with comparison_folder(out, overwrite, scenario, runs, written_by):  # runs in subfolders; comparison.md, figures here
        say(f"{scenario.name}: {len(runs)} runs of {scenario.stop_time - scenario.start_time:g} s "
            f"({scenario.n_steps} steps, {scenario.format}) on {min(jobs, len(runs))} process(es) -> {out}")
        noisy = noise_tasks(runs, ssp, out) if noise else {}
        if noisy:
            say(f"{scenario.name}: the noise runs ({len(noisy)} runs at "
                + ", ".join(_nm(x) for x in NOISE_LEVELS) + " nm rms)")
        bars = (lambda name: progress_bar(f"{scenario.name} {name}", True)) if progress else None
        drawing = _FiguresDuringRuns(out, list(runs), show) if figures else None
        aside = AnalysisAside(runs, jobs) if jobs > 1 else None  # the robustness section, computed meanwhile
        try:
            # One pool for the runs and the noise runs, the figures' runs first: the figures are drawn
            # while the others go on. Only the rows of the runs the figures need come back here.
            records = run_many({**{name: (sc, ssp, out / name) for name, sc in runs.items()}, **noisy}, jobs,
                               drawing.needed if figures else False, bars, scenario.name,
                               first=drawing.needed if drawing else (),
                               on_record=drawing.record if drawing else None, idle=drawing.idle if drawing else None)
            if aside is not None:
                aside.keep()
        finally:
            if aside is not None:
                aside.close()
        results = {name: records[name]["metrics"] for name in runs}
        text = write_comparison(out / "comparison.md", scenario, results, command, runs, checks, reference)
        if noise:
            text += "\n".join(["", "## Measurement noise: SC-DC, APD-DC and the matched baselines", "",
                                noise_intro(), "",
                                *noise_table(read_noise(out, results), float(scenario.plant.get("noise_rms", 0.0))),
                                ""])
            write_text(out / "comparison.md", text)
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
