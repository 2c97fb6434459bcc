"""The paper study's commands (orchestrator/paper): `tapmp reproduce` (the paper-reproduction page)
and what docs/paper-*.md, calibration.md, theorem1.md and modal-view.md print: `paper-gains`,
`calibrate`, `null-models`, `theorem1`, `modal`."""

import sys
from pathlib import Path

from ..builder.families import SCENARIOS_DIR
from ..errors import UsageError
from .common import (check_workers, choices, compare_runs, heartbeat, jobs, record_every, recording,
                     recording_changes, ssp_of)
from .options import RELATIVE, fmu_args, jobs_arg, progress_arg, recording_args


def add_reproduce(sub) -> None:
    """`tapmp reproduce`."""
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


def check_reproduce_may_replace(folder: Path, overwrite: bool) -> None:
    """OutputExistsError (one line) if ``folder`` holds a completed comparison that `tapmp reproduce`
    did not write (comparison.json's written_by), unless ``overwrite``; reproduce replaces its own."""
    import json
    from ..tool.folders import COMPARISON_JSON, OutputExistsError, folder_completed, marked_kind
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
    """`tapmp reproduce`: compare on both paper scenarios (and their calibrated versions), the
    paper's gains at fine steps, and the paper-reproduction page."""
    from ..tool.estimate import check_output_size
    from ..paper.reproduction import reproduce
    from ..tool.scenario import load
    command = args.command_line
    n_jobs = jobs(args)

    results = Path(args.results)
    page = Path(args.out) if args.out else results / "paper-reproduction.md"
    if not 0 < args.paper_gains_stop_time < float("inf"):
        raise UsageError(f"--paper-gains-stop-time = {args.paper_gains_stop_time:g} is invalid: allowed is a "
                         "finite horizon > 0 s")
    check_workers(args.workers)
    if page.suffix != ".md":
        raise UsageError(f"--out = {str(page)!r} is invalid: allowed is a Markdown file ending in .md")
    if args.record_every is not None:
        record_every(args.record_every)
    from ..paper.reproduction import SCENARIOS
    files = [Path(args.scenarios) / f"{name}{suffix}.toml" for suffix in ("", "_calibrated") for name in SCENARIOS]
    for f in files[:len(SCENARIOS)]:
        if not f.is_file():
            raise UsageError(f"--scenarios = {args.scenarios!r}: no {f.name} there: allowed is a folder with "
                             + " and ".join(f"{name}.toml" for name in SCENARIOS))
    runs = [sc for f in files if f.is_file() for sc in compare_runs(recording(args, load(f))).values()]
    check_output_size(runs, results, "reproduce", n_jobs)  # every compare run, before the first starts
    for f in files:  # before the first run: a comparison `tapmp compare` completed is not replaced silently
        if f.is_file():
            check_reproduce_may_replace(results / f.stem / "compare", args.overwrite)

    with heartbeat() as tell:
        text = reproduce(Path(args.scenarios), results, page, command, ssp_of=lambda sc: ssp_of(args, sc),
                         changes=recording_changes(args), progress=not args.no_progress, jobs=n_jobs,
                         paper_gains_stop=args.paper_gains_stop_time, workers=args.workers, ssp=ssp_of(args),
                         say=tell)
    print(f"wrote {page}")
    if args.write_docs:
        docs = Path("docs") / "paper-reproduction.md"
        if not docs.parent.is_dir():
            raise UsageError(f"--write-docs: no folder {docs.parent.absolute()}: run it from the repository root")
        from ..tool.folders import write_text
        write_text(docs, text)
        print(f"wrote {docs}")
    return 0


def paper_command(sub, name, func, help, description):
    """The paper study's subcommand ``name``, which runs ``func``: its parser, for its arguments."""
    sp = sub.add_parser(name, help=help, description=description)
    sp.set_defaults(func=func)
    return sp


def add_paper_gains(sub) -> None:
    """`tapmp paper-gains`."""
    pg = paper_command(sub, "paper-gains", cmd_paper_gains,
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


def cmd_paper_gains(args) -> int:
    """`tapmp paper-gains`: the paper's gains (Eq. 40-43) at fine steps in the plain loop; the table
    on stdout (progress on stderr), the rows also to --json."""
    from ..paper.paper_gains import CASES, LAWS, PLANTS, READINGS, paper_gains_table, run_paper_gains
    cases = choices("--cases", args.cases or list(CASES), CASES)
    laws = choices("--laws", args.laws or list(LAWS), LAWS)
    readings = choices("--readings", args.readings or list(READINGS), READINGS)
    plants = choices("--plants", args.plants or list(PLANTS), PLANTS)
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
        from ..tool.folders import write_text
        write_text(Path(args.json), json.dumps(rows, indent=1))
    return 0


def add_calibrate(sub) -> None:
    """`tapmp calibrate`."""
    ca = paper_command(sub, "calibrate", cmd_calibrate,
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


def cmd_calibrate(args) -> int:
    """`tapmp calibrate`: fit the plant on the paper's APD-DC rows, predict SC-DC, write the
    calibrated scenario."""
    import math
    if args.horizon is not None and not (math.isfinite(args.horizon) and args.horizon > 0.0):
        raise UsageError(f"--horizon = {args.horizon!r} is invalid: allowed is a number > 0 [s]")
    if args.max_nfev < 1:
        raise UsageError(f"--max-nfev = {args.max_nfev!r} is invalid: allowed is an integer >= 1")
    from ..paper.calibration import calibrate_and_predict, calibrated_file
    ssp = ssp_of(args)
    work = Path(args.work or Path("results") / "calibration" / args.target)
    write_to = None if args.no_write else Path(args.write_to or work / calibrated_file(args.target).name)
    try:
        lines = calibrate_and_predict(args.target, ssp, work, args.horizon, args.max_nfev, write_to)
    except ValueError as err:
        raise UsageError(str(err)) from None
    print("\n".join(lines))
    return 0


def add_null_models(sub) -> None:
    """`tapmp null-models`."""
    paper_command(sub, "null-models", cmd_null_models,
                  help="score the null models on the paper's reductions (no simulation)",
                  description="Print how the null models (constants, the gain ratio) score on the paper's "
                  "printed reductions (docs/paper-reproduction.md).")


def cmd_null_models(args) -> int:
    """`tapmp null-models`: the null models' scores on the paper's printed reductions."""
    from ..paper.null_models import null_model_table
    print(null_model_table())
    return 0


def add_theorem1(sub) -> None:
    """`tapmp theorem1`."""
    paper_command(sub, "theorem1", cmd_theorem1, help="Theorem 1's counterexample and Eq. 31 on a random state",
                  description="Print the counterexample's eigenvalues for both laws and both sides of Eq. 31 "
                  "on a random state (docs/theorem1.md).")


def cmd_theorem1(args) -> int:
    """`tapmp theorem1`: the counterexample's eigenvalues for both laws and Eq. 31 on a random state."""
    from ..paper.theorem1 import summary_lines
    print("\n".join(summary_lines()))
    return 0


def add_modal(sub) -> None:
    """`tapmp modal`."""
    mo = paper_command(sub, "modal", cmd_modal, help="the laws' modal gains of gain presets",
                       description="Print the modal gains of SC-DC and APD-DC for gain presets "
                       "(docs/modal-view.md).")
    mo.add_argument("presets", nargs="*", metavar="PRESET", help="gain presets (default: default, "
                    "paper_simulation, paper_experiment)")


def cmd_modal(args) -> int:
    """`tapmp modal [PRESET ...]`: the laws' modal gains of gain presets (tapmp.modal.modal_table)."""
    from tapmp.modal import modal_table
    from tapmp.params import GAIN_PRESETS
    names = choices("preset", args.presets or ["default", "paper_simulation", "paper_experiment"], GAIN_PRESETS)
    print(modal_table(list(names)))
    return 0
