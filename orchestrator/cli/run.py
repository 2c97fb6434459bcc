"""Runs and their figures: `tapmp run` (one scenario), `tapmp compare` (SC-DC, APD-DC and the fair
baselines) and `tapmp plot`, with the summaries run and compare print."""

from pathlib import Path

from ..errors import UsageError
from .common import (compare_runs, jobs, load_scenario, names, result_base, ssp_of, warn_if_implausible,
                     warn_if_unstable)
from .options import PATHS_HELP, RELATIVE, jobs_arg, real_time_args, scenario_args

MODE_SHAPES = ((1, 1, 1), (1, 0, -1), (1, -2, 1))  # the motors' shares of each mode (tapmp.modal.MODES)
PLOT_SIGNALS = ("e1..e3 tracking error of each motor [µm] (also q1_err..q3_err), es1..es3 synchronization "
                "errors [µm], eX, eZ [µm], eB [µrad] axis errors, F1..F3 force commands [N], q1..q3 motor positions "
                "[mm], X, Z [mm], B [deg] platform pose, or a recorded column by its full name (e.g. controller.u1) "
                "in SI units")


def add_run(sub) -> None:
    """`tapmp run`."""
    r = sub.add_parser("run", help="run one scenario", description="Co-simulate one scenario and write "
                       "results.csv (or results.mat), run.json and metrics.json into its output folder, by default "
                       "<output>/<law>, e.g. results/paper_simulation/sc-dc.", epilog=PATHS_HELP)
    scenario_args(r)
    real_time_args(r)
    r.set_defaults(func=cmd_run)


def cmd_run(args) -> int:
    """`tapmp run`: one scenario into its output folder; its errors and moves printed."""
    pacing = pacing_of(args)
    scenario = load_scenario(args)
    if pacing is not None:
        check_compiled_core(scenario)
    warn_if_implausible(scenario)
    warn_if_unstable(scenario)
    out = Path(args.out) if args.out else result_base(scenario) / scenario.law
    from ..tool.estimate import check_output_size
    check_output_size([scenario], out, scenario.name)
    m = _run_one(scenario, ssp_of(args, scenario), out, args.overwrite, not args.no_progress, scenario.name, pacing)
    print(f"{scenario.name} ({scenario.law}): results in {out}")
    if pacing is not None:
        from ..tool.folders import read_json
        for line in real_time_lines(read_json(out / "run.json")["real_time"]):
            print(line)
    print("tracking MAE [um]: " + ", ".join(f"{v:.4f}" for v in m["tracking_mae_um"]))
    print("sync MAE [um]:     " + ", ".join(f"{v:.4f}" for v in m["sync_mae_um"]))
    if "tracking_mean_um" in m:
        from tapmp.laws import MODE_LABELS
        print("steady (mean) error per mode [um]: " + ", ".join(
            f"{name} {v:+.4f}" for name, v in zip(MODE_LABELS, mode_means(m)))
            + "   (e = common (1,1,1) + diff. Z (1,0,-1) + diff. B (1,-2,1))")
    for line in move_lines({scenario.law: m}):
        print(line)
    return 0


def _run_one(scenario, ssp, out, overwrite, progress, label, pacing=None):
    from ..tool.progress import progress_bar
    from ..tool.results import run_scenario
    update, close = progress_bar(label, progress)
    try:
        return run_scenario(scenario, ssp, out, overwrite, update, pacing=pacing)
    finally:
        close()


def pacing_of(args):
    """The engine.pacing.Pacing of --real-time and its options, None without it; UsageError for an
    option without --real-time or a value that is not allowed."""
    extra = [name for name, given in (("--overrun", args.overrun), ("--real-time-trace", args.real_time_trace),
                                      ("--rt-priority", args.rt_priority), ("--spin-margin", args.spin_margin))
             if given not in (None, False)]
    if args.real_time is None:
        if extra:
            raise UsageError(f"{extra[0]} is for a paced run: it goes with --real-time [FACTOR]")
        return None
    import math
    from ..engine.pacing import SPIN_MARGIN_S, Pacing

    def number(name, text, allowed):
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not math.isfinite(value) or not allowed(value):
            raise UsageError(f"{name} = {text!r} is invalid: allowed is {ALLOWED[name]}")
        return value
    factor = number("--real-time", args.real_time, lambda v: v > 0)
    margin = SPIN_MARGIN_S if args.spin_margin is None else \
        number("--spin-margin", args.spin_margin, lambda v: 0 <= v <= 100000) * 1e-6
    priority = None
    if args.rt_priority is not None:
        priority = int(number("--rt-priority", args.rt_priority, lambda v: v == int(v) and 1 <= v <= 99))
    return Pacing(factor, args.overrun or "continue", margin, args.real_time_trace, priority)


ALLOWED = {"--real-time": "a finite number > 0 (simulated seconds per wall second: 1 the wall clock, 0.5 half "
                          "speed, 10 ten times faster)",
           "--spin-margin": "a number of microseconds in [0, 100000]",
           "--rt-priority": "an integer in [1, 99]"}


def check_compiled_core(scenario) -> None:
    """UsageError unless ``scenario`` would step in the compiled stepping core (real time needs it)."""
    import os
    from ..engine import stepper
    why = None
    if os.environ.get("TAPMP_STEPPER") == "python":
        why = "TAPMP_STEPPER=python selects the Python loop"
    elif scenario.plant_interface == "me":
        why = "a Model Exchange plant (plant_interface = \"me\") steps in the Python loop"
    elif not stepper.available(quiet=True):
        why = "it cannot be built or loaded on this machine"
    if why:
        raise UsageError(f"real time (--real-time) needs the compiled stepping core: {why}")


def real_time_lines(rt: dict) -> list[str]:
    """The summary of a paced run's statistics (run.json "real_time"): a few lines."""
    def us(v):
        return "n/a" if v is None else f"{v * 1e6:.1f}"
    late, run = rt["lateness_s"], rt["execution_s"]
    measures = "; ".join(f"{name} {'applied' if m['applied'] else 'not applied'} ({m['detail']})"
                         for name, m in rt["measures"].items())
    return [f"real time: factor {rt['factor']:g} (period {rt['period_s'] * 1e6:g} us), overrun policy "
            f"{rt['overrun_policy']}, {rt['steps']} steps, achieved factor "
            f"{rt['achieved_factor'] or 0:.4g}",
            f"  lateness [us] (completion - deadline, > 0 overrun): p50 {us(late['p50'])}, p99 {us(late['p99'])}, "
            f"p99.9 {us(late['p999'])}, max {us(late['max'])}; execution [us]: p50 {us(run['p50'])}, "
            f"p99 {us(run['p99'])}, max {us(run['max'])}",
            f"  overruns: {rt['overruns']} (longest run {rt['longest_overrun_run']}, slots dropped "
            f"{rt['dropped_slots']})",
            f"  measures: {measures}"]


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


def summary_text(results: dict) -> str:
    """The short table `tapmp compare` prints: one row per run (orchestrator.tool.report.summary_rows:
    SC-DC's reduction against each run), its force effort and the steady (mean) tracking error on
    each mode (mode_means)."""
    from ..tool.report import summary_rows
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


def add_compare(sub) -> None:
    """`tapmp compare`."""
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


def cmd_compare(args) -> int:
    """`tapmp compare`: every run of the comparison, comparison.md and figures; the summary printed."""
    scenario = load_scenario(args)
    warn_if_implausible(scenario)
    out = Path(args.out) if args.out else result_base(scenario) / "compare"
    command = args.command_line
    n_jobs = jobs(args)
    show = names(args.runs)
    if show and args.no_figures:
        raise UsageError("--runs chooses the runs the figures show: it cannot go with --no-figures")
    if show:  # before any run starts
        from ..tool.plots import select_runs
        select_runs(out, list(compare_runs(scenario)), show)
    from ..paper.paper_tables import reference_rows
    from ..tool.compare import run_comparison
    _, results, _, _ = run_comparison(scenario, ssp_of(args, scenario), out, args.overwrite, not args.no_progress,
                                      command, n_jobs, show, not args.no_figures, noise=not args.no_noise,
                                      reference=reference_rows(scenario.name))
    print(f"{scenario.name}: mean over the three motors; SC-DC's reduction against each run, positive = SC-DC has "
          "the smaller error")
    print("mean: the steady tracking error per mode, e = common (1,1,1) + diff. Z (1,0,-1) + diff. B (1,-2,1)")
    print(summary_text(results))
    for line in move_lines(results, ("X", "Z", "B")):  # the motors' too in each run's metrics.json
        print(line)
    print(f"results{'' if args.no_figures else ', figures'} and the full tables (comparison.md) in {out}")
    return 0


def add_plot(sub) -> None:
    """`tapmp plot`."""
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


def cmd_plot(args) -> int:
    """`tapmp plot`: the figures of one result folder, or of several run folders overlaid."""
    from ..tool.plots import parse_window, plot_runs
    window = parse_window(args.window)
    written = plot_runs(args.result_dir, args.label, names(args.signals), window,
                        Path(args.out) if args.out else None, args.svg, args.allow_different_horizons,
                        names(args.runs))
    for path in written:
        print(f"wrote {path}")
    return 0
