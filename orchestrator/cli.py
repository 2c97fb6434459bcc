"""Command-line tool ``tapmp`` (also ``python -m orchestrator``)."""

import argparse
import math
import os
import shlex
import signal
import sys
import threading
import traceback
from contextlib import contextmanager
from pathlib import Path

from ctoolchain import PLATFORMS

from .builder.families import (DEFAULT_FAMILY, ENV as FMUS_DIR_ENV, FAMILIES, SCENARIOS_DIR, data_dir,
                               default_build_dir, resolve_ssp)
from .errors import UsageError

# Only light modules above: `tapmp --help` and a refused option print before numpy, fmpy, pydantic
# or matplotlib are loaded; each command imports what it runs.


def user_errors() -> tuple:
    """What `tapmp` prints as one line (exit code 2): bad input (an option, a file's content), a run
    or build that failed for a reason it names, and OSError (a file or folder the user named, a full
    disk, a scheduler address). Every other exception is a programming error and shows its traceback."""
    from tapmp.errors import ModelInputError
    from tapmp.cmodel import CModelError
    from ctoolchain import CacheTrustError
    from .builder.build import BuildError
    from .builder.build_native import NativeBuildError
    from .engine.master import CoSimulationError
    from .engine.schedule import ScheduleError
    from .engine.ssd import ParameterAddressError
    from .tool.export import ExportError
    from .tool.folders import OutputExistsError, OutputInUseError, ResultsWriteError
    from .tool.reading import ResultFolderError
    from .tool.scenario import ScenarioError
    from .studies.study_file import StudyError
    return (UsageError, ScenarioError, StudyError, ExportError, ScheduleError, ParameterAddressError,
            ModelInputError, ResultFolderError, CoSimulationError, OutputExistsError, OutputInUseError,
            ResultsWriteError, BuildError, NativeBuildError, CModelError, CacheTrustError, OSError)


def __getattr__(name):
    """``USER_ERRORS``: :func:`user_errors`, imported only when asked for."""
    if name == "USER_ERRORS":
        return user_errors()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _family(value: str) -> str:
    """--fmus: a family name, else the one-line refusal with the closest names."""
    if value not in FAMILIES:
        from tapmp.errors import allowed_are
        raise argparse.ArgumentTypeError(f"fmus = {value!r} is invalid: {allowed_are(value, FAMILIES)}")
    return value


# The result file formats (tool.scenario.RESULT_FORMATS, which loads pydantic and numpy;
# tests/cli/test_cli_parser.py checks the two agree).
RESULT_FORMATS = ("csv", "mat")


def _result_format(value: str) -> str:
    """--format: a result file format, else the one-line refusal with the closest names."""
    if value not in RESULT_FORMATS:
        from tapmp.errors import allowed_are
        raise argparse.ArgumentTypeError(f"format = {value!r} is invalid: {allowed_are(value, RESULT_FORMATS)}")
    return value


def _ssp(args, scenario=None) -> Path:
    """--ssp, else the SSP of --fmus, else of the scenario's ``fmus`` (default native)."""
    fmus = args.fmus or (scenario.fmus if scenario is not None else DEFAULT_FAMILY)
    return resolve_ssp(args.ssp, fmus, getattr(args, "fmus_dir", None))


def shipped_names(kind: str) -> list[str]:
    """The names of the files shipped with the package of ``kind`` "scenarios" or "studies"."""
    return sorted(f.stem for f in data_dir(kind).glob("*.toml"))


def named_file(name: str, kind: str) -> str:
    """A scenario or study argument (``kind`` "scenarios" or "studies"): a file path, or the name of
    a file shipped with the package (``paper_simulation``, ``gain_sweep``) if no such file exists.
    Neither: UsageError listing the shipped names and the closest ones."""
    from tapmp.errors import suggestion
    path = Path(name)
    if path.exists():
        return name
    shipped = data_dir(kind) / f"{name}.toml"
    if not path.suffix and len(path.parts) == 1 and shipped.is_file():
        return str(shipped)
    what = kind[:-1] if kind == "scenarios" else "study"
    names = shipped_names(kind)
    raise UsageError(f"{what} {name!r} is neither a file nor a shipped {what}: shipped are {', '.join(names)}"
                     f"{suggestion(path.stem, names)}")


def scenario_file(name: str) -> str:
    """A scenario argument: a file path, or the name of a scenario shipped with the package
    (e.g. ``paper_simulation``, found in its scenarios folder); see :func:`named_file`. A study
    file (a [study] table) is refused with one line saying to run it with `tapmp study`."""
    path = named_file(name, "scenarios")
    from .tool.scenario import tomllib
    try:
        data = tomllib.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return path  # the scenario loader says what is wrong with it
    if isinstance(data.get("study"), dict):
        raise UsageError(f"{name} is a study file (it has a [study] table), not a scenario: run it with "
                         f"tapmp study {name}")
    return path


def study_file(name: str) -> str:
    """A study argument: a file path, or the name of a study shipped with the package (e.g.
    ``gain_sweep``); see :func:`named_file`."""
    return named_file(name, "studies")


def _run_one(scenario, ssp, out, overwrite, progress, label):
    from .tool.progress import progress_bar
    from .tool.results import run_scenario
    update, close = progress_bar(label, progress)
    try:
        return run_scenario(scenario, ssp, out, overwrite, update)
    finally:
        close()


def _recording_changes(args) -> dict:
    """The --format and --record-every of ``args`` (where given) as scenario changes."""
    changes = {}
    if getattr(args, "format", None):
        changes["format"] = args.format
    if getattr(args, "record_every", None) is not None:
        changes["record_every"] = record_every(args.record_every)
    return changes


def _recording(args, scenario):
    """``scenario`` with the --format and --record-every of ``args`` (where given)."""
    changes = _recording_changes(args)
    return scenario.with_changes(**changes) if changes else scenario


def _load(args):
    """The scenario of a run/compare command: the file, its --set overrides, --format and --record-every."""
    from .tool.scenario import load
    return _recording(args, load(scenario_file(args.scenario), args.set))


def record_every(value) -> int:
    """--record-every checked: an integer from 1 to MAX_INT (the scenario key's bound)."""
    from .tool.scenario import MAX_INT
    try:
        n = int(value)
    except ValueError:
        n = 0
    if not 1 <= n <= MAX_INT:
        raise UsageError(f"--record-every = {value!r} is invalid: allowed is an integer from 1 to {MAX_INT} "
                         "(keep every N-th step)")
    return n


def result_base(scenario) -> Path:
    """The scenario's result folder: its ``output``, else results/<name> (relative to the
    current directory); `tapmp run` writes into <base>/<law>, `tapmp compare` into <base>/compare."""
    return Path(scenario.output or Path("results") / scenario.name)


def warn_if_implausible(scenario) -> None:
    """One warning line on stderr per parameter far outside this machine's usual range."""
    from .tool.plausibility import implausible
    for line in implausible(scenario):
        print(f"warning: {line}", file=sys.stderr, flush=True)


def cmd_build(args) -> int:
    from .builder.build import build_all
    from .builder.build_native import build_native
    out = Path(args.out or default_build_dir())
    for p in args.platform or ():  # before building anything
        if p not in PLATFORMS:
            raise UsageError(f"--platform = {p!r} is invalid: allowed are {', '.join(PLATFORMS)}")
    if args.clean_cache:
        from ctoolchain import cache_dir, clean_cache
        removed = clean_cache(cache_sources())
        print(f"removed {len(removed)} stale file(s) from the compiled-code cache {cache_dir()}", flush=True)

    def log(line):
        print(line, flush=True)  # progress, also when the output is a pipe
    built = build_platforms(args)
    if set(built) == set(PLATFORMS):
        print(f"building every platform: {ALL_PLATFORMS_TIME}", flush=True)
    if args.cross_check:
        return build_cross_check(Path(args.out or "cross-check"), built, log)
    build_all(out, log)
    build_native(out / "native", platforms=built, log=log)
    from .engine import stepper
    if stepper.available():  # else a note says why; runs then step in Python
        print(f"compiled stepping core in {stepper.library_path()}")
    if set(built) != set(PLATFORMS):
        print(f"the native FMUs hold binaries for {', '.join(p for p in PLATFORMS if p in built)} only (and their "
              f"C sources); `tapmp build --all-platforms` adds {', '.join(p for p in PLATFORMS if p not in built)} "
              f"({ALL_PLATFORMS_TIME})")
    return 0


def build_cross_check(out: Path, platforms, log) -> int:
    """`tapmp build --cross-check`: the native FMI 2.0 FMUs (built in a temporary folder, for ``platforms``)
    in the FMI Cross-Check layout under ``out``, and nothing else."""
    import tempfile
    from .builder.build_native import build_native
    from .builder.fmu_extras import cross_check_tree
    with tempfile.TemporaryDirectory(prefix="tapmp_cross_check_") as tmp:
        native = build_native(Path(tmp), families=("fmi2",), platforms=platforms, log=log)
        fmus = {m: p for m, p in native["fmi2"].items() if m != "ssp"}
        for folder in cross_check_tree(fmus, out):
            print(f"wrote {folder}", flush=True)
    return 0


# What --all-platforms costs (docs/native-fmus.md#build-time)
ALL_PLATFORMS_TIME = ("4 to 13 min the first time on a machine (Zig builds each target's C runtime once, the two "
                      "Windows ones longest), seconds afterwards")


def build_platforms(args) -> tuple[str, ...]:
    """The platforms `tapmp build` compiles the native FMUs for: --platform's, every one with
    --all-platforms, else this machine's alone (as `bash build_fmus.sh --host`, the quick start)."""
    from ctoolchain import HOST
    if args.platform:
        return tuple(args.platform)
    return tuple(PLATFORMS) if args.all_platforms else (HOST,)


def cache_sources() -> list[Path]:
    """The C sources of the libraries tapmp compiles into its cache (the C model, the stepping core)."""
    from tapmp import cmodel
    from .engine import stepper
    return [cmodel.SOURCE, cmodel.HEADER, stepper.SOURCE]


def warn_if_unstable(scenario) -> None:
    """One line on stderr if the stability pre-check finds the scenario's loop unstable."""
    from .tool.stability import check, radius_text
    report = check(scenario)
    if not report.stable:
        print(f"warning: {scenario.name}: the sampled closed loop is {report.verdict} (spectral radius "
              f"{radius_text(report.spectral_radius)}, stable needs < 1 - 1e-6, at h = {scenario.step:g} s, {scenario.ordering}); "
              f"see `tapmp check`", file=sys.stderr, flush=True)


def cmd_check(args) -> int:
    from .tool.scenario import load
    from .tool.stability import check
    if args.fmus is not None:
        raise UsageError(f"--fmus = {args.fmus!r} is not an option of check: the check linearizes the FMI-free model, "
                         "which every FMU family reproduces bit for bit, so its verdict is the same for all "
                         "(`tapmp run --fmus` runs one family)")
    scenario = load(scenario_file(args.scenario), args.set)
    report = check(scenario)
    print(f"{scenario.name}: {report.summary()}")
    if args.eigenvalues:
        for z in report.eigenvalues:
            print(f"  {z.real:+.6f} {z.imag:+.6f}j   |z| = {abs(z):.6f}")
    return 0 if report.stable else 1


def cmd_analyze(args) -> int:
    from .tool.analysis import analyze, pole_table, robustness_table, table
    from .tool.scenario import load
    from .tool.stability import verdict_for
    scenario = load(scenario_file(args.scenario), args.set)
    out = Path(args.out) if args.out else result_base(scenario) / "analysis"
    from .tool.baselines import compare_runs
    if args.worst_case:
        return _analyze_worst_case(args, scenario, out)
    given = [k for k, v in (("--box", args.box), ("--poses", args.poses), ("--runs", args.runs)) if v is not None]
    if given:
        raise UsageError(f"{given[0]} is invalid without --worst-case: allowed only with --worst-case")
    for key, v in (("--delay", args.delay), ("--actuator-bandwidth", args.actuator_bandwidth)):
        if v is not None and not (math.isfinite(v) and v >= 0.0 if key == "--delay" else math.isfinite(v) and v > 0.0):
            raise UsageError(f"{key} = {v!r} is invalid: allowed is " + (
                "a delay >= 0 s" if key == "--delay" else "a bandwidth > 0 Hz (finite)"))
    with heartbeat() as tell:  # a line per run and step, repeated every 10 s (seconds to minutes)
        result = analyze(scenario, out, args.f_min, args.f_max, args.points, runs=compare_runs(scenario),
                         responses=args.responses, say=tell)
    print(f"{scenario.name}: the sampled loop (h = {scenario.step:g} s, {scenario.ordering}) broken at the plant "
          "input force, one motor or mode at a time")
    print(table(result))
    print("robustness on the same loop: disk margins (symmetric), all three motors' forces scaled at once, "
          "a delay in one loop and on all three motors at once, a first-order actuator on every motor")
    print(robustness_table(result))
    if args.delay or args.actuator_bandwidth is not None:
        from .tool.analysis import inserted_radius
        what = " and ".join(x for x in (f"a delay of {args.delay:g} s on every motor's force" if args.delay else "",
                                        f"a first-order actuator of {args.actuator_bandwidth:g} Hz on every motor"
                                        if args.actuator_bandwidth is not None else "") if x)
        print(f"spectral radius of the sampled loop with {what} (each inserted alone; stable if < 1 - 1e-6):")
        for name, sc in compare_runs(scenario).items():
            r = inserted_radius(sc, args.delay or 0.0, args.actuator_bandwidth)
            print(f"  {name}: " + ", ".join(f"{k} {v:.6f} ({verdict_for(v)})" for k, v in r.items() if v is not None))
    print(pole_table(result))
    print(f"analysis.json and figures in {out}")
    return 0


def _analyze_worst_case(args, scenario, out) -> int:
    """`tapmp analyze --worst-case`: the worst margins of each run over poses, envelope corners and a
    study's parameter box (orchestrator.studies.worst_case), printed and written to out."""
    from .studies import worst_case
    from .studies.study_file import load_study
    from .tool.folders import atomic_file, write_json
    from .tool.progress import say
    poses = worst_case.check_poses(8 if args.poses is None else args.poses)
    box = args.box or "robustness"
    try:
        study = load_study(study_file(box))
    except UsageError as err:
        raise UsageError(f"--box = {box!r}: {err}") from None
    runs = worst_case.worst_case_runs(scenario, study, args.runs)
    result = worst_case.worst_case(runs, study, poses, args.points, say=say)
    left = f"; left out (no effect on the linearized loop): {', '.join(result['left_out'])}" if result["left_out"] else ""
    head = (f"{scenario.name}: worst case of each run over {result['points']} points: the start, {poses} poses along "
            f"the trajectory, the 8 corners of the envelope and the vertices of the parameter box of {box}{left}")
    table = worst_case.worst_case_table(result)
    print(head)
    print(table)
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "worst_case.json", result)
    with atomic_file(out / "worst_case.md") as f:
        f.write(f"{head}\n\n{table}\n")
    print(f"worst_case.json and worst_case.md in {out}")
    return 0


def cmd_run(args) -> int:
    scenario = _load(args)
    warn_if_implausible(scenario)
    warn_if_unstable(scenario)
    out = Path(args.out) if args.out else result_base(scenario) / scenario.law
    from .tool.estimate import check_output_size
    check_output_size([scenario], out, scenario.name)
    m = _run_one(scenario, _ssp(args, scenario), out, args.overwrite, not args.no_progress, scenario.name)
    print(f"{scenario.name} ({scenario.law}): results in {out}")
    print("tracking MAE [um]: " + ", ".join(f"{v:.4f}" for v in m["tracking_mae_um"]))
    print("sync MAE [um]:     " + ", ".join(f"{v:.4f}" for v in m["sync_mae_um"]))
    if "tracking_mean_um" in m:
        print("steady (mean) error per mode [um]: " + ", ".join(
            f"{name} {v:+.4f}" for name, v in zip(MODE_NAMES, mode_means(m)))
            + "   (e = common (1,1,1) + diff. Z (1,0,-1) + diff. B (1,-2,1))")
    for line in move_lines({scenario.law: m}):
        print(line)
    return 0


MODE_NAMES = ("common", "diff. Z", "diff. B")
MODE_SHAPES = ((1, 1, 1), (1, 0, -1), (1, -2, 1))  # the motors' shares of each mode (tapmp.modal.MODES)


def mode_means(m: dict) -> list[float]:
    """The steady offset [um] the MAE does not show: the signed mean tracking error of a run's
    metrics ``m`` split into the modes, e = c (1,1,1) + z (1,0,-1) + b (1,-2,1), as [c, z, b]: c is
    the mean over the motors (every motor's offset in the common mode), z and b the differential
    modes' (orthogonal shapes, so each is (shape . e) / (shape . shape))."""
    e = m["tracking_mean_um"]
    return [sum(vi * ei for vi, ei in zip(v, e)) / sum(vi * vi for vi in v) for v in MODE_SHAPES]


def move_lines(results: dict, channels=("X", "Z", "B", "q1", "q2", "q3")) -> list[str]:
    """A point-to-point run's move metrics ({run: metrics} with a "move" entry, see
    tool.metrics.MoveMetrics), one line per run and moving channel of ``channels``: rise
    time [ms], overshoot [um, urad for B], settling time into each band [ms after the reference
    stops]; [] if no run has them."""
    lines = []
    for name, m in results.items():
        move = m.get("move")
        if not move or "channels" not in move:
            continue
        if not lines:
            lines.append(f"move ({move['profile']}): rise 10-90 % [ms], overshoot [um; urad for B], settling "
                         "within each band [m; rad for B] [ms after the reference stops; never: not in the run]")

        def ms(v):
            return "never" if v is None else f"{v * 1e3:.2f}"
        for channel, c in move["channels"].items():
            if c["distance"] == 0.0 or channel not in channels:
                continue
            over = f"{c['overshoot']:.4f}"
            settle = ", ".join(f"{band}: {ms(t)}" for band, t in c["settling_time_s"].items())
            lines.append(f"  {name} {channel}: rise {ms(c['rise_time_s'])}, overshoot {over}, settling within "
                         f"{settle}")
    return lines


def compare_runs(scenario):
    """The runs of `tapmp compare` ({folder name: Scenario}): SC-DC, APD-DC (Eq. 41) and the fair
    baselines and ablations of orchestrator.tool.baselines."""
    from .tool.baselines import compare_runs as runs
    return runs(scenario)


def summary_text(results: dict) -> str:
    """The short table `tapmp compare` prints: one row per run (orchestrator.tool.report.summary_rows:
    SC-DC's reduction against each run), its force effort and the steady (mean) tracking error on
    each mode (mode_means)."""
    from .tool.report import summary_rows
    rows = [(name, t, y, rt, ry) for name, _, t, y, rt, ry in summary_rows(results)]
    w = max(len("run"), *(len(r[0]) for r in rows))
    hz = next((m["force_rms_above_hz"] for m in results.values() if "force_rms_above_hz" in m), 0.0)
    head = f"F RMS > {hz:g} Hz [N]"
    lines = [f"{'run':<{w}}  {'tracking MAE [um]':>17}  {'sync MAE [um]':>13}  {'SC-DC vs it: tracking':>21}  "
             f"{'sync':>8}  {head:>19}  {'mean: common':>12}  {'diff. Z':>8}  {'diff. B':>8} [um]"]
    for name, t, y, rt, ry in rows:
        f = results[name].get("force_hf_rms_n")
        effort = f"{sum(f) / len(f):.4g}" if f else "n/a"  # the mean over the motors
        means = mode_means(results[name]) if "tracking_mean_um" in results[name] else [float("nan")] * 3
        lines.append(f"{name:<{w}}  {t:>17.4f}  {y:>13.4f}  {rt:>+20.1f}%  {ry:>+7.1f}%  {effort:>19}  "
                     f"{means[0]:>+12.4f}  {means[1]:>+8.4f}  {means[2]:>+8.4f}")
    return "\n".join(lines)


MAX_WORKERS = 4096  # processes one command may start; bounded before the number reaches the OS or Dask


def _check_workers(workers: int) -> None:
    """--workers: UsageError unless 1 to MAX_WORKERS processes."""
    if workers < 1:
        raise UsageError(f"--workers = {workers} is invalid: allowed is an integer >= 1")
    if workers > MAX_WORKERS:
        raise UsageError(f"--workers = {workers} is invalid: allowed is an integer from 1 to {MAX_WORKERS}")


def _jobs(args) -> int:
    """--jobs checked: a positive integer up to the cores (default: one per core)."""
    from .tool.pool import parse_jobs
    return parse_jobs(args.jobs)


def cmd_compare(args) -> int:
    scenario = _load(args)
    warn_if_implausible(scenario)
    out = Path(args.out) if args.out else result_base(scenario) / "compare"
    command = args.command_line
    jobs = _jobs(args)
    show = _names(args.runs)
    if show and args.no_figures:
        raise UsageError("--runs chooses the runs the figures show: it cannot go with --no-figures")
    if show:  # before any run starts
        from .tool.plots import select_runs
        select_runs(out, list(compare_runs(scenario)), show)
    from .paper.paper_tables import reference_rows
    from .tool.compare import run_comparison
    _, results, _, _ = run_comparison(scenario, _ssp(args, scenario), out, args.overwrite, not args.no_progress,
                                      command, jobs, show, not args.no_figures, noise=not args.no_noise,
                                      reference=reference_rows(scenario.name))
    print(f"{scenario.name}: mean over the three motors; SC-DC's reduction against each run, positive = SC-DC has "
          "the smaller error")
    print("mean: the steady tracking error per mode, e = common (1,1,1) + diff. Z (1,0,-1) + diff. B (1,-2,1)")
    print(summary_text(results))
    for line in move_lines(results, ("X", "Z", "B")):  # the motors' too in each run's metrics.json
        print(line)
    print(f"results{'' if args.no_figures else ', figures'} and the full tables (comparison.md) in {out}")
    return 0


@contextmanager
def heartbeat(tell=None, every: float = 10.0):
    """A ``tell(line)`` (default: tool.progress.say, a line on stderr) for the duration that
    also repeats the last line with the seconds since it whenever ``every`` seconds pass without
    one, so a long phase is never silent."""
    import time
    if tell is None:
        from .tool.progress import say as tell
    last = {"line": None, "since": time.monotonic(), "beat": time.monotonic()}
    lock, done = threading.Lock(), threading.Event()

    def told(line):
        with lock:
            now = time.monotonic()
            last.update(line=line, since=now, beat=now)
            tell(line)

    def watch():
        while not done.wait(1.0):
            with lock:
                now = time.monotonic()
                if last["line"] is not None and now - last["beat"] >= every:
                    tell(f"{last['line']} (still running, {now - last['since']:.0f} s)")
                    last["beat"] = now

    watcher = threading.Thread(target=watch, daemon=True)
    watcher.start()
    try:
        yield told
    finally:
        done.set()
        watcher.join()


def check_reproduce_may_replace(folder: Path, overwrite: bool) -> None:
    """OutputExistsError (one line) if ``folder`` holds a completed comparison that `tapmp reproduce`
    did not write (comparison.json's written_by), unless ``overwrite``; reproduce replaces its own."""
    import json
    from .tool.folders import COMPARISON_JSON, OutputExistsError, folder_completed, marked_kind
    if overwrite or marked_kind(folder) != "comparison" or not folder_completed(folder):
        return
    try:
        written_by = json.loads((folder / COMPARISON_JSON).read_text()).get("written_by", "compare")
    except (OSError, ValueError, AttributeError):
        written_by = "compare"
    if written_by != "reproduce":
        raise OutputExistsError(f"output folder {folder} holds a completed comparison that tapmp reproduce did "
                                f"not write (by tapmp {written_by}): pass --overwrite to replace it, or --results "
                                "another folder")


def cmd_reproduce(args) -> int:
    from .tool.estimate import check_output_size
    from .paper.reproduction import reproduce
    from .tool.scenario import load
    command = args.command_line
    jobs = _jobs(args)

    results = Path(args.results)
    page = Path(args.out) if args.out else results / "paper-reproduction.md"
    if not 0 < args.paper_gains_stop_time < float("inf"):
        raise UsageError(f"--paper-gains-stop-time = {args.paper_gains_stop_time:g} is invalid: allowed is a "
                         "finite horizon > 0 s")
    _check_workers(args.workers)
    if page.suffix != ".md":
        raise UsageError(f"--out = {str(page)!r} is invalid: allowed is a Markdown file ending in .md")
    if args.record_every is not None:
        record_every(args.record_every)
    from .paper.reproduction import SCENARIOS
    files = [Path(args.scenarios) / f"{name}{suffix}.toml" for suffix in ("", "_calibrated") for name in SCENARIOS]
    for f in files[:len(SCENARIOS)]:
        if not f.is_file():
            raise UsageError(f"--scenarios = {args.scenarios!r}: no {f.name} there: allowed is a folder with "
                             + " and ".join(f"{name}.toml" for name in SCENARIOS))
    runs = [sc for f in files if f.is_file() for sc in compare_runs(_recording(args, load(f))).values()]
    check_output_size(runs, results, "reproduce", jobs)  # every compare run, before the first starts
    for f in files:  # before the first run: a comparison `tapmp compare` completed is not replaced silently
        if f.is_file():
            check_reproduce_may_replace(results / f.stem / "compare", args.overwrite)

    with heartbeat() as tell:
        text = reproduce(Path(args.scenarios), results, page, command, ssp_of=lambda sc: _ssp(args, sc),
                         changes=_recording_changes(args), progress=not args.no_progress, jobs=jobs,
                         paper_gains_stop=args.paper_gains_stop_time, workers=args.workers, ssp=_ssp(args),
                         say=tell)
    print(f"wrote {page}")
    if args.write_docs:
        docs = Path("docs") / "paper-reproduction.md"
        if not docs.parent.is_dir():
            raise UsageError(f"--write-docs: no folder {docs.parent.absolute()}: run it from the repository root")
        from .tool.folders import write_text
        write_text(docs, text)
        print(f"wrote {docs}")
    return 0


def cmd_study(args) -> int:
    """`tapmp study`: 0 if every case ran (completed, diverged or rejected), 1 if any failed (an error)."""
    from .studies.run import run_study
    from .engine.tempdirs import remove_stale_folders
    from .tool.estimate import check_output_size
    from .tool.folders import output_lock
    from .tool.progress import say
    from .studies.study import MAX_CASES, StudyError, check_case_count, close_client, load_study, open_client
    study = load_study(study_file(args.study))
    every = record_every(args.record_every) if args.record_every is not None else None
    if args.write_docs and not study.tune:
        raise StudyError(f"--write-docs: {args.study} has no [tune] table; only a tuning writes a write_to folder")
    if args.workers is not None:
        _check_workers(args.workers)
    if args.scheduler and args.workers is not None:
        raise StudyError("--workers is for the local cluster: with --scheduler the cluster's own workers run the cases")
    if args.shared_fs and not args.scheduler:
        raise StudyError("--shared-fs is for a cluster given by --scheduler (the local cluster shares this disk)")
    max_cases = MAX_CASES if args.max_cases is None else args.max_cases
    if max_cases < 1:
        raise StudyError(f"--max-cases = {max_cases} is invalid: allowed is an integer >= 1")
    if args.retry_failed and not (args.resume and not study.tune):
        raise StudyError("--retry-failed goes with --resume, for a grid or Monte Carlo study: it runs the cases "
                         "whose row in study.csv says failed again")
    if not args.worker_timeout > 0:
        raise StudyError(f"--worker-timeout = {args.worker_timeout:g} is invalid: allowed is a number > 0 [s]")
    if not study.tune:
        check_case_count(study, max_cases)  # before the cases are listed
    if args.format or args.record_every is not None:  # scenario keys, applied like the study's [set]
        import dataclasses
        recording = {k: v for k, v in (("format", args.format), ("record_every", every)) if v is not None}
        study = dataclasses.replace(study, set={**study.set, **recording})
    out = Path(args.out or study.output)
    case_list = None
    if not study.tune:
        from .studies.study import cases
        case_list = cases(study, max_cases)  # every case validated before a cluster starts
    if study.keep_results and not study.tune:  # else each case deletes its result file once scored
        check_output_size([study.base_scenario()] * len(case_list), out, study.name, args.workers or 1)
    ssp = _ssp(args)  # after the cases (a study file's error first), before starting a cluster
    if not ssp.exists():
        raise StudyError(f"SSP file {ssp} does not exist: build the FMUs first (bash build_fmus.sh, "
                         "or tapmp build) or pass --ssp")
    remote = None
    with output_lock(out):  # before starting a cluster; run_study takes it again (re-entrant)
        if args.scheduler:
            say(f"{study.name}: connecting to the Dask scheduler at {args.scheduler}")
            remote = {"address": args.scheduler, "data": not args.shared_fs, "timeout": args.worker_timeout}
        else:
            say(f"{study.name}: starting the Dask workers")
        client = open_client(args.scheduler, args.workers, args.worker_timeout)
        try:
            command = args.command_line
            say(f"{study.name}: running the cases -> {out}")
            s = run_study(study, ssp, client, out, args.resume, args.overwrite,
                          not args.no_progress, command, args.write_docs, remote, max_cases, case_list,
                          args.retry_failed)
        finally:
            close_client(client)
            remove_stale_folders()  # of local workers that were killed, not stopped
    for f in s["figures"]:
        print(f"wrote {f}")
    c = s["counts"]
    counts = (f"{c['completed']} completed, {c['diverged']} diverged, {c['failed']} failed"
              + (f", {c['rejected']} rejected (not stable, not run)" if c["rejected"] else "")
              + (f"; {s['unstable']} of them unstable by the stability check (flag in study.csv)"
                 if s.get("unstable") else ""))
    if study.tune:
        for law, r in s["tuning"].items():
            start = f"{r['start']:.4f} um" if r["start"] is not None else "not run (start gains rejected)"
            print(f"{law}: objective {start} (start gains) -> {r['tuned']:.4f} um (tuned, "
                  f"{r['evaluations']} evaluations); preset {r['preset']}")
        print(f"presets, comparison and objective plot in {s['write_to']}")
        print(f"{study.name}: {s['cases']} evaluations ({s['wall_time_s']:.1f} s): {counts} -> "
              f"{s['out'] / 'study.csv'}")
    else:
        print(f"{study.name}: {s['cases']} cases ({s['ran']} run now, {s['wall_time_s']:.1f} s): {counts} -> "
              f"{s['out'] / 'study.csv'}")
    return 1 if c["failed"] else 0


def cmd_export(args) -> int:
    """`tapmp export`: the scenario's SSP with its parameter set, and the container's start values."""
    from .tool.export import export
    from .tool.scenario import load
    scenario = load(scenario_file(args.scenario), args.set)
    source = _ssp(args, scenario)
    ssp, values = export(scenario, source, Path(args.out), args.overwrite)
    pairs = values.read_text().split()
    print(f"wrote {ssp} (SSP 1.0: the FMUs of {source}, parameter set "
          f"{scenario.name!r} bound to every element, {scenario.n_steps} steps of {scenario.step:g} s to "
          f"{scenario.stop_time:g} s)")
    print(f"wrote {values} (--start-values for fmpy simulate on TAPMP_ClosedLoop.fmu):")
    print(" ".join(pairs))
    return 0


def _names(text) -> list | None:
    """A comma-separated option (--runs, --signals) as a list; None if not given."""
    return None if text is None else [v.strip() for v in text.split(",") if v.strip()]


def cmd_plot(args) -> int:
    from .tool.plots import parse_window, plot_runs
    window = parse_window(args.window)
    written = plot_runs(args.result_dir, args.label, _names(args.signals), window,
                        Path(args.out) if args.out else None, args.svg, args.allow_different_horizons,
                        _names(args.runs))
    for path in written:
        print(f"wrote {path}")
    return 0


PLOT_SIGNALS = ("e1..e3 tracking error of each motor [µm] (also q1_err..q3_err), es1..es3 synchronization "
                "errors [µm], eX, eZ [µm], eB [µrad] axis errors, F1..F3 force commands [N], q1..q3 motor positions "
                "[mm], X, Z [mm], B [deg] platform pose, or a recorded column by its full name (e.g. controller.u1) "
                "in SI units")
RELATIVE = "a relative path is relative to the current directory"
PLATFORM_NAMES = tuple(PLATFORMS)
PATHS_HELP = ("Paths: scenario files, --out, --ssp, --fmus-dir and a scenario's 'output' are relative to the "
              "current directory; a scenario may also be named (paper_simulation: the scenario shipped with the "
              "package); a scenario's gains_file is relative to the scenario file; the SSP of --fmus is found in "
              f"--fmus-dir, else ${FMUS_DIR_ENV}, else the repository's build/ (in a checkout) or ./build "
              "(installed as a wheel).")
FMUS_DIR_HELP = (f"folder of the built FMUs, as `tapmp build --out DIR` writes it (default: ${FMUS_DIR_ENV}, else "
                 "the repository's build/ in a checkout, else ./build)")


def fmu_args(sp) -> None:
    """--ssp, --fmus and --fmus-dir: the FMUs a command runs (run, compare, export, reproduce, study)."""
    sp.add_argument("--ssp", help="SSP system file (default: the built SSP of --fmus)")
    sp.add_argument("--fmus", type=_family, metavar="{" + ",".join(FAMILIES) + "}", help="FMU family: native "
                    "(default: the C FMUs, FMI 2.0, build/native/fmi2/TAPMP.ssp), fmi3 (the C FMUs, FMI 3.0, "
                    "build/native/fmi3/TAPMP.ssp) or python (the pythonfmu FMUs, build/TAPMP.ssp); overrides the "
                    "scenario's fmus; paths relative to --fmus-dir")
    sp.add_argument("--fmus-dir", metavar="DIR", help=FMUS_DIR_HELP)


def scenario_arg(sp, example: str) -> None:
    """The scenario file and its --set overrides (``example``: a KEY=VALUE shown in the help)."""
    sp.add_argument("scenario", help="scenario TOML file, e.g. scenarios/paper_simulation.toml, or the name of a "
                    f"scenario shipped with the package: {', '.join(shipped_names('scenarios'))}")
    sp.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help=f"override a scenario value, e.g. {example}")


def _choices(option: str, values: list, allowed) -> tuple:
    """``values`` of a repeatable option, each one of ``allowed``; else the one-line refusal."""
    from tapmp.errors import allowed_are
    for v in values:
        if v not in allowed:
            raise UsageError(f"{option} = {v!r} is invalid: {allowed_are(v, list(allowed))}")
    return tuple(values)


def cmd_paper_gains(args) -> int:
    """`tapmp paper-gains`: the paper's gains (Eq. 40-43) at fine steps in the plain loop; the table
    on stdout (progress on stderr), the rows also to --json."""
    from .paper.paper_gains import CASES, LAWS, PLANTS, READINGS, paper_gains_table, run_paper_gains
    cases = _choices("--cases", args.cases or list(CASES), CASES)
    laws = _choices("--laws", args.laws or list(LAWS), LAWS)
    readings = _choices("--readings", args.readings or list(READINGS), READINGS)
    plants = _choices("--plants", args.plants or list(PLANTS), PLANTS)
    steps = tuple(args.steps or (1e-6, 1e-5, 1e-4))
    if args.workers < 1:
        raise UsageError(f"--workers = {args.workers} is invalid: allowed is an integer >= 1")

    def progress(done, total, row):  # on stderr, so that stdout stays the table
        print(f"run {done}/{total}: {row['case']} gains, {row['plant']} plant, reading {row['reading']}, "
              f"{row['law'].upper()}, step {row['step'] * 1e6:g} us, {row['stop_time']:g} s: {row['status']} "
              f"({row['wall_s']:.1f} s)", file=sys.stderr, flush=True)

    n = len(cases) * len(plants) * len(readings) * len(laws) * len(steps)
    print(f"running the paper's gains in the plain loop: {n} runs of {args.stop_time:g} s on {args.workers} "
          f"process(es); the table follows", file=sys.stderr, flush=True)
    try:
        rows = run_paper_gains(steps=steps, stop_time=args.stop_time, readings=readings, cases=cases, laws=laws,
                               plants=plants, workers=args.workers, progress=progress)
    except ValueError as err:
        raise UsageError(str(err)) from None
    print(paper_gains_table(rows))
    if args.json:
        import json
        from .tool.folders import write_text
        write_text(Path(args.json), json.dumps(rows, indent=1))
    return 0


def cmd_calibrate(args) -> int:
    """`tapmp calibrate`: fit the plant on the paper's APD-DC rows, predict SC-DC, write the
    calibrated scenario."""
    import math
    if args.horizon is not None and not (math.isfinite(args.horizon) and args.horizon > 0.0):
        raise UsageError(f"--horizon = {args.horizon!r} is invalid: allowed is a number > 0 [s]")
    if args.max_nfev < 1:
        raise UsageError(f"--max-nfev = {args.max_nfev!r} is invalid: allowed is an integer >= 1")
    from .paper.calibration import calibrate_and_predict, calibrated_file
    ssp = _ssp(args)
    work = Path(args.work or Path("results") / "calibration" / args.target)
    write_to = None if args.no_write else Path(args.write_to or work / calibrated_file(args.target).name)
    try:
        lines = calibrate_and_predict(args.target, ssp, work, args.horizon, args.max_nfev, write_to)
    except ValueError as err:
        raise UsageError(str(err)) from None
    print("\n".join(lines))
    return 0


def cmd_null_models(args) -> int:
    """`tapmp null-models`: the null models' scores on the paper's printed reductions."""
    from .paper.null_models import null_model_table
    print(null_model_table())
    return 0


def cmd_theorem1(args) -> int:
    """`tapmp theorem1`: the counterexample's eigenvalues for both laws and Eq. 31 on a random state."""
    from .paper.theorem1 import summary_lines
    print("\n".join(summary_lines()))
    return 0


def cmd_modal(args) -> int:
    """`tapmp modal [PRESET ...]`: the laws' modal gains of gain presets (tapmp.modal.modal_table)."""
    from tapmp.modal import modal_table
    from tapmp.params import GAIN_PRESETS
    names = _choices("preset", args.presets or ["default", "paper_simulation", "paper_experiment"], GAIN_PRESETS)
    print(modal_table(list(names)))
    return 0


class Parser(argparse.ArgumentParser):
    """argparse's parser with its errors as one line, ``error: ...`` (the closest names for an
    invalid choice) and where the usage is (``see tapmp run --help``), exit code 2."""

    def error(self, message):
        import re
        from tapmp.errors import suggestion
        m = re.search(r"invalid choice: '([^']*)' \(choose from (.*)\)$", message)
        if m:  # argparse lists the choices but names none of them as the closest
            choices = [c.strip().strip("'") for c in m.group(2).split(",")]
            message = message[:m.start()] + f"{m.group(1)!r} is invalid: allowed are {', '.join(choices)}" \
                + suggestion(m.group(1), choices)
        self.exit(2, f"error: {self.prog}: {' '.join(message.split())} (see {self.prog} --help)\n")


def parser() -> argparse.ArgumentParser:
    p = Parser(prog="tapmp", description=(
        "Co-simulate the TAPMP (three-axis parallel motion platform) FMUs: build them, run "
        "scenarios, compare SC-DC with APD-DC, plot results."), epilog=PATHS_HELP)
    p.add_argument("--debug", action="store_true", help="show the traceback of an error")
    sub = p.add_subparsers(dest="command", required=True)

    b = sub.add_parser("build", help="build every FMU family and its SSP",
                       description="Build the pythonfmu family (TAPMP_Plant.fmu, TAPMP_Controller.fmu, "
                       "TAPMP_Trajectory.fmu, TAPMP.ssp and the closed-loop container FMU TAPMP_ClosedLoop.fmu) "
                       "into OUT and the native FMI 2.0 and 3.0 families into OUT/native/fmi2 and OUT/native/fmi3, "
                       "with this machine's binaries and their C sources (--all-platforms: Linux, Windows and macOS on x86-64 "
                       "and ARM), compiled by zig cc from the ziglang package ($CC for x86_64-linux if set). No "
                       "system compiler needed.")
    b.add_argument("--out", help=f"output folder (default: ${FMUS_DIR_ENV}, else the repository's build/ in a "
                   "checkout, else ./build)")
    b.add_argument("--platform", action="append", metavar="P",
                   help="build the native FMUs' binaries for these platforms only (repeatable): "
                   f"{', '.join(PLATFORM_NAMES)} (default: this machine's)")
    b.add_argument("--all-platforms", action="store_true",
                   help="binaries for every platform (the FMUs to hand to other machines): 4 to 13 min the first "
                   "time on a machine, seconds afterwards")
    b.add_argument("--cross-check", action="store_true",
                   help="instead of the families, write the native FMI 2.0 FMUs in the FMI Cross-Check layout into "
                   "OUT (default: ./cross-check): fmus/2.0/cs/<platform>/tapmp/<version>/<model>/ with the FMU, its "
                   "reference experiment (_ref.csv, _in.csv, _ref.opt) and ReadMe.txt; nothing else is built")
    b.add_argument("--clean-cache", action="store_true", help="first remove from the compiled-code cache "
                   "($TAPMP_CACHE, else ~/.cache/tapmp) the libraries and lock files older than this package's C "
                   "sources (left by earlier versions, checkouts and environments; rebuilt when used again)")
    b.set_defaults(func=cmd_build)

    def source_args(sp):
        """The scenario, its --set overrides and the SSP it runs on (run, compare, export)."""
        scenario_arg(sp, "--set stop_time=0.5 --set plant.k_pull=0")
        fmu_args(sp)

    def recording_args(sp):
        """--format and --record-every: what the result files keep."""
        sp.add_argument("--format", type=_result_format, metavar="{" + ",".join(RESULT_FORMATS) + "}", help="result files: csv (results.csv, text) or mat "
                        "(results.mat, MATLAB 5 MAT-file, about 40 %% of the size and faster to write); overrides "
                        "the scenario's format (default csv)")
        sp.add_argument("--record-every", metavar="N", help="keep every N-th step (and the last) "
                        "in the result files; the metrics still use every step (default: the scenario's "
                        "record_every, 1)")

    def progress_arg(sp):
        sp.add_argument("--no-progress", action="store_true", help="no progress bar")

    def jobs_arg(sp, what):
        sp.add_argument("--jobs", metavar="N", help=f"{what} at once, each in its own process (default: one per "
                        "core)")

    def scenario_args(sp):
        source_args(sp)
        sp.add_argument("--out", help=f"output folder (default: the scenario's 'output', else results/<name>, "
                        f"then /<law> for run, /compare for compare); {RELATIVE}")
        sp.add_argument("--overwrite", action="store_true", help="replace a completed result in the output folder "
                        "(a failed or interrupted one is replaced without it)")
        recording_args(sp)
        progress_arg(sp)

    r = sub.add_parser("run", help="run one scenario", description="Co-simulate one scenario and write "
                       "results.csv (or results.mat), run.json and metrics.json into its output folder, by default "
                       "<output>/<law>, e.g. results/paper_simulation/sc-dc.", epilog=PATHS_HELP)
    scenario_args(r)
    r.set_defaults(func=cmd_run)
    ck = sub.add_parser("check", help="stability pre-check of a scenario's sampled loop",
                        description="Linearize the sampled closed loop (plant about the start pose, the "
                        "scenario's controller, step and ordering) and report the spectral radius of its "
                        "one-step map: stable if < 1 - 1e-6. Exit code 0 if stable, 1 if not.")
    scenario_arg(ck, "--set gains='\"paper_simulation\"'")
    ck.add_argument("--eigenvalues", action="store_true", help="list every eigenvalue")
    ck.add_argument("--fmus", help=argparse.SUPPRESS)  # refused with the reason (cmd_check), not "unrecognized"
    ck.set_defaults(func=cmd_check)
    an = sub.add_parser("analyze", help="frequency response, margins and poles of the sampled loop",
                        description="Linearize the sampled closed loop as `check` does, break it at the plant input "
                        "force (per motor and per mode: common, differential Z, differential B; the other directions "
                        "closed) and write analysis.json and Bode figures: loop gain L, sensitivity S, complementary "
                        "sensitivity T, force-to-error disturbance sensitivity up to the Nyquist frequency; gain and "
                        "phase margin, peak |S| and |T|, bandwidth; closed-loop poles as natural frequency and "
                        "damping; for SC-DC and every baseline of `compare`. See docs/analysis.md.",
                        epilog=PATHS_HELP)
    scenario_arg(an, "--set step=1e-5")
    an.add_argument("--out", help=f"output folder (default: the scenario's 'output', else results/<name>, then "
                    f"/analysis); {RELATIVE}")
    an.add_argument("--f-min", type=float, default=0.1, metavar="HZ", help="lowest frequency (default 0.1 Hz)")
    an.add_argument("--f-max", type=float, default=None, metavar="HZ",
                    help="highest frequency (default: the Nyquist frequency 1/(2 step))")
    an.add_argument("--points", type=int, default=400, help="frequencies, log-spaced (default 400)")
    an.add_argument("--delay", type=float, default=None, metavar="SECONDS",
                    help="also report each run's spectral radius with this delay on every motor's force")
    an.add_argument("--actuator-bandwidth", type=float, default=None, metavar="HZ",
                    help="also report each run's spectral radius with a first-order actuator (current loop) of "
                    "this bandwidth on every motor")
    an.add_argument("--worst-case", action="store_true", help="instead: the worst Ms, all-loops gain margin, disk "
                    "margin and all-motor delay margin of each run over poses along the trajectory, the corners of "
                    "the envelope and the vertices of a study's parameter box, and where each occurs")
    an.add_argument("--box", default=None, metavar="STUDY", help="with --worst-case: the study whose uniform "
                    "Monte Carlo factors span the parameter box (default: the shipped robustness study)")
    an.add_argument("--poses", type=int, default=None, help="with --worst-case: poses along the trajectory (default 8)")
    an.add_argument("--runs", default=None, metavar="NAMES", help="with --worst-case: comma-separated runs of "
                    "`compare` (default: the box study's baselines)")
    an.add_argument("--responses", action="store_true", help="also write frequency_response.csv: magnitude and "
                    "phase of L, S, T and e/d per run and break point at every frequency")
    an.set_defaults(func=cmd_analyze)
    c = sub.add_parser("compare", help="run a scenario with SC-DC, APD-DC and fair baselines",
                       description="Run the scenario with SC-DC, APD-DC (Eq. 41), APD-DC with SC-DC's common-mode "
                       "and differential-mode stiffness, the mode-matched PD and PID (PID-DC) and the SC-DC "
                       "ablations b = 0 and Lambda_p = 0 (orchestrator/tool/baselines.py); write "
                       "comparison.md (the full tables) and figures and print one summary row per run. Output folder by default "
                       "<output>/compare, e.g. results/paper_simulation/compare (one subfolder per run).",
                       epilog=PATHS_HELP)
    scenario_args(c)
    jobs_arg(c, "runs")
    c.add_argument("--runs", metavar="R1,R2,...", help="runs the figures show (folder names, e.g. "
                   "sc-dc,apd-dc,pid-dc-mode-matched, or all; default: sc-dc, apd-dc and the better of "
                   "apd-dc-mode-matched and apd-dc-ms-matched by mean tracking MAE); every run still runs and is "
                   "in comparison.md")
    c.add_argument("--no-figures", action="store_true", help="write no figures (the runs and comparison.md only; "
                   "draw them later with `tapmp plot FOLDER`)")
    c.add_argument("--no-noise", action="store_true", help="leave out the noise runs (SC-DC, APD-DC and the "
                   "matched baselines again at 20 and 100 nm rms measurement noise, seeded; 10 more runs) and "
                   "comparison.md's noise table")
    c.set_defaults(func=cmd_compare)
    rp = sub.add_parser("reproduce", help="write the paper-reproduction page (results/paper-reproduction.md)",
                        description="Run `compare` (SC-DC, APD-DC and the fair baselines) on both paper scenarios "
                        "and their calibrated versions if present, run the paper's gains at fine steps, and write the "
                        "paper-reproduction page: the paper's Tables 1-6 as printed beside ours, the modal table, "
                        "the baselines, the paper-gain runs and which of the paper's claims hold. The page goes to "
                        "RESULTS/paper-reproduction.md; docs/paper-reproduction.md only with --write-docs.")
    rp.add_argument("--out", help="page to write, ending in .md (default: RESULTS/paper-reproduction.md)")
    rp.add_argument("--write-docs", action="store_true", help="also write the page to docs/paper-reproduction.md "
                    "(relative to the current directory: run it from the repository root)")
    recording_args(rp)
    rp.add_argument("--scenarios", default=str(SCENARIOS_DIR), help="folder with paper_simulation.toml, "
                    "paper_experiment.toml (default: the scenarios shipped with the package)")
    rp.add_argument("--results", default="results", help="folder for the runs: RESULTS/<scenario>/compare "
                    "(the folders `tapmp compare` writes by default: a comparison reproduce wrote is replaced, one "
                    f"`tapmp compare` completed only with --overwrite); {RELATIVE}")
    rp.add_argument("--overwrite", action="store_true", help="replace a completed comparison of `tapmp compare` "
                    "in RESULTS/<scenario>/compare")
    fmu_args(rp)
    rp.add_argument("--paper-gains-stop-time", type=float, default=0.2, metavar="S",
                    help="horizon [s] of each run of the paper's gains at 1 us, 10 us and 0.1 ms (default 0.2)")
    rp.add_argument("--workers", type=int, default=2, help="processes for the paper-gain runs (default 2)")
    jobs_arg(rp, "compare runs")
    progress_arg(rp)
    rp.set_defaults(func=cmd_reproduce)
    st = sub.add_parser("study", help="run a parameter study on Dask",
                        description="Run every case of a study file (grid, Monte Carlo or tuning) as an "
                        "independent co-simulation on Dask workers; one row per case in OUTPUT/study.csv.")
    st.add_argument("study", help="study TOML file, e.g. studies/robustness.toml, or the name of a study "
                    f"shipped with the package: {', '.join(shipped_names('studies'))}")
    st.add_argument("--scheduler", help="address of a running Dask scheduler, e.g. tcp://10.0.0.5:8786 "
                    "(default: a LocalCluster on this machine)")
    st.add_argument("--workers", type=int, help="worker processes of the LocalCluster (default: one per core)")
    st.add_argument("--shared-fs", action="store_true", help="with --scheduler: the workers see this machine's "
                    "files at the same paths (a shared file system); they read the SSP and write the case folders "
                    "themselves instead of receiving the SSP and sending each case's files back")
    st.add_argument("--worker-timeout", type=float, default=60.0, metavar="S", help="how long to wait for the "
                    "scheduler and for its first worker [s] (default 60)")
    st.add_argument("--max-cases", type=int, metavar="N", help="run a study of more than 100000 cases (up to N)")
    st.add_argument("--out", help="output folder (overrides the study's 'output')")
    fmu_args(st)
    st.add_argument("--resume", action="store_true", help="run only the cases without a row in study.csv")
    st.add_argument("--retry-failed", action="store_true", help="with --resume: run the cases whose row says "
                    "failed again, replacing their rows")
    st.add_argument("--overwrite", action="store_true", help="start again in an output folder with a study.csv")
    recording_args(st)
    st.add_argument("--write-docs", action="store_true", help="a tuning study: write its presets, comparison.md "
                    "and objective.png into its [tune] write_to folder (studies/tune.toml: docs/tuning) instead "
                    "of OUT/tuning")
    progress_arg(st)
    st.set_defaults(func=cmd_study)
    ex = sub.add_parser("export", help="write a scenario as an SSP with its parameter set",
                        description="Write the SSP of the FMU family with the scenario's parameter set (SSP "
                        "ParameterValues, resources/<element>.ssv, bound to every element; the plant's initial "
                        "state included) and its start time, stop time and step in the DefaultExperiment, so that "
                        "libcosim, Ecos or FMPy run the scenario; and FILE.start-values.txt, the same values as "
                        "--start-values for `fmpy simulate` on TAPMP_ClosedLoop.fmu (also printed). Relative "
                        "paths are relative to the current directory; the SSP of --fmus is found in --fmus-dir.")
    source_args(ex)
    ex.add_argument("--out", required=True, help="SSP file to write, ending in .ssp, e.g. export/paper.ssp")
    ex.add_argument("--overwrite", action="store_true", help="replace an existing FILE.ssp and its start values")
    ex.set_defaults(func=cmd_export)
    pl = sub.add_parser("plot", help="plot a run, a comparison, or runs side by side",
                        description="Write the figures (cf. paper Fig. 4-7, and the force commands) of one result "
                        "folder, or of several run folders overlaid, as PNG (and SVG with --svg). One run folder: "
                        "run_fig4_trajectory.png ... run_fig8_force_commands.png into it; one comparison folder: "
                        "fig4_trajectory.png ... fig8_force_commands.png into it, showing by default SC-DC "
                        "(proposed), APD-DC (the paper's baseline) and the better fair baseline (apd-dc-mode-matched "
                        "or apd-dc-ms-matched, the lower mean tracking MAE); several run folders: fig4 ... fig8 "
                        "with one trace per run into --out. With --signals one figure signals.png instead. "
                        "Runs of different horizons (start, stop or step) are refused unless "
                        "--allow-different-horizons.", epilog=PATHS_HELP)
    pl.add_argument("result_dir", nargs="+", metavar="FOLDER",
                    help=f"a run folder or a comparison folder, or several run folders to overlay; {RELATIVE}")
    pl.add_argument("--label", action="append", metavar="TEXT", help="legend label of each run folder, in order "
                    "(repeat once per folder; default: the folder names)")
    pl.add_argument("--signals", metavar="S1,S2,...", help="plot these signals, one panel each, into signals.png: "
                    + PLOT_SIGNALS)
    pl.add_argument("--window", metavar="START:STOP", help="time window in seconds, e.g. 0.5:1.0 (either side may "
                    "be empty: 0.5: or :1.0)")
    pl.add_argument("--runs", metavar="R1,R2,...", help="runs of a comparison folder to show (folder names, e.g. "
                    "sc-dc,apd-dc,pid-dc-mode-matched, or all)")
    pl.add_argument("--out", help="output folder (default: the folder itself for one folder; "
                    "results/plots/<label>_vs_<label>... for several run folders, and for --runs, which leaves "
                    f"the comparison's own figures as they are); {RELATIVE}")
    pl.add_argument("--svg", action="store_true", help="also write each figure as SVG")
    pl.add_argument("--allow-different-horizons", action="store_true",
                    help="overlay runs of different start time, stop time or step")
    pl.set_defaults(func=cmd_plot)

    # The paper study's own commands (orchestrator/paper): what docs/paper-*.md, calibration.md and
    # theorem1.md print
    def paper_command(name, func, help, description):
        """The paper study's subcommand ``name``, which runs ``func``: its parser, for its arguments."""
        sp = sub.add_parser(name, help=help, description=description)
        sp.set_defaults(func=func)
        return sp

    pg = paper_command("paper-gains", cmd_paper_gains,
                       help="run the paper's gains (Eq. 40-43) at fine steps in the plain loop",
                       description="Run the paper's gains (Eq. 40-43) at fine steps in the plain loop and print "
                       "the table (docs/paper-gains.md).")
    pg.add_argument("--stop-time", type=float, default=0.5, help="horizon of every run [s] (default 0.5)")
    pg.add_argument("--steps", type=float, nargs="+", help="steps [s] (default 1e-6 1e-5 1e-4)")
    pg.add_argument("--cases", nargs="+", help="gain sets: 'Eq. 40-41', 'Eq. 42-43' (default both)")
    pg.add_argument("--laws", nargs="+", help="sc-dc, apd-dc (default both)")
    pg.add_argument("--readings", nargs="+", help="readings of the units: A, B (default both)")
    pg.add_argument("--plants", nargs="+", help="encoder, exact (default both)")
    pg.add_argument("--workers", type=int, default=1, help="processes (default 1)")
    pg.add_argument("--json", help="also write the rows to this JSON file")
    ca = paper_command("calibrate", cmd_calibrate,
                       help="calibrate the plant on the paper's APD-DC rows, predict SC-DC",
                       description="Calibrate the plant on APD-DC (the paper's Tables 1-2 or 4-5), predict SC-DC "
                       "and write the calibrated scenario (docs/calibration.md).")
    ca.add_argument("--target", required=True, choices=("simulation", "experiment"))
    fmu_args(ca)
    ca.add_argument("--work", help="folder for the runs (default results/calibration/<target>)")
    ca.add_argument("--horizon", type=float, help="fit horizon [s] (default: one period of the slowest reference)")
    ca.add_argument("--max-nfev", type=int, default=25, help="least_squares iterations budget (default 25)")
    ca.add_argument("--no-write", action="store_true", help="do not write the calibrated scenario file")
    ca.add_argument("--write-to", metavar="FILE", help="calibrated scenario file to write (default: "
                    "paper_<target>_calibrated.toml in the work folder; scenarios/paper_<target>_calibrated.toml "
                    "replaces the shipped one)")
    paper_command("null-models", cmd_null_models,
                  help="score the null models on the paper's reductions (no simulation)",
                  description="Print how the null models (constants, the gain ratio) score on the paper's "
                  "printed reductions (docs/paper-reproduction.md).")
    paper_command("theorem1", cmd_theorem1, help="Theorem 1's counterexample and Eq. 31 on a random state",
                  description="Print the counterexample's eigenvalues for both laws and both sides of Eq. 31 "
                  "on a random state (docs/theorem1.md).")
    mo = paper_command("modal", cmd_modal, help="the laws' modal gains of gain presets",
                       description="Print the modal gains of SC-DC and APD-DC for gain presets "
                       "(docs/modal-view.md).")
    mo.add_argument("presets", nargs="*", metavar="PRESET", help="gain presets (default: default, "
                    "paper_simulation, paper_experiment)")
    return p


@contextmanager
def _signals_interrupt():
    """For the duration, SIGINT, SIGTERM and SIGHUP stop the run in progress on the main thread
    at its next step boundary (stops.deliver_signal) or, without one, raise Interrupted once and
    let the clean-up (folders, locks, a study's workers) finish undisturbed by repeats. The only
    signal handler of the package; main thread only. A worker process forked by `tapmp compare`
    inherits it: there a signal stops the worker's run, or is ignored while it is idle (the
    parent stops the set)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    from .tool.stops import STOP_SIGNALS, Interrupted, deliver_signal
    command = os.getpid()

    def interrupt(signum, frame):
        if deliver_signal(signum) or os.getpid() != command:
            return
        for s in STOP_SIGNALS:
            signal.signal(s, signal.SIG_IGN)
        raise Interrupted(signum)

    previous = {s: signal.signal(s, interrupt) for s in STOP_SIGNALS}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, signal.SIG_DFL if handler is None else handler)


def single_threaded_blas() -> None:
    """One BLAS thread per process unless the environment says otherwise (OPENBLAS_NUM_THREADS),
    set before numpy is loaded: the matrices here are tiny (at most some 40 x 40), where OpenBLAS's
    threads only wait on each other (the robustness analysis of a comparison took 7.8 s of wall
    time with them on a busy 2-core machine, 1.8 s without), and the commands run in parallel
    by processes (--jobs, Dask workers), which inherit the setting."""
    if "numpy" not in sys.modules:
        os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def main(argv=None) -> int:
    """The `tapmp` command; returns its exit code: 0, 1 (`check`: not stable; `study`: a case
    failed), 2 (an error, one line on stderr) or 128 + N after signal N (SIGINT 130, SIGHUP 129,
    SIGTERM 143)."""
    argv = sys.argv[1:] if argv is None else [str(a) for a in argv]
    single_threaded_blas()
    args = parser().parse_args(argv)
    args.command_line = "tapmp " + shlex.join(argv)  # what was typed, as comparison.md and study.json record it
    errors = user_errors()
    from .tool.results import one_line
    try:
        with _signals_interrupt():
            return args.func(args)
    except KeyboardInterrupt as err:
        import logging
        # a stopped study's Dask client tasks end with AllExit, which asyncio reports at exit as "never
        # retrieved": the line below stays the command's last word
        logging.getLogger("asyncio").setLevel(logging.CRITICAL)
        print(f"{one_line(err) if str(err) else 'interrupted'}: the results so far are in the output folder",
              file=sys.stderr)
        return getattr(err, "exit_code", 130)
    except errors as err:
        if args.debug:
            traceback.print_exc()
        print(f"error: {one_line(err)}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
