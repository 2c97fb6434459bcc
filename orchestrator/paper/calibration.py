"""Calibrate the plant on APD-DC, then predict SC-DC.

The plant's disturbance and mismatch levels are chosen so that APD-DC reproduces the
magnitudes of the paper's APD-DC rows: Tables 1-2 (simulation, Section 5.2) or Tables
4-5 (experiment, Section 6.2). SC-DC is then run on the same plant with the same gain
preset, unchanged: a prediction, not a fit.

Gains (both laws, both targets): the paper's Eq. 40 with Lambda_p and Lambda_v multiplied
by GAIN_SCALE = 0.36 / 150, and b, D, K_T unchanged; APD-DC reads them by Eq. 41
(k_p = Lambda_p, k_v = Lambda_v, K_T1 = K_T). Multiplying both feedback gains by one
factor keeps the paper's PD corner k_p / k_v (53 1/s on motor 1) and the rates b and D
[1/s] of SC-DC, and only changes the force per metre of error (it is the same as
dividing the feedback by a different unit of u). The factor is fixed before any fit:
it makes motor 1's Lambda_v equal to the `default` preset's 0.36, the damping known
stable at the 0.1 ms step (Eq. 40 itself is unstable there). The experiment's Eq. 42-43
are not used: their corner k_p / k_v is 0.13 1/s, so at any damping the 0.1 ms step
allows the position stiffness is a few kN/m and a 2 N friction force gives 100-300 um
(docs/calibration.md, measured).

Fitted parameters (PARAMETERS, few and physical): the Coulomb friction of the outer
movers (F_c1 = F_c3) and of the middle mover (F_c2) [N], the adjacent-mover stiffness
k_pull [N/m], bounded to <= 0 (an attraction has a negative stiffness; the old
restoring +200 N/m had no source), and the payload mismatch: the controller's m_p is
the plant's times a factor (an unknown payload). Everything else stays as the base
scenario (100 nm encoder, 5 N s/m viscous friction, 600 N limit).

Objective: the residuals r_j = ln(ours_j / paper_j) over APD-DC's tracking MAE and
synchronization MAE of the three motors (six residuals); J = sum r_j^2, minimized by
scipy.optimize.least_squares (trust region reflective, within the bounds, forward
differences of 2 % of each range). Each evaluation is a co-simulation through the FMUs
(orchestrator.tool.results.run_scenario), over the fit horizon: one period of the
slowest reference component (2.5 s for the simulation, 1 / 0.18 Hz for the experiment),
capped at the scenario's stop_time. The result is verified on the full horizon of the
base scenario, for APD-DC (the fit) and SC-DC (the prediction), with the stability
pre-check of both.

Run: ``.venv/bin/tapmp calibrate --target simulation``
(or ``experiment``); it writes <work>/paper_<target>_calibrated.toml (or the file of
--write-to, e.g. scenarios/paper_<target>_calibrated.toml) and <work>/calibration.json.
"""

import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

from tapmp.params import GAIN_PRESETS

from ..builder.families import SCENARIOS_DIR
from . import paper_tables
from ..tool import scenario as scenario_mod
from ..tool import stability
from ..tool.folders import write_json, write_text
from .paper_tables import TABLES, by_metric, tables_of, values
from ..tool.metrics import METRIC_KEYS, reductions
from ..tool.results import run_scenario
from ..tool.scenario import Scenario

ROOT = SCENARIOS_DIR  # the shipped scenario files (the repository's scenarios/ in a checkout)
GAIN_SCALE = 0.36 / 150.0  # Eq. 40's Lambda_v of motor 1 (150) -> the default preset's 0.36
GAIN_PRESET = "paper_simulation"  # Eq. 40 (SC-DC) and, by Eq. 41, APD-DC
FIT_KEYS = ("tracking_mae_um", "sync_mae_um")  # the residuals: 3 motors each
DIFF_STEP = 0.02  # forward-difference step, share of each parameter's range
FIT_PREFIX = "#: "  # comment lines of a calibrated scenario file that hold the fit record (TOML)


@dataclass(frozen=True)
class Parameter:
    """A fitted quantity: where it goes (table, keys), its bounds, start and unit."""

    name: str
    table: str        # "plant" or "mismatch"
    keys: tuple       # scenario keys set to the value
    low: float
    high: float
    start: float
    unit: str


PARAMETERS = (
    # Coulomb friction of the outer movers' guides (equal: same blocks, same rails)
    Parameter("F_c_outer", "plant", ("F_c1", "F_c3"), 0.0, 20.0, 2.0, "N"),
    # Coulomb friction of the middle mover (a lighter block, its own preload)
    Parameter("F_c_middle", "plant", ("F_c2",), 0.0, 20.0, 2.0, "N"),
    # adjacent-mover stiffness, negative: the small-signal attraction of the movers
    Parameter("k_pull", "plant", ("k_pull",), -3000.0, 0.0, -200.0, "N/m"),
    # controller's payload mass / plant's (an unknown payload, identification error)
    Parameter("m_p_factor", "mismatch", ("m_p",), 0.5, 1.5, 1.0, "1"),
)

TARGETS = paper_tables.TARGETS  # "simulation" (Tables 1-3), "experiment" (Tables 4-6)


def base_file(target: str) -> Path:
    """The scenario file a target is calibrated on (its trajectory, step and horizon)."""
    return ROOT / f"paper_{_checked(target)}.toml"


def calibrated_file(target: str) -> Path:
    """The calibrated scenario of a target shipped with the package (main writes a new one only
    where --write-to says)."""
    return ROOT / f"paper_{_checked(target)}_calibrated.toml"


def _checked(target: str) -> str:
    if target not in TARGETS:
        raise ValueError(f"target = {target!r} is invalid: allowed are {', '.join(TARGETS)}")
    return target


def scaled_gains() -> dict:
    """The gain overrides of the calibrated scenarios: Eq. 40's Lambda_p and Lambda_v times
    GAIN_SCALE (lists per motor, Lambda in K_T-scaled N/m and N s/m)."""
    p = GAIN_PRESETS[GAIN_PRESET]
    return {name: [x * GAIN_SCALE for x in p[name]] for name in ("Lambda_p", "Lambda_v")}


def check_theta(theta) -> dict:
    """{parameter name: value} of a parameter vector in PARAMETERS order; ValueError names a
    value that is not finite or outside its bounds."""
    theta = [float(x) for x in theta]
    if len(theta) != len(PARAMETERS):
        raise ValueError(f"theta has {len(theta)} values: allowed are {len(PARAMETERS)} "
                         f"({', '.join(p.name for p in PARAMETERS)})")
    for p, v in zip(PARAMETERS, theta):
        if not (math.isfinite(v) and p.low <= v <= p.high):
            raise ValueError(f"{p.name} = {v!r} is invalid: allowed is a number in [{p.low:g}, {p.high:g}] {p.unit}")
    return {p.name: v for p, v in zip(PARAMETERS, theta)}


def fit_horizon(base: Scenario) -> float:
    """One period of the slowest reference component (XZ circle or B sinusoid) [s], in whole
    steps, capped at the base scenario's duration."""
    f = min(base.trajectory.get("f_xz", 0.4), base.trajectory.get("f_B", 0.4))
    span = min(1.0 / f, base.stop_time - base.start_time)
    return round(span / base.step) * base.step


def calibrated_scenario(target: str, theta, law: str = "apd-dc", horizon: float | None = None) -> Scenario:
    """The base scenario of ``target`` with the scaled Eq. 40 gains, the plant and mismatch
    values of ``theta`` (PARAMETERS order) and ``law``; ``horizon`` [s] shortens the run
    (None: the base scenario's stop_time)."""
    values = check_theta(theta)
    base = scenario_mod.load(base_file(target))
    plant, mismatch = dict(base.plant), dict(base.mismatch)
    for p in PARAMETERS:
        table = plant if p.table == "plant" else mismatch
        for key in p.keys:
            table[key] = values[p.name]
    stop = base.stop_time if horizon is None else base.start_time + horizon
    return base.with_changes(law=law, gains=GAIN_PRESET, gain_overrides=scaled_gains(), plant=plant,
                             mismatch=mismatch, stop_time=stop, name=f"{base.name}_calibrated")


def residuals(metrics: dict, target: str) -> np.ndarray:
    """ln(ours / paper) of APD-DC's tracking MAE (q1..q3) then synchronization MAE (q1..q3)."""
    paper = by_metric(_checked(target), "apd_dc")
    return np.array([math.log(metrics[k][i] / paper[k][i]) for k in FIT_KEYS for i in range(3)])


def objective(metrics: dict, target: str) -> float:
    """J = sum of squared residuals (see residuals); 0 when APD-DC equals the paper's row."""
    r = residuals(metrics, target)
    return float(r @ r)


def run_metrics(sc: Scenario, ssp: Path, out: Path) -> dict:
    """One co-simulation of ``sc`` through the FMUs of ``ssp`` into ``out`` (overwritten),
    keeping only its first and last rows on disk; returns its metrics.json content."""
    return run_scenario(sc.with_changes(record_every=sc.n_steps, format="csv"), ssp, out, overwrite=True)


class Evaluator:
    """The calibration objective over real runs: each call runs APD-DC with one parameter
    vector over ``horizon`` [s] into work/evals/NNNN and records theta, metrics, residuals."""

    def __init__(self, target: str, ssp: Path, work: Path, horizon: float):
        self.target, self.ssp, self.work, self.horizon = _checked(target), Path(ssp), Path(work), horizon
        self.history = []

    def __call__(self, theta) -> np.ndarray:
        folder = self.work / "evals" / f"{len(self.history):04d}"
        m = run_metrics(calibrated_scenario(self.target, theta, "apd-dc", self.horizon), self.ssp, folder)
        r = residuals(m, self.target)
        self.history.append({"theta": [float(x) for x in theta], "folder": str(folder),
                             "metrics": {k: m[k] for k in FIT_KEYS}, "residuals": r.tolist(),
                             "objective": float(r @ r)})
        return r


def _to_z(theta) -> np.ndarray:
    return np.array([(v - p.low) / (p.high - p.low) for p, v in zip(PARAMETERS, theta)])


def _from_z(z) -> list:
    """Parameter values from the [0, 1] scaled ones; within 1e-9 of a bound is the bound (the
    optimizer's steps land a few ulps inside it)."""
    out = []
    for p, x in zip(PARAMETERS, z):
        x = min(max(float(x), 0.0), 1.0)
        x = 0.0 if x < 1e-9 else 1.0 if x > 1.0 - 1e-9 else x
        out.append(p.low + x * (p.high - p.low))
    return out


def calibrate(target: str, ssp: Path, work: Path, horizon: float | None = None, max_nfev: int = 25,
              log=print) -> dict:
    """Fit PARAMETERS so APD-DC's tracking and synchronization MAE match the paper's row.

    Minimizes J = sum ln(ours/paper)^2 (six residuals) with scipy's least_squares over the
    parameters scaled to [0, 1] on their bounds, from their start values; each evaluation
    is a co-simulation of ``horizon`` [s] (default fit_horizon of the base scenario)
    through the FMUs of ``ssp``. ``max_nfev`` bounds the iterations (each costs one run
    plus one per parameter for the forward differences). Returns theta, the fitted values
    by name, the objective and residuals at theta, evaluations and wall time [s].
    """
    base = scenario_mod.load(base_file(target))
    horizon = fit_horizon(base) if horizon is None else horizon
    ev = Evaluator(target, ssp, work, horizon)
    t0 = time.perf_counter()

    def fun(z):
        r = ev(_from_z(z))
        log(f"  eval {len(ev.history):3d}: " + ", ".join(f"{p.name}={v:.5g}" for p, v in zip(PARAMETERS, _from_z(z)))
            + f" -> J = {r @ r:.5f}")
        return r

    res = least_squares(fun, _to_z([p.start for p in PARAMETERS]), bounds=(0.0, 1.0), method="trf",
                        diff_step=DIFF_STEP, max_nfev=max_nfev, x_scale=1.0)
    best = min(ev.history, key=lambda h: h["objective"])  # the best run seen (the last step may not be)
    theta = best["theta"]
    return {"target": target, "horizon_s": horizon, "theta": theta, "values": check_theta(theta),
            "objective": best["objective"], "residuals": best["residuals"], "metrics": best["metrics"],
            "evaluations": len(ev.history), "optimizer": {"status": int(res.status), "message": res.message,
                                                         "nfev": int(res.nfev)},
            "wall_s": time.perf_counter() - t0, "history": ev.history}


def predict(target: str, theta, ssp: Path, work: Path) -> dict:
    """APD-DC (the calibrated law) and SC-DC (the prediction) on the full horizon of the base
    scenario with the calibrated plant: metrics, stability pre-check of both, reductions."""
    out = {}
    for law in ("apd-dc", "sc-dc"):
        sc = calibrated_scenario(target, theta, law)
        rep = stability.check(sc)
        t0 = time.perf_counter()
        m = run_metrics(sc, ssp, Path(work) / "full" / law)
        out[law] = {"metrics": m, "verdict": rep.verdict, "spectral_radius": rep.spectral_radius,
                    "stop_time_s": sc.stop_time, "wall_s": time.perf_counter() - t0}
    out["reduction"] = reductions(out["apd-dc"]["metrics"], out["sc-dc"]["metrics"])
    out["objective_full"] = objective(out["apd-dc"]["metrics"], target)
    out["residuals_full"] = residuals(out["apd-dc"]["metrics"], target).tolist()
    return out


def _toml(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml(x) for x in v) + "]"
    raise TypeError(f"cannot write {v!r} as TOML")


def _fmt(values, digits=3) -> str:
    return ", ".join(f"{x:.{digits}f}" for x in values)


def scenario_text(target: str, fit: dict, pred: dict) -> str:
    """The calibrated scenario file: the base scenario's keys with the scaled gains, the fitted
    plant and mismatch, law = "apd-dc"; comments state the fit, its residuals and the command;
    FIT_PREFIX lines hold the same record as TOML (read_fit_record)."""
    sc = calibrated_scenario(target, fit["theta"], "apd-dc")
    paper = by_metric(target, "apd_dc")
    fitted = [name.split()[1] for name in tables_of(target)[:2]]  # the tracking and sync tables
    apd, scdc = pred["apd-dc"]["metrics"], pred["sc-dc"]["metrics"]
    lines = [
        f"# Calibrated plant for the paper's {target}: APD-DC fitted to Tables {fitted[0]}-{fitted[1]}, "
        "SC-DC predicted.",
        f"# Written by: .venv/bin/tapmp calibrate --target {target}",
        f"# Base: scenarios/{base_file(target).name} (trajectory, step, horizon); see docs/calibration.md.",
        f"# Gains: Eq. 40 with Lambda_p, Lambda_v x {GAIN_SCALE:g} (= 0.36 / 150); APD-DC reads them by Eq. 41.",
        f"# Fit: least squares on ln(ours/paper) of APD-DC tracking and sync MAE (6 residuals), "
        # no wall time here: the file is tracked, and a rerun that finds the same fit leaves it unchanged
        f"{fit['evaluations']} co-simulations of {fit['horizon_s']:g} s.",
        "#   fitted: " + ", ".join(f"{p.name} = {fit['values'][p.name]:.6g} {p.unit}" for p in PARAMETERS),
        f"#   J = {pred['objective_full']:.4f} on the full {sc.stop_time:g} s ({fit['objective']:.4f} on the fit horizon)",
        f"#   APD-DC tracking MAE [um]: {_fmt(apd['tracking_mae_um'])}  (paper {_fmt(paper['tracking_mae_um'], 2)})",
        f"#   APD-DC sync MAE [um]:     {_fmt(apd['sync_mae_um'])}  (paper {_fmt(paper['sync_mae_um'], 2)})",
        f"#   residuals ln(ours/paper): {_fmt(pred['residuals_full'])}",
        f"#   SC-DC (predicted, same plant and preset) tracking MAE [um]: {_fmt(scdc['tracking_mae_um'])}, "
        f"sync MAE: {_fmt(scdc['sync_mae_um'])}",
        f"# SC-DC: tapmp run scenarios/{calibrated_file(target).name} --set law='\"sc-dc\"'",
        "# Fit record (read by orchestrator.paper.calibration.read_fit_record):",
    ]
    record = {"fit_horizon_s": fit["horizon_s"], "objective_fit": fit["objective"],
              "objective_full": pred["objective_full"], "residuals_full": pred["residuals_full"],
              **{f"{p.name}": fit["values"][p.name] for p in PARAMETERS}}
    for law, tag in (("apd-dc", "apd"), ("sc-dc", "scdc")):
        m = pred[law]["metrics"]
        for k in ("tracking_mae_um", "tracking_std_um", "sync_mae_um", "sync_std_um"):
            record[f"{tag}_{k}"] = m[k]
    lines += [f"{FIT_PREFIX}{k} = {_toml(v)}" for k, v in record.items()]
    lines += ["", f"name = {_toml(sc.name)}",
              f"description = {_toml(f'{sc.description} (calibrated plant, scaled Eq. 40 gains)')}",
              'law = "apd-dc"            # the calibrated law; SC-DC is the prediction (--set law=\'"sc-dc"\')',
              f"gains = {_toml(GAIN_PRESET)}  # Eq. 40-41, feedback scaled below"]
    for key in ("start_time", "stop_time", "step", "ordering", "start_on_trajectory"):
        lines.append(f"{key} = {_toml(getattr(sc, key))}")
    lines.append(f'output = "results/{sc.name}"')
    lines += ["", "[gain_overrides]              # Eq. 40 x GAIN_SCALE"]
    lines += [f"{k} = {_toml(v)}" for k, v in sc.gain_overrides.items()]
    for table in ("trajectory", "plant", "mismatch", "controller"):
        values = getattr(sc, table)
        lines += ["", f"[{table}]"] + [f"{k} = {_toml(v)}" for k, v in values.items()]
    return "\n".join(lines) + "\n"


def read_fit_record(path) -> dict:
    """The fit record of a calibrated scenario file (its FIT_PREFIX comment lines, as TOML)."""
    text = "\n".join(line[len(FIT_PREFIX):] for line in Path(path).read_text().splitlines()
                     if line.startswith(FIT_PREFIX))
    return scenario_mod.tomllib.loads(text)


def _row(label, values, digits=2) -> str:
    return f"| {label} | " + " | ".join(f"{v:.{digits}f}" for v in values) + " |"


def prediction_table(target: str, pred: dict) -> str:
    """Markdown: per table of the paper, the APD-DC and SC-DC rows and the reductions, ours
    (calibrated plant) beside the paper's printed values."""
    apd, scdc = pred["apd-dc"]["metrics"], pred["sc-dc"]["metrics"]
    out = []
    for table in tables_of(target):
        t = TABLES[table]
        std, mae = METRIC_KEYS[t.quantity]
        cols = t.columns if t.quantity != "axis" else tuple(f"{c} {u}" for c, u in zip(t.columns, t.units))
        out += [f"{table} ({t.quantity}): STD {', '.join(cols)} | MAE {', '.join(cols)}", "",
                "| row | " + " | ".join(f"STD {c}" for c in cols) + " | " + " | ".join(f"MAE {c}" for c in cols) + " |",
                "|---|" + "---|" * 6,
                _row("APD-DC paper", values(table, "apd_dc")),
                _row("APD-DC ours (fit)", (*apd[std], *apd[mae])),
                _row("SC-DC paper", values(table, "sc_dc")),
                _row("SC-DC ours (predicted)", (*scdc[std], *scdc[mae])),
                _row("reduction % paper (printed)", values(table, "reduction"), 2),
                _row("reduction % ours (predicted)", (*pred["reduction"][std], *pred["reduction"][mae]), 1), ""]
    return "\n".join(out)


def calibrate_and_predict(target: str, ssp: Path, work: Path, horizon: float | None, max_nfev: int,
                          write_to: Path | None) -> list[str]:
    """`tapmp calibrate`: fit the plant on APD-DC of ``target`` (``max_nfev`` least-squares
    iterations over ``horizon`` [s], default one period of the slowest reference), verify on the
    full horizon, predict SC-DC; work/calibration.json holds both, the calibrated scenario goes to
    ``write_to`` (None: not written). Returns the lines to print."""
    fit = calibrate(target, ssp, work, horizon, max_nfev)
    pred = predict(target, fit["theta"], ssp, work)
    write_json(work / "calibration.json", {"fit": fit, "prediction": pred})
    lines = []
    if write_to is not None:
        write_text(write_to, scenario_text(target, fit, pred))
        lines.append(f"wrote {write_to}")
    lines.append(f"fitted ({fit['evaluations']} runs of {fit['horizon_s']:g} s, {fit['wall_s']:.0f} s): "
                 + ", ".join(f"{k} = {v:.6g}" for k, v in fit["values"].items()))
    lines.append(f"J = {fit['objective']:.4f} (fit horizon), {pred['objective_full']:.4f} (full); "
                 f"residuals ln(ours/paper) = {_fmt(pred['residuals_full'])}")
    for law in ("apd-dc", "sc-dc"):
        lines.append(f"{law}: {pred[law]['verdict']}, spectral radius {pred[law]['spectral_radius']:.6f}")
    lines.append(prediction_table(target, pred))
    return lines
