"""The option blocks several commands share, each defined once, and the parser's one-line errors.

Light imports only (see the package's docstring): `tapmp --help` loads no numerical library.
"""

import argparse

from ..builder.families import ENV as FMUS_DIR_ENV, FAMILIES
from ..tool.folders import RESULT_FORMATS  # stdlib and filelock only: --help loads no numerical package
from .common import shipped_names

RELATIVE = "a relative path is relative to the current directory"
PATHS_HELP = ("Paths: scenario files, --out, --ssp, --fmus-dir and a scenario's 'output' are relative to the "
              "current directory; a scenario may also be named (paper_simulation: the scenario shipped with the "
              "package); a scenario's gains_file is relative to the scenario file; the SSP of --fmus is found in "
              f"--fmus-dir, else ${FMUS_DIR_ENV}, else the repository's build/ (in a checkout) or ./build "
              "(installed as a wheel).")
FMUS_DIR_HELP = (f"folder of the built FMUs, as `tapmp build --out DIR` writes it (default: ${FMUS_DIR_ENV}, else "
                 "the repository's build/ in a checkout, else ./build)")


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


def family(value: str) -> str:
    """--fmus: a family name, else the one-line refusal with the closest names."""
    if value not in FAMILIES:
        from tapmp.errors import allowed_are
        raise argparse.ArgumentTypeError(f"fmus = {value!r} is invalid: {allowed_are(value, FAMILIES)}")
    return value


def result_format(value: str) -> str:
    """--format: a result file format, else the one-line refusal with the closest names."""
    if value not in RESULT_FORMATS:
        from tapmp.errors import allowed_are
        raise argparse.ArgumentTypeError(f"format = {value!r} is invalid: {allowed_are(value, RESULT_FORMATS)}")
    return value


def fmu_args(sp) -> None:
    """--ssp, --fmus and --fmus-dir: the FMUs a command runs (run, compare, export, reproduce, study)."""
    sp.add_argument("--ssp", help="SSP system file (default: the built SSP of --fmus)")
    sp.add_argument("--fmus", type=family, metavar="{" + ",".join(FAMILIES) + "}", help="FMU family: native "
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


def source_args(sp) -> None:
    """The scenario, its --set overrides and the SSP it runs on (run, compare, export)."""
    scenario_arg(sp, "--set stop_time=0.5 --set plant.k_pull=0")
    fmu_args(sp)


def recording_args(sp) -> None:
    """--format and --record-every: what the result files keep."""
    sp.add_argument("--format", type=result_format, metavar="{" + ",".join(RESULT_FORMATS) + "}", help="result files: csv (results.csv, text) or mat "
                    "(results.mat, MATLAB 5 MAT-file, about 40 %% of the size and faster to write); overrides "
                    "the scenario's format (default csv)")
    sp.add_argument("--record-every", metavar="N", help="keep every N-th step (and the last) "
                    "in the result files; the metrics still use every step (default: the scenario's "
                    "record_every, 1)")


def progress_arg(sp) -> None:
    """--no-progress."""
    sp.add_argument("--no-progress", action="store_true", help="no progress bar")


def jobs_arg(sp, what: str) -> None:
    """--jobs: how many ``what`` run at once."""
    sp.add_argument("--jobs", metavar="N", help=f"{what} at once, each in its own process (default: one per "
                    "core)")


def scenario_args(sp) -> None:
    """What run and compare share: the scenario and its FMUs, the output folder, recording, progress."""
    source_args(sp)
    sp.add_argument("--out", help=f"output folder (default: the scenario's 'output', else results/<name>, "
                    f"then /<law> for run, /compare for compare); {RELATIVE}")
    sp.add_argument("--overwrite", action="store_true", help="replace a completed result in the output folder "
                    "(a failed or interrupted one is replaced without it)")
    recording_args(sp)
    progress_arg(sp)


def real_time_args(sp) -> None:
    """--real-time [FACTOR] and what goes with it (tapmp run)."""
    sp.add_argument("--real-time", nargs="?", const="1", metavar="FACTOR", help="keep every step to the wall "
                    "clock: FACTOR simulated seconds per second (no value: 1, the wall clock; 0.5 half speed; 10 ten "
                    "times faster); run.json gets the steps' lateness and execution time under real_time, and "
                    "real_time.png is drawn (docs/performance.md, Real time). Needs the compiled stepping core")
    sp.add_argument("--overrun", choices=("continue", "skip", "abort"), help="with --real-time, after a step "
                    "finished late: continue (default; keep the schedule, late steps back to back until caught up), "
                    "skip (start the next step at the next slot still ahead; the run takes longer) or abort (stop "
                    "the run, failed)")
    sp.add_argument("--real-time-trace", action="store_true", help="with --real-time: also write every step's "
                    "lateness and execution time into real_time_trace.csv")
    sp.add_argument("--rt-priority", metavar="N", help="with --real-time: run the stepping thread at SCHED_FIFO "
                    "priority N (1-99) if the system allows it (not by default: a thread spinning at real-time "
                    "priority can starve the machine's other work)")
    sp.add_argument("--spin-margin", metavar="US", help="with --real-time: sleep until US microseconds before "
                    "each step's start, then spin (default 60: above the usual wake-up latency of a kernel without real-time "
                    "preemption, below the 100 us servo period, so that a SCHED_FIFO thread sleeps in every period; "
                    "docs/performance.md, Real time)")
