"""comparison.md: the compare runs' metrics laid out like the paper's Tables 1-3, beside reference
rows a caller passes in (the paper study passes the paper's printed rows for its scenarios)."""

from pathlib import Path

from .baselines import BASELINES, BY_NAME, robustness_matched, run_gains_text, scdc_modal
from .metrics import METRIC_KEYS, QUANTITIES, reduction
from .folders import write_text

_TITLE = {"tracking": "tracking error of each motor", "sync": "synchronization error of each motor",
          "axis": "tracking error of each drive axis"}
# Runs whose reduction of SC-DC is shown in the tables (the paper's baseline and the fair ones).
REDUCTION_AGAINST = ("apd-dc", "apd-dc-diff-stiffness", "apd-dc-mode-matched")


def _label(run: str) -> str:
    return BY_NAME[run].label if run in BY_NAME else run


def comparison_tables(results: dict, reference: dict | None = None) -> str:
    """Markdown tables laid out like the paper's Tables 1-3 for metrics by run name.

    One row per run (in the order of baselines.BASELINES, other names after), the reduction
    of SC-DC against each run of REDUCTION_AGAINST present, then the rows of ``reference``
    ({quantity of metrics.QUANTITIES: (source, [(label, six cells as text)])}, e.g. the
    paper's rows as printed for its scenarios; the source is named in the table's title).
    Values in um (B in urad), three decimals.
    """
    order = [b.name for b in BASELINES if b.name in results] + [r for r in results if r not in BY_NAME]
    lines = []
    for kind, (labels, units) in QUANTITIES.items():
        unit = units[0] if len(set(units)) == 1 else ", ".join(units)
        source, rows = (reference or {}).get(kind, (None, ()))
        ref = f" ({source})" if source else ""
        lines += [f"### Comparison of the {_TITLE[kind]} [{unit}]{ref}", "",
                  "| Control strategy | " + " | ".join(f"STD {x}" for x in labels) + " | "
                  + " | ".join(f"MAE {x}" for x in labels) + " |",
                  "|---" * 7 + "|"]
        std_key, mae_key = METRIC_KEYS[kind]

        def row(label, std, mae):
            return f"| {label} | " + " | ".join(f"{v:.3f}" for v in (*std, *mae)) + " |"

        for run in order:
            lines.append(row(f"ours: {_label(run)}", results[run][std_key], results[run][mae_key]))
        sc = results.get("sc-dc")
        for run in REDUCTION_AGAINST:
            if sc and run in results:
                base = results[run]
                lines.append(row(f"ours: reduction of SC-DC vs {_label(run).split(' (')[0]} (%)",
                                 [reduction(b, s) for b, s in zip(base[std_key], sc[std_key])],
                                 [reduction(b, s) for b, s in zip(base[mae_key], sc[mae_key])]))
        for label, cells in rows:
            lines.append(f"| {label} | " + " | ".join(cells) + " |")
        lines.append("")
    lines += force_step_table(results, order)
    return "\n".join(lines)


def force_step_table(results: dict, order: list) -> list[str]:
    """Markdown lines: each run's response to the plant's force step (metrics.json force_step),
    nothing if no run has one. Changes of the mean tracking error e = q_d - q [um] from the window
    before the step to the last window of the run, and the peak change after the step."""
    runs = [r for r in order if "force_step" in results[r]]
    if not runs:
        return []
    fs = results[runs[0]]["force_step"]
    lines = [f"### Response to the force step at {fs['disturbance_time_s']:g} s [um]", "",
             f"Change of the mean tracking error from the {fs['window_s']:g} s before the step to the last "
             f"{fs['window_s']:g} s of the run (a steady error the law leaves), its mean over the motors (the "
             "common mode) and the largest change after the step.", "",
             "| Control strategy | change e1 | change e2 | change e3 | common mode | peak e1 | peak e2 | peak e3 |",
             "|---" * 8 + "|"]
    for run in runs:
        f = results[run]["force_step"]
        lines.append(f"| ours: {_label(run)} | " + " | ".join(
            f"{v:.3f}" for v in (*f["error_change_um"], f["common_mode_change_um"], *f["peak_error_change_um"]))
            + " |")
    return lines + [""]


def _mean(values) -> float:
    return sum(values) / len(values)


def modal_note(scenario) -> str:
    """One sentence: how the PID-DC rows' modal gains were obtained from the scenario's gains."""
    return (f"Modal gains of the PID-DC rows: {scdc_modal(scenario.gain_values())[1]}. "
            + robustness_matched(scenario).text())


_ANALYZED: dict = {}  # the last analyses by the runs' scenarios: `tapmp reproduce` shows each twice


def _analysis_key(runs: dict) -> str:
    import json
    return json.dumps({name: sc.to_dict() for name, sc in runs.items()}, sort_keys=True, default=repr)


def _keep_analysis(key: str, result: dict) -> None:
    if len(_ANALYZED) >= 8:
        _ANALYZED.pop(next(iter(_ANALYZED)))
    _ANALYZED[key] = result


def _grid(runs: dict):
    from . import analysis
    return analysis.frequency_grid(next(iter(runs.values())).step)


def _analyze(runs: dict, freqs=None) -> dict:
    """analysis.analyze_runs of ``runs`` ({name: Scenario}) on ``freqs`` [Hz] (default: the
    frequency grid of the first run's step)."""
    from . import analysis
    return analysis.analyze_runs(runs, _grid(runs) if freqs is None else freqs)


def _analyzed(runs: dict) -> dict:
    """_analyze(runs), computed once for the same scenarios (or taken from an AnalysisAside)."""
    key = _analysis_key(runs)
    if key not in _ANALYZED:
        _keep_analysis(key, _analyze(runs))
    return _ANALYZED[key]


class AnalysisAside:
    """The robustness analysis of a comparison's runs ({name: Scenario}) computed in forked
    processes while the runs go on (it needs none of their results and costs about as much as
    all the runs together): the runs split between ``processes`` processes, each analyzing its
    share (every run is analyzed on its own, so the parts are exactly the whole).
    :meth:`keep` waits for them and keeps the analysis for robustness_section (raising an
    error, if any); :meth:`close` ends the processes whatever happened. If a process died, the
    analysis is left to robustness_section, in this process."""

    def __init__(self, runs: dict, processes: int = 1):
        from concurrent.futures import ProcessPoolExecutor
        from multiprocessing import get_context
        from .pool import ignore_interrupts
        self.key, self.names = _analysis_key(runs), list(runs)
        self.pool, self.futures = None, []
        if self.key in _ANALYZED:
            return
        n = max(1, min(processes, len(runs)))
        self.pool = ProcessPoolExecutor(n, mp_context=get_context("fork"), initializer=ignore_interrupts)
        freqs = _grid(runs)
        # the runs dealt out in turn: the costly ones (stable loops get every measure) spread out
        self.futures = [self.pool.submit(_analyze, {k: runs[k] for k in self.names[i::n]}, freqs) for i in range(n)]

    def keep(self) -> None:
        from concurrent.futures.process import BrokenProcessPool
        if self.pool is None:
            return
        parts = {}
        try:
            for f in self.futures:
                parts.update(f.result())
        except BrokenProcessPool:
            return
        _keep_analysis(self.key, {name: parts[name] for name in self.names})

    def close(self) -> None:
        if self.pool is None:
            return
        for proc in list(getattr(self.pool, "_processes", {}).values()):
            if proc.is_alive():
                proc.kill()
        self.pool.shutdown(wait=True, cancel_futures=True)
        self.pool = None


def robustness_section(runs: dict) -> list[str]:
    """Markdown lines: each run's robustness on the sampled loop of `tapmp check` (tapmp analyze's
    measures, orchestrator.tool.analysis): Ms per mode, disk margins per loop and for all
    motors at once, the all-loops gain margin with the K_T error it covers, the smallest delay margin
    of one loop, the delay margin of all motors at once and the lowest actuator bandwidth. runs: {name: Scenario}."""
    from . import analysis
    result = {"runs": _analyzed(runs)}
    lines = ["| run | Ms common, diff. Z, diff. B | disk margin per loop: " + ", ".join(analysis.BREAK_POINTS)
             + " | all loops: disk margin (gain dB, phase deg) | all-loops gain margin (K_T error) "
             "| " + analysis.DELAY_COLUMNS + " | lowest actuator bandwidth [Hz] |", "|---" * 8 + "|"]
    for run, r in result["runs"].items():
        if r["verdict"] != "stable":
            lines.append(f"| {run} | the closed loop is {r['verdict']} (spectral radius {r['spectral_radius']:.4g}) "
                         "| - | - | - | - | - | - |")
            continue
        cells = analysis.robustness_cells(run, r)
        ms = ", ".join(f"{r['loops'][m]['Ms']:.3f}" for m in ("common", "diff. Z", "diff. B"))
        lines.append("| " + " | ".join([cells[0], ms, *cells[1:]]) + " |")
    return ["Computed on the linearized sampled loop of `tapmp check` (as `tapmp analyze`, docs/analysis.md): "
            "Ms = peak sensitivity at the plant input with one mode open; disk margin alpha (symmetric): any "
            "simultaneous gain in [(2 - alpha)/(2 + alpha), (2 + alpha)/(2 - alpha)] or phase within "
            "+-2 atan(alpha/2) on the opened loops keeps the loop stable; the all-loops gain margin scales all three "
            "motor forces at once (a K_T error, F = u / K_T); the delay margin (loop) is the smallest delay in one loop that "
            "destabilizes it, the delay margin (all motors) that of one delay on all three motors' forces at once (a "
            "shared computation delay); the actuator bandwidth is that of a first-order lag on every motor below which the "
            "loop is unstable.", "", *lines]


def runs_table(runs: dict, results: dict, checks: dict) -> str:
    """Markdown table of the compare runs: what each isolates, its gains, the stability
    pre-check (spectral radius, verdict) and the share of samples at the force limit [%].

    runs: {name: Scenario}; results: {name: metrics.json dict}; checks: {name: StabilityReport}.
    """
    lines = ["| run (folder) | law | what it isolates | gains (u units, F = u / K_T) | spectral radius, verdict "
             "| at force limit q1, q2, q3 [%] |", "|---" * 6 + "|"]
    for name, sc in runs.items():
        b = BY_NAME.get(name)
        c = checks.get(name)
        sat = results.get(name, {}).get("saturation_fraction")
        lines.append(f"| `{name}` | {sc.law.upper()} | {b.isolates if b else ''} | {run_gains_text(sc)} | "
                     + (f"{c.spectral_radius:.6f}, {c.verdict}" if c else "not checked") + " | "
                     + (", ".join(f"{100 * v:.3g}" for v in sat) if sat is not None else "n/a") + " |")
    return "\n".join(lines)


def summary_rows(results: dict) -> list[tuple]:
    """(run, label, mean tracking MAE [um], mean sync MAE [um], SC-DC's tracking and sync reduction
    against the run [%]) per run of a comparison ({run: metrics.json}), in the order of
    baselines.BASELINES, other names after; the means are over the three motors. A reduction is
    positive where SC-DC has the smaller error (NaN without an SC-DC run): the one direction of
    every summary, comparison.md's and the one `tapmp compare` prints."""
    sc = results.get("sc-dc")
    order = [b.name for b in BASELINES if b.name in results] + [r for r in results if r not in BY_NAME]
    rows = []
    for name in order:
        m = results[name]
        t, y = _mean(m["tracking_mae_um"]), _mean(m["sync_mae_um"])
        rt = reduction(t, _mean(sc["tracking_mae_um"])) if sc else float("nan")
        ry = reduction(y, _mean(sc["sync_mae_um"])) if sc else float("nan")
        rows.append((name, _label(name), t, y, rt, ry))
    return rows


def summary_table(results: dict) -> str:
    """Markdown table of summary_rows: each run's mean tracking and synchronization MAE over the
    motors [um], SC-DC's reduction against it [%] and its force RMS above the effort band [N]."""
    hz = next((m["force_rms_above_hz"] for m in results.values() if "force_rms_above_hz" in m), None)
    lines = ["| run | mean tracking MAE [um] | mean sync MAE [um] | SC-DC's tracking reduction [%] "
             "| SC-DC's sync reduction [%] | force RMS above " + (f"{hz:g} Hz" if hz else "the band") + " [N] |",
             "|---" * 6 + "|"]
    for name, label, t, y, rt, ry in summary_rows(results):
        lines.append(f"| {label} | {t:.4f} | {y:.4f} | {rt:+.1f} | {ry:+.1f} | {effort_text(results[name])} |")
    return "\n".join(lines)


def effort_text(m: dict) -> str:
    """The metrics' force RMS above the effort band per motor [N] ("n/a" if not computed)."""
    v = m.get("force_hf_rms_n")
    return "n/a" if not v else ", ".join(f"{x:.3g}" for x in v)


def _ms(x) -> str:
    return "not settled" if x is None else f"{1e3 * x:.1f}"


def move_tables(results: dict) -> str:
    """Markdown tables of the move metrics (metrics.json "move") of point-to-point runs: per run
    and axis (X, Z, B), then per run and motor: rise time, overshoot, settling time into each
    band after the end of the reference move, peak error while moving, error at constant
    velocity (max, mean). "" if no run has move metrics."""
    order = [b.name for b in BASELINES if b.name in results] + [r for r in results if r not in BY_NAME]
    moves = {r: results[r]["move"] for r in order if "channels" in results[r].get("move", {})}
    if not moves:
        return ""
    first = next(iter(moves.values()))
    bands = first["bands"]
    head = ("| run | {what} | rise 10-90 % [ms] | overshoot [{u}] | "
            + " | ".join(f"settling +-{b:g} [ms]" for b in bands)
            + " | peak error moving [{u}] | error at constant velocity, max / mean [{u}] |")
    out = [f"## Point-to-point move ({first['profile']}, from t = {first['t_move_s']:g} s to "
           f"{first['t_end_s']:.4g} s)", "",
           "Settling: time after the end of the reference move until the true position stays within "
           "the band around the end value (0: it already does; not settled: outside at the end of the run). "
           "Bands in m for X, Z and the motors and in rad for B; B's errors in urad.", ""]
    for title, channels, what in (("Per axis", ("X", "Z", "B"), "axis"), ("Per motor", ("q1", "q2", "q3"), "motor")):
        out += [f"### {title}", "", head.format(what=what, u="um or urad" if what == "axis" else "um"),
                "|---" * (6 + len(bands)) + "|"]
        for run, mv in moves.items():
            for c in channels:
                x = mv["channels"][c]
                rise = "-" if x["rise_time_s"] is None else f"{1e3 * x['rise_time_s']:.1f}"
                cruise = ("-" if x["cruise_error_max"] is None
                          else f"{x['cruise_error_max']:.3f} / {x['cruise_error_mean']:.3f}")
                out.append(f"| {_label(run)} | {c} | {rise} | {x['overshoot']:.3f} | "
                           + " | ".join(_ms(x["settling_time_s"][f"{b:g}"]) for b in bands)
                           + f" | {x['peak_error_moving']:.3f} | {cruise} |")
        out.append("")
    return "\n".join(out)


def write_comparison(path: Path, scenario, results: dict, command: str, runs: dict | None = None,
                     checks: dict | None = None, reference: dict | None = None) -> str:
    """Write comparison.md for a `tapmp compare` run and return its text.

    results: {run name: metrics}; runs: {run name: Scenario} and checks: {run name:
    StabilityReport} for the table of runs (left out if runs is None); reference: the rows shown
    beside ours (see comparison_tables).
    """
    g = scenario.gain_values()
    parts = [
        f"# SC-DC vs APD-DC and fair baselines: {scenario.name}", "",
        f"{scenario.description}", "",
        f"Produced by `{command}`.", "",
        f"Step {scenario.step:g} s, {scenario.ordering} ordering, {scenario.stop_time - scenario.start_time:g} s "
        f"simulated, gain preset `{scenario.gains}`: Lambda_p = {list(g.Lambda_p)}, "
        f"Lambda_v = {list(g.Lambda_v)}, b = {list(g.b)}, D = {list(g.D)}, K_T = {list(g.K_T)}. "
        "Errors use the plant's true motor positions. The paper's values are from its own plant and "
        "gains, copied as printed (see docs/paper-reproduction.md for what differs).", ""]
    if runs is not None:
        parts += ["## Runs", "", runs_table(runs, results, checks or {}), "", modal_note(scenario), "",
                  "## Robustness of each run", "", *robustness_section(runs), ""]
    parts += ["## SC-DC against each run (mean over the three motors)", "", summary_table(results), "",
              comparison_tables(results, reference)]
    moves = move_tables(results)
    if moves:
        parts += [moves]
    text = "\n".join(parts)
    write_text(path, text)  # under a temporary name, then renamed; a link there is refused
    return text
