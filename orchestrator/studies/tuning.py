"""Gain tuning: minimize the study objective over a law's gains with differential evolution.

scipy.optimize.differential_evolution searches the base-10 logarithm of the tuned gains
(the same value on all three motors) within stated bounds. It hands each generation to
``workers`` as one batch; ``TuneObjective.map`` runs the batch as cases on the Dask
workers (through the real FMUs, orchestrator.studies.study.run_case) and records every
evaluation as a row of study.csv. A candidate that the stability pre-check
(orchestrator.tool.stability) finds not stable is rejected without running (status
"rejected"); so is a stable candidate whose peak sensitivity Ms on any mode (common, the two
differential modes; orchestrator.tool.robustness.mode_peaks, the loop of `tapmp analyze`)
exceeds the [tune] table's ms_bound (default 2, the usual 6 dB guideline), or whose delay margin
with every motor delayed at once (orchestrator.tool.analysis.delay_margin) is below its
delay_margin_min [s] (if given): the objective is minimized subject to those robustness bounds,
so the tuned laws are compared at a stated, equal robustness ceiling. With the drive in the base
scenario (drive = true) the bounds are evaluated on the loop with the drive's delay and current
loop in it, so the delay margin is what a further delay may add beyond the drive's own. Rejected and failed candidates score PENALTY_UM, and a law none of whose
candidates completed is an error, never a preset beyond the bound.

The objective is orchestrator.studies.study.objective: (mean tracking MAE + mean synchronization
MAE) / 2 over the three motors [um], on the study's base scenario (with its [set], e.g. a
short stop_time). K_T is not tuned: F = u / K_T, so only the ratios Lambda / K_T matter.

A law is one of tapmp.laws' (tuned on its Gains) or pid-dc-full: PID-DC with one
integral gain on every mode (ki_c = ki_d = ki), tuned on its modal gains in the controller table,
starting from SC-DC's modal gains of the base (orchestrator.tool.baselines, full_integral).

After tuning each law it writes TUNED/<law>.toml (a gain preset file a scenario uses
with gains_file = "..."; for pid-dc-full the law and the [controller] settings to put in a scenario) and runs the starting and the tuned gains of every law over
compare_stop_time into TUNED/comparison.md, with TUNED/objective.png. TUNED is the study's
output folder's tuning/ subfolder, or the [tune] table's write_to folder when asked
(`tapmp study --write-docs`), so that a plain run leaves the repository's files alone.
"""

import json
import math
import time
from pathlib import Path

import numpy as np
from scipy.optimize import differential_evolution

from tapmp.params import GAIN_NAMES

from ..tool.config import require
from ..tool.folders import write_text
from ..tool.scenario import load_gain_file
from .study import PENALTY_UM, STATUSES, STUDY_CSV, STUDY_JSON, CaseRunner, StudyTable, case_value, fingerprint, prepare
from .study_file import FULL_PID, StudyError, apply_changes

def candidate_changes(law: str, values: dict) -> dict:
    """The scenario changes of a law's gains ``values`` ({gain: value}, the same on every motor)."""
    if law == FULL_PID:
        modal = {f"controller.{n}": v for n, v in values.items() if n != "ki"}
        return {"law": "pid-dc", **modal, "controller.ki_c": values["ki"], "controller.ki_d": values["ki"]}
    return {"law": law, **{f"gain_overrides.{n}": v for n, v in values.items()}}


def start_values(law: str, base, names: list) -> dict:
    """{gain: value} a law's tuning starts from: the base scenario's gains (mean over the motors); for
    pid-dc-full SC-DC's modal gains of the base with ki = ki_d."""
    g0 = base.gain_values()
    if law == FULL_PID:
        from ..tool.baselines import full_integral, scdc_modal
        mg = full_integral(scdc_modal(g0)[0])._asdict()
        return {n: float(mg["ki_d"] if n == "ki" else mg[n]) for n in names}
    return {n: float(np.mean(getattr(g0, n))) for n in names}


class TuneObjective:
    """The objective of one law's candidates x = log10(gains), evaluated as study cases."""

    def __init__(self, runner: CaseRunner, law: str, names: list, scenario=None, ms_bound: float | None = None,
                 delay_margin_min: float | None = None):
        self.runner = runner
        self.law = law
        self.names = names
        self.count = 0
        self.cases = []
        self.scenario = scenario  # the law's base scenario, for the Ms of a candidate
        self.ms_bound = ms_bound
        self.delay_margin_min = delay_margin_min

    def beyond_bound(self, case: dict) -> str:
        """Why the candidate is beyond ms_bound or below delay_margin_min ("" if it is not, or if its
        loop is not stable: the stability pre-check of run_case rejects that one)."""
        from ..tool.robustness import mode_peaks
        from ..tool.stability import check
        if (self.ms_bound is None and self.delay_margin_min is None) or self.scenario is None:
            return ""
        sc = apply_changes(self.scenario, case["changes"], "tune")
        if not check(sc).stable:
            return ""
        if self.ms_bound is not None:
            peaks = mode_peaks(sc)
            mode = max(peaks, key=peaks.get)
            if peaks[mode] > self.ms_bound:
                return f"not run: Ms {peaks[mode]:.4g} ({mode}) above tune.ms_bound = {self.ms_bound:g}"
        if self.delay_margin_min is not None:
            margin = all_motors_delay_margin(sc)
            if margin < self.delay_margin_min:
                return (f"not run: delay margin (all motors) {margin * 1e6:.4g} us below tune.delay_margin_min = "
                        f"{self.delay_margin_min * 1e6:g} us")
        return ""

    def case(self, x) -> dict:
        """The study case of candidate x (the next evaluation number)."""
        gains = {n: float(10.0 ** v) for n, v in zip(self.names, x)}
        case = {"case": f"{self.law}-{self.count:04d}", "params": {"law": self.law, **gains},
                "changes": candidate_changes(self.law, gains)}
        self.count += 1
        old = self.runner.table.rows.get(case["case"])
        if old is not None:  # resumed: the optimizer must be asking for the same candidate
            same = all(math.isclose(float(old[n]), gains[n], rel_tol=1e-9) for n in self.names)
            require(same, f"--resume: evaluation {case['case']} in {self.runner.table.path} had other gains "
                    "than the optimizer asks for now; the study changed: use --overwrite", StudyError)
        self.cases.append(case)
        return case

    def map(self, func, xs) -> list:
        """scipy's ``workers`` protocol: [func(x) for x in xs], here one batch of cases on Dask
        (func is this objective, wrapped by scipy; its batch is run instead of one by one)."""
        cases = [self.case(x) for x in xs]
        for c in cases:  # rejected here for its robustness: a row without a run (run() skips it)
            if c["case"] not in self.runner.table.rows:
                why = self.beyond_bound(c)
                if why:
                    self.runner.table.add(c, {"status": "rejected", "error": why})
        rows = self.runner.run(cases, reject_unstable=True)
        return [case_value(r) for r in rows]

    def __call__(self, x) -> float:
        return self.map(None, [x])[0]


def all_motors_delay_margin(scenario) -> float:
    """The delay margin [s] of the scenario's loop with one delay on every motor's force (analysis.delay_margin;
    0 if the loop is not stable)."""
    from ..tool import analysis
    margin = analysis.delay_margin(analysis.SplitLoop(scenario), np.eye(3))
    return 0.0 if margin is None else margin


def _full_pid_text(values, objective_start, objective_tuned, base, command) -> str:
    """The pid-dc-full preset: its law and [controller] settings (ki_c = ki_d = ki)."""
    head = _preset_text(FULL_PID, None, objective_start, objective_tuned, base, command).split("\n[gains]")[0]
    head = head.replace('# use in a scenario: gains_file = "<path of this file>"\nlaw = "pid-dc-full"',
                        '# use in a scenario: law = "pid-dc" and these [controller] settings (one integral gain '
                        'on every mode)\nlaw = "pid-dc"')
    modal = {**{n: v for n, v in values.items() if n != "ki"}, "ki_c": values["ki"], "ki_d": values["ki"]}
    return head + "\n[controller]\n" + "".join(f"{n} = {float(v)!r}\n" for n, v in modal.items())


def _preset_text(law, gains, objective_start, objective_tuned, base, command) -> str:
    lines = [f"# {law} gains tuned by `{command}`" if command else f"# {law} gains, tuned",
             f"# objective (mean tracking + sync MAE)/2 on {base.name}, {base.stop_time - base.start_time:g} s, "
             f"h = {base.step:g} s: start " + (f"{objective_start:.6g} um" if objective_start is not None else
                                             "not run (rejected)") + f" -> tuned {objective_tuned:.6g} um",
             '# use in a scenario: gains_file = "<path of this file>"', f'law = "{law}"',
             *([f"objective_start_um = {objective_start!r}"] if objective_start is not None else []),
             f"objective_tuned_um = {objective_tuned!r}",
             "", "[gains]"]
    for n in GAIN_NAMES if gains is not None else ():
        lines.append(f"{n} = [{', '.join(repr(float(v)) for v in gains[n])}]")
    return "\n".join(lines) + "\n"


def run_tuning(study, ssp: Path, client, out: Path, resume: bool, overwrite: bool, progress: bool,
               command: str, write_docs: bool = False, ship=None, reference: dict | None = None) -> dict:
    """Tune every law of the study's [tune] table; write presets, comparison.md and objective.png
    into out/tuning, or into the table's write_to folder if ``write_docs``. ``ship``: how the
    cases reach the workers (study.Shipping; default the local cluster's). ``reference``: published
    rows comparison.md prints beside the tuned laws' (orchestrator.tool.report.comparison_tables)."""
    from ..tool.folders import write_json

    spec = study.tune
    fp = fingerprint(study, [])
    prepare(study, out, resume, overwrite, fp)
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / STUDY_JSON, {"name": study.name, "source": study.source, "kind": "tune",
                                  "fingerprint": fp, "command": command, "tune": spec})
    names_all = list(dict.fromkeys(n for law in spec["laws"] for n in spec["bounds"][law]))
    table = StudyTable(out / STUDY_CSV, ["law", *names_all])
    write_to = Path(spec["write_to"]) if write_docs else out / "tuning"
    write_to.mkdir(parents=True, exist_ok=True)
    base = study.base_scenario()
    start = time.perf_counter()
    results = {}
    try:
        for law in spec["laws"]:
            names = list(spec["bounds"][law])
            v0 = start_values(law, base, names)
            scenario = apply_changes(base, candidate_changes(law, v0), "tune")
            g0 = scenario.gain_values()
            lo = np.log10([spec["bounds"][law][n][0] for n in names])
            hi = np.log10([spec["bounds"][law][n][1] for n in names])
            x0 = np.clip(np.log10([v0[n] for n in names]), lo, hi)
            runner = CaseRunner(client, scenario, ssp, out, table, study.keep_results, progress,
                                f"{study.name} {law}", ship)
            obj = TuneObjective(runner, law, names, scenario, spec.get("ms_bound"), spec.get("delay_margin_min"))
            res = differential_evolution(obj, list(zip(lo, hi)), x0=x0, popsize=spec["population"],
                                         maxiter=spec["generations"], seed=spec["seed"], polish=False,
                                         updating="deferred", workers=obj.map, tol=0.0)
            rows = [table.rows[c["case"]] for c in obj.cases]
            start_row = rows[0]  # differential_evolution evaluates x0 first
            done = [r for r in rows if r.get("status") == "completed"]
            if not done:  # never a preset beyond the bound or unstable
                raise StudyError(f"tune: no candidate of {law} was stable with Ms <= tune.ms_bound = "
                                 f"{spec.get('ms_bound')}"
                                 + (f" and a delay margin >= tune.delay_margin_min = {spec['delay_margin_min']:g} s"
                                    if spec.get("delay_margin_min") is not None else "")
                                 + f" in {len(rows)} evaluations: widen tune.bounds.{law} or relax the bounds")
            best_row = min(done, key=case_value)
            tuned = {n: tuple(float(v) for v in getattr(g0, n)) for n in GAIN_NAMES}
            for n in names:
                tuned[n] = (float(best_row[n]),) * 3
            preset = write_to / f"{law}.toml"
            start_value = case_value(start_row) if start_row.get("status") == "completed" else None
            tuned_values = {n: float(best_row[n]) for n in names}
            if law == FULL_PID:
                write_text(preset, _full_pid_text(tuned_values, start_value, case_value(best_row), scenario, command))
            else:
                write_text(preset, _preset_text(law, tuned, start_value, case_value(best_row), scenario, command))
                load_gain_file(preset)  # what we wrote must be a valid preset file
            results[law] = {"preset": preset, "start": start_value, "tuned": case_value(best_row),
                            "start_note": start_row.get("error", ""),
                            "evaluations": len(rows), "result_fun": float(res.fun),
                            "rows": rows, "start_values": v0, "tuned_values": tuned_values}
        compare = _compare(study, ssp, client, out, table, results, spec, progress, ship)
    finally:
        table.close()
    from .study_plots import plot_objective
    fig = plot_objective(write_to / "objective.png", results)
    text = _comparison_md(write_to / "comparison.md", study, base, results, compare, spec, command, reference)
    for r in results.values():
        r.pop("rows")
    statuses = [row["status"] for row in table.rows.values()]
    return {"out": out, "write_to": write_to, "tuning": results, "comparison": text, "figures": [fig],
            "wall_time_s": time.perf_counter() - start,
            "cases": len(table.rows), "counts": {s: statuses.count(s) for s in STATUSES}}


def _compare(study, ssp, client, out, table, results, spec, progress, ship=None) -> dict:
    """Run the starting and the tuned gains of each law over compare_stop_time.

    Returns {"base": scenario, "metrics": {(law, "start" | "tuned"): metrics.json or None}, "rows": {...}}.
    """
    base = apply_changes(study.base_scenario(), {"stop_time": spec["compare_stop_time"]},
                         "tune.compare_stop_time")
    cases = []
    for law, r in results.items():
        for which in ("start", "tuned"):
            values = r["tuned_values"] if which == "tuned" else r["start_values"]
            changes = candidate_changes(law, values)
            if which == "tuned" and law != FULL_PID:  # the preset file as a scenario reads it
                changes = {"law": law, "gains_file": str(Path(r["preset"]).resolve())}
            params = {"law": law, **values}
            cases.append({"case": f"compare-{law}-{which}", "params": params, "changes": changes})
    runner = CaseRunner(client, base, ssp, out, table, study.keep_results, progress, f"{study.name} compare", ship)
    rows = runner.run(cases)
    metrics, by_case = {}, {}
    for c, row in zip(cases, rows):
        key = (c["params"]["law"], c["case"].rsplit("-", 1)[1])
        path = Path(out) / "cases" / c["case"] / "metrics.json"
        metrics[key] = json.loads(path.read_text()) if row["status"] == "completed" and path.exists() else None
        by_case[key] = row
    return {"base": base, "metrics": metrics, "rows": by_case}


def _drive_text(drive: dict) -> str:
    from tapmp.interface import DRIVE_DEFAULTS
    d = {**DRIVE_DEFAULTS, **drive}
    return (f"{d['delay_samples']} sample(s) of delay, a {d['current_bandwidth']:g} Hz current loop damped "
            f"{d['current_damping']:g}")


def _comparison_md(path: Path, study, short, results, compare, spec, command, reference=None) -> str:
    """comparison.md: starting vs tuned gains per law, and SC-DC vs APD-DC with both laws tuned
    (beside ``reference``'s published rows, if given)."""
    from ..tool.report import comparison_tables
    from .study import objective

    base = compare["base"]
    lines = [f"# Tuned gains: {study.name}", "",
             f"Produced by `{command}` (from the repository root, after `bash build_fmus.sh`)." if command else "",
             "",
             f"Tuning: differential evolution (scipy) over log10 of the gains, the same value on all three "
             f"motors, population {spec['population']} x dimensions, {spec['generations']} generations, "
             f"seed {spec['seed']}; every candidate is a co-simulation of `{Path(study.base).name}` with the "
             f"study's changes ({', '.join(f'{k} = {v}' for k, v in study.set.items()) or 'none'}), "
             f"{short.stop_time - short.start_time:g} s at h = {short.step:g} s, {short.ordering}. "
             "Objective: (mean tracking MAE + mean synchronization MAE) / 2 over the three motors [um], "
             "on the plant's true positions. Candidates the stability check finds not stable, or whose peak "
             f"sensitivity Ms on any mode exceeds tune.ms_bound = {spec.get('ms_bound')}"
             + (f", or whose delay margin with every motor delayed at once is below tune.delay_margin_min = "
                f"{spec['delay_margin_min'] * 1e3:g} ms" if spec.get("delay_margin_min") is not None else "")
             + f", are rejected without running (scored {PENALTY_UM:g} um): the tuned gains stay within "
             + ("those robustness bounds" if spec.get("delay_margin_min") is not None else "that robustness bound")
             + (f", evaluated on the loop with the drive ({_drive_text(short.drive)}) in it" if short.drive is not None
                else "") + ".", "",
             "| law | evaluations | rejected (not stable, Ms beyond the bound or delay margin below it) | failed / diverged | objective, start gains [um] | "
             "objective, tuned [um] | tuned gains (all motors) | preset file |",
             "|---|---|---|---|---|---|---|---|"]
    for law, r in results.items():
        st = [row["status"] for row in r["rows"]]
        tuned = ", ".join(f"{n} = {r['tuned_values'][n]:.4g}" for n in spec["bounds"][law])
        lines.append(f"| {law} | {r['evaluations']} | {st.count('rejected')} | "
                     f"{st.count('failed')} / {st.count('diverged')} | "
                     + (f"{r['start']:.4f}" if r["start"] is not None else f"rejected ({r['start_note']})")
                     + f" | {r['tuned']:.4f} | {tuned} | `{Path(r['preset']).name}` |")
    start_desc = "; ".join(f"{law}: " + ", ".join(f"{n} = {r['start_values'][n]:.4g}" for n in spec["bounds"][law])
                           for law, r in results.items())
    lines += ["", f"Starting gains (the base scenario's `{short.gains}` preset): {start_desc}.", "",
              f"## Full horizon: {base.stop_time - base.start_time:g} s of `{Path(study.base).name}`", "",
              "| law | gains | objective [um] | tracking MAE q1, q2, q3 [um] | sync MAE q1, q2, q3 [um] |",
              "|---|---|---|---|---|"]
    for (law, which), m in compare["metrics"].items():
        if m is None:
            row = compare["rows"][(law, which)]
            why = row.get("error") or f"status {row.get('status')}, no metrics.json in cases/compare-{law}-{which}"
            lines.append(f"| {law} | {which} | {row.get('status')}: {why} | | |")
            continue
        lines.append(f"| {law} | {which} | {objective(m):.4f} | "
                     + ", ".join(f"{v:.4f}" for v in m["tracking_mae_um"]) + " | "
                     + ", ".join(f"{v:.4f}" for v in m["sync_mae_um"]) + " |")
    tuned = {law: compare["metrics"].get((law, "tuned")) for law in results}
    if all(tuned.values()) and len(tuned) >= 2:
        lines += ["", f"## {' vs '.join(law.upper() if law != FULL_PID else law for law in tuned)}, every law tuned", "",
                  "Laid out like `tapmp compare` (paper Tables 1-3): every row uses its own tuned gains.", "",
                  comparison_tables(tuned, reference)]
    text = "\n".join(lines) + "\n"
    write_text(path, text)
    return text
