"""Command-line tool ``tapmp`` (also ``python -m orchestrator``).

One module per command group, each registering its subcommands beside their handlers: ``build``
(build, export), ``run`` (run, compare, plot and their printed summaries), ``analysis`` (check,
analyze), ``study``, ``paper`` (reproduce and the paper study's commands). ``options`` holds the
option blocks several commands share, ``common`` what the commands share when they run,
``signals`` the signal handler.

Only light modules are imported at the top of every module here: `tapmp --help` and a refused
option print before numpy, fmpy, pydantic or matplotlib are loaded; each command imports what it
runs.
"""

import os
import shlex
import sys
import traceback

from ..errors import UserError
from . import analysis, build, paper, run, study
from .options import PATHS_HELP, Parser
from .signals import signals_interrupt

# What `tapmp` prints as one line (exit code 2): the project's user errors (bad input, a run or
# build that failed for a reason it names) and OSError (a file or folder the user named, a full
# disk, a scheduler address). Every other exception is a programming error and shows its traceback.
USER_ERRORS = (UserError, OSError)

# Every subcommand, in the order `tapmp --help` lists them; each is defined in its group's module.
SUBCOMMANDS = (build.add_build, run.add_run, analysis.add_check, analysis.add_analyze, analysis.add_frf, run.add_compare,
               paper.add_reproduce, study.add_study, build.add_export, run.add_plot, paper.add_paper_gains,
               paper.add_calibrate, paper.add_null_models, paper.add_theorem1, paper.add_modal)


def parser() -> Parser:
    """The parser of `tapmp` and every subcommand."""
    p = Parser(prog="tapmp", description=(
        "Co-simulate the TAPMP (three-axis parallel motion platform) FMUs: build them, run "
        "scenarios, compare SC-DC with APD-DC, plot results."), epilog=PATHS_HELP)
    p.add_argument("--debug", action="store_true", help="show the traceback of an error")
    sub = p.add_subparsers(dest="command", required=True)
    for add in SUBCOMMANDS:
        add(sub)
    return p


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
    from ..tool.results import one_line
    try:
        with signals_interrupt():
            return args.func(args)
    except KeyboardInterrupt as err:
        import logging
        # a stopped study's Dask client tasks end with AllExit, which asyncio reports at exit as "never
        # retrieved": the line below stays the command's last word
        logging.getLogger("asyncio").setLevel(logging.CRITICAL)
        print(f"{one_line(err) if str(err) else 'interrupted'}: the results so far are in the output folder",
              file=sys.stderr)
        return getattr(err, "exit_code", 130)
    except USER_ERRORS as err:
        if args.debug:
            traceback.print_exc()
        print(f"error: {one_line(err)}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
