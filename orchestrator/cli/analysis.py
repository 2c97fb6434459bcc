"""The linearized loop: `tapmp check` (the stability pre-check) and `tapmp analyze` (frequency
response, margins, poles; with --worst-case the worst margins over poses and a parameter box)."""

import argparse
import math
import sys
from pathlib import Path

from ..errors import UsageError
from .common import compare_runs, heartbeat, result_base, scenario_file, study_file
from .options import PATHS_HELP, RELATIVE, fmu_args, scenario_arg


def add_check(sub) -> None:
    """`tapmp check`."""
    ck = sub.add_parser("check", help="stability pre-check of a scenario's sampled loop",
                        description="Linearize the sampled closed loop (plant about the start pose, the "
                        "scenario's controller, step and ordering) and report the spectral radius of its "
                        "one-step map: stable if < 1 - 1e-6. Exit code 0 if stable, 1 if not.")
    scenario_arg(ck, "--set gains='\"paper_simulation\"'")
    ck.add_argument("--eigenvalues", action="store_true", help="list every eigenvalue")
    ck.add_argument("--fmus", help=argparse.SUPPRESS)  # refused with the reason (cmd_check), not "unrecognized"
    ck.set_defaults(func=cmd_check)


def cmd_check(args) -> int:
    """`tapmp check`: 0 if the scenario's sampled loop is stable, 1 if not."""
    from ..tool.scenario import load
    from ..tool.stability import check
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


def add_analyze(sub) -> None:
    """`tapmp analyze`."""
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


def cmd_analyze(args) -> int:
    """`tapmp analyze`: margins, robustness and poles of SC-DC and every baseline, printed and written."""
    from ..tool.analysis import analyze, pole_table, robustness_table, table
    from ..tool.scenario import load
    from ..tool.stability import verdict_for
    scenario = load(scenario_file(args.scenario), args.set)
    out = Path(args.out) if args.out else result_base(scenario) / "analysis"
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
        from ..tool.analysis import inserted_radius
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
    from ..studies import worst_case
    from ..studies.study_file import load_study
    from ..tool.folders import atomic_file, write_json
    from ..tool.progress import say
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


def add_frf(sub) -> None:
    """`tapmp frf`."""
    from ..tool import frf_settings as frf
    fr = sub.add_parser("frf", help="margins measured from the co-simulation (any SSP)",
                        description="Inject a seeded periodic multisine (random phases, interleaved frequency grids) "
                        "at the plant's force inputs of the closed-loop co-simulation, identify the input sensitivity "
                        "S = U/D and the loop gain L = -F_ctrl/U per input and per mode (common, diff. Z, diff. B) "
                        "from the co-simulation's own signals, and report Ms, gain, phase, disk and delay margins "
                        "from the measured points beside the analytic ones of the linearized loop (TAPMP's FMUs "
                        "only); frf.json and a Bode/Nyquist figure per run. See docs/analysis.md.",
                        epilog=PATHS_HELP)
    scenario_arg(fr, "--set trajectory.f_xz=0")
    fmu_args(fr)
    fr.add_argument("--out", help=f"output folder (default: the scenario's 'output', else results/<name>, then /frf); "
                    f"{RELATIVE}")
    fr.add_argument("--runs", default=None, metavar="NAMES", help="comma-separated runs of `compare` to measure "
                    "(default: the scenario's own law)")
    fr.add_argument("--inputs", default=None, metavar="NAMES", help="comma-separated plant force inputs to excite, "
                    "\"element.variable\" (an element by its SSP name or role; default: the TAPMP plant's F1,F2,F3 "
                    "by role: plant.F1,plant.F2,plant.F3)")
    fr.add_argument("--amplitude", type=float, default=frf.AMPLITUDE, metavar="N",
                    help=f"RMS of the injected force per direction (default {frf.AMPLITUDE:g}, in the inputs' unit)")
    fr.add_argument("--seed", type=int, default=0, help="seed of the multisine's random phases (default 0)")
    fr.add_argument("--period", type=float, default=frf.PERIOD, metavar="SECONDS",
                    help=f"period of the multisine, a whole number of steps (default {frf.PERIOD:g} s; the "
                    "frequency resolution is its inverse)")
    fr.add_argument("--periods", type=int, default=frf.PERIODS, help=f"periods measured and averaged (default "
                    f"{frf.PERIODS})")
    fr.add_argument("--transient", type=int, default=frf.TRANSIENT, help="periods run before the measurement "
                    f"(default {frf.TRANSIENT})")
    fr.add_argument("--f-min", type=float, default=None, metavar="HZ", help="lowest excited frequency (default "
                    "1 / --period)")
    fr.add_argument("--f-max", type=float, default=None, metavar="HZ", help="highest excited frequency (default: "
                    "the highest DFT bin below the Nyquist frequency 1/(2 step))")
    fr.add_argument("--points", type=int, default=frf.POINTS, help=f"excited frequencies per direction (default "
                    f"{frf.POINTS})")
    fr.add_argument("--overwrite", action="store_true", help="replace frf.json and the figures of a former "
                    "measurement in --out (without it they stop the command before it runs)")
    fr.set_defaults(func=cmd_frf)


def cmd_frf(args) -> int:
    """`tapmp frf`: the measured margins of the scenario's run (or --runs), printed and written."""
    from ..tool import frf
    from ..tool.scenario import load
    from .common import names, ssp_of
    scenario = load(scenario_file(args.scenario), args.set)
    if args.runs is None:
        runs = {scenario.law: scenario}
    else:
        every = compare_runs(scenario)
        runs = {}
        for name in names(args.runs):
            if name not in every:
                raise UsageError(f"--runs: {name!r} is not a run of compare: allowed are {', '.join(every)}")
            runs[name] = every[name]
    out = Path(args.out) if args.out else result_base(scenario) / "frf"
    there = [p for p in frf.files_of(out, runs) if p.exists() or p.is_symlink()]
    if there and not args.overwrite:
        raise UsageError(f"{there[0]} exists: allowed is --overwrite to replace it (or another --out)")
    from ..engine.errors import CoSimulationError
    try:
        with heartbeat() as tell:
            result = frf.measure(runs, ssp_of(args, scenario), names(args.inputs), args.period, args.f_min,
                                 args.f_max, args.points, args.amplitude, args.seed, args.transient, args.periods,
                                 say=tell)
    except CoSimulationError as err:  # the engine names its option; the user wrote --inputs
        if str(err).startswith("perturb: "):
            raise UsageError("--inputs: " + str(err).removeprefix("perturb: ")) from None
        raise
    e = result["excitation"]
    print(f"{scenario.name}: the closed loop broken at the plant inputs {', '.join(result['inputs'])}, one direction "
          f"at a time; multisine of {e['rms_per_direction']:g} RMS per direction, seed {result['seed']}, "
          f"{e['points_per_direction']} frequencies per direction from {e['from_hz']:g} to {e['to_hz']:g} Hz, "
          f"{e['measured_periods']} periods of {e['period_s']:g} s averaged after {e['transient_periods']}")
    print(frf.table(result))
    for name, r in result["runs"].items():
        share = f"{r['u_max'] / r['force_limit'] * 100.0:.0f} % of the force limit {r['force_limit']:g}" \
            if r["force_limit"] > 0 else "no force limit"
        print(f"{name}: max |u| = {r['u_max']:.4g} ({share}): "
              + ("linear" if r["linear"] else f"NOT linear (above {frf.LINEAR_SHARE:.0%}): lower --amplitude")
              + f"; analytic: {r['analytic']}")
    files = frf.write(result, out)
    print(f"frf.json and figures in {out} ({len(files)} files)")
    return 0
