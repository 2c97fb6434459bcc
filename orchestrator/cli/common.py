"""What the commands share when they run: the scenario or study a name stands for, the SSP of
--ssp/--fmus, the checked values of shared options, the warnings before a run, a heartbeat.

Light imports only (see the package's docstring); each function imports what it runs.
"""

import sys
import threading
from contextlib import contextmanager
from pathlib import Path

from ..builder.families import DEFAULT_FAMILY, data_dir, resolve_ssp
from ..errors import UsageError

MAX_WORKERS = 4096  # processes one command may start; bounded before the number reaches the OS or Dask


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
    from ..tool.scenario import tomllib
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


def ssp_of(args, scenario=None, drive: bool | None = None) -> Path:
    """--ssp, else the SSP of --fmus, else of the scenario's ``fmus`` (default native); with the drive in the
    loop if ``drive``, by default if the scenario has it."""
    fmus = args.fmus or (scenario.fmus if scenario is not None else DEFAULT_FAMILY)
    if drive is None:
        drive = scenario is not None and scenario.drive is not None
    return resolve_ssp(args.ssp, fmus, getattr(args, "fmus_dir", None), drive)


def record_every(value) -> int:
    """--record-every checked: an integer from 1 to MAX_INT (the scenario key's bound)."""
    from ..tool.scenario import MAX_INT
    try:
        n = int(value)
    except ValueError:
        n = 0
    if not 1 <= n <= MAX_INT:
        raise UsageError(f"--record-every = {value!r} is invalid: allowed is an integer from 1 to {MAX_INT} "
                         "(keep every N-th step)")
    return n


def recording_changes(args) -> dict:
    """The --format and --record-every of ``args`` (where given) as scenario changes."""
    changes = {}
    if getattr(args, "format", None):
        changes["format"] = args.format
    if getattr(args, "record_every", None) is not None:
        changes["record_every"] = record_every(args.record_every)
    return changes


def recording(args, scenario):
    """``scenario`` with the --format and --record-every of ``args`` (where given)."""
    changes = recording_changes(args)
    return scenario.with_changes(**changes) if changes else scenario


def load_scenario(args):
    """The scenario of a run/compare command: the file, its --set overrides, --format and --record-every."""
    from ..tool.scenario import load
    return recording(args, load(scenario_file(args.scenario), args.set))


def result_base(scenario) -> Path:
    """The scenario's result folder: its ``output``, else results/<name> (relative to the
    current directory); `tapmp run` writes into <base>/<law>, `tapmp compare` into <base>/compare."""
    return Path(scenario.output or Path("results") / scenario.name)


def compare_runs(scenario):
    """The runs of `tapmp compare` ({folder name: Scenario}): SC-DC, APD-DC (Eq. 41) and the fair
    baselines and ablations of orchestrator.tool.baselines."""
    from ..tool.baselines import compare_runs as runs
    return runs(scenario)


def check_workers(workers: int) -> None:
    """--workers: UsageError unless 1 to MAX_WORKERS processes."""
    if workers < 1:
        raise UsageError(f"--workers = {workers} is invalid: allowed is an integer >= 1")
    if workers > MAX_WORKERS:
        raise UsageError(f"--workers = {workers} is invalid: allowed is an integer from 1 to {MAX_WORKERS}")


def jobs(args) -> int:
    """--jobs checked: a positive integer up to the cores (default: one per core)."""
    from ..tool.pool import parse_jobs
    return parse_jobs(args.jobs)


def names(text) -> list | None:
    """A comma-separated option (--runs, --signals) as a list; None if not given."""
    return None if text is None else [v.strip() for v in text.split(",") if v.strip()]


def choices(option: str, values: list, allowed) -> tuple:
    """``values`` of a repeatable option, each one of ``allowed``; else the one-line refusal."""
    from tapmp.errors import allowed_are
    for v in values:
        if v not in allowed:
            raise UsageError(f"{option} = {v!r} is invalid: {allowed_are(v, list(allowed))}")
    return tuple(values)


def warn_if_implausible(scenario) -> None:
    """One warning line on stderr per parameter far outside this machine's usual range."""
    from ..tool.plausibility import implausible
    for line in implausible(scenario):
        print(f"warning: {line}", file=sys.stderr, flush=True)


def warn_if_unstable(scenario) -> None:
    """One line on stderr if the stability pre-check finds the scenario's loop unstable."""
    from ..tool.stability import check, radius_text
    report = check(scenario)
    if not report.stable:
        print(f"warning: {scenario.name}: the sampled closed loop is {report.verdict} (spectral radius "
              f"{radius_text(report.spectral_radius)}, stable needs < 1 - 1e-6, at h = {scenario.step:g} s, {scenario.ordering}); "
              f"see `tapmp check`", file=sys.stderr, flush=True)


@contextmanager
def heartbeat(tell=None, every: float = 10.0):
    """A ``tell(line)`` (default: tool.progress.say, a line on stderr) for the duration that
    also repeats the last line with the seconds since it whenever ``every`` seconds pass without
    one, so a long phase is never silent."""
    import time
    if tell is None:
        from ..tool.progress import say as tell
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
