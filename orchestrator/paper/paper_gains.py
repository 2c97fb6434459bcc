"""The paper's own gains (Eq. 40-43) run at fine steps, under both readings of the units.

The paper states its simulation gains (Eq. 40-41) and experiment gains (Eq. 42-43) but
not its simulation step; 0.1 ms is the experiment's sampling period. Fine steps (1 us,
10 us) stand for its continuous-time simulation; 0.1 ms shows what the servo cycle does.

Readings of the units (the paper gives none):

* "A", as implemented (tapmp.control): u is in K_T-scaled units, the motor force is
  F = u / K_T = u_d + (Lambda_v n + Lambda_p c) / K_T [N]: full feedforward, feedback
  gains divided by K_T (4.1e-5 and 3e-5: N/m in the millions).
* "B": u is the force in newtons and K_T only scales the feedforward:
  F = K_T u_d + Lambda_v n + Lambda_p c [N] (feedback gains in N/m, N s/m directly; the
  feedforward is 4.1e-5 of the model's, so the feedback holds gravity). Run exactly with
  the unchanged controller: Lambda_p and Lambda_v multiplied by K_T, and the controller's
  nominal masses and inertia (m_p, m_1, m_2, m_3, I_y) multiplied by K_T. u_d of Eq. 26 is
  linear and homogeneous in those five (M, C and G are), so u_d' = K_T u_d and
  F = u' / K_T = u_d' + K_T (Lambda_v n + Lambda_p c) / K_T = K_T u_d + Lambda_v n + Lambda_p c.
  This needs K_T equal on the three motors (u_d mixes the motors through J^-T), as in
  Eq. 40 and 42; other gains are refused.

Plants: "encoder" is the scenario's plant as its TOML file gives it (100 nm encoder
quantization, friction, pulling, 600 N saturation); "exact" is the same with the
quantization off (encoder_resolution = 0), the measurement a continuous-time
simulation would have. The loop is ``tapmp.closed_loop.run``: the FMI-free loop stepped in C
(the FMUs' model functions in the same order, the same doubles as the readable Python loop
``tapmp.closed_loop.simulate``); the FMUs at 1 us would take 100 times the steps of a 0.1 ms
run through the co-simulation master.

Per run: the metrics of orchestrator.tool.metrics (tracking and synchronization
MAE and STD per motor [um], every communication point from the start), the share of
samples with the command at the plant's force limit per motor, the spectral radius
of the linearized loop (orchestrator.tool.stability.check) and the wall time.
"""

import math
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from tapmp.closed_loop import COLUMNS, run
from tapmp.control import Gains
from tapmp.errors import ModelInputError
from tapmp.params import ModelParams

from ..builder.families import SCENARIOS_DIR
from ..errors import UsageError
from ..tool import stability
from ..tool.metrics import ErrorStatistics
from ..tool.scenario import Scenario, load, model_tuple

ROOT = SCENARIOS_DIR  # the shipped scenario files (the repository's scenarios/ in a checkout)
# case: (scenario file, gain preset, the paper's equations)
CASES = {"Eq. 40-41": ("paper_simulation.toml", "paper_simulation"),
         "Eq. 42-43": ("paper_experiment.toml", "paper_experiment")}
READINGS = {"A": "F = u / K_T (as implemented)",
            "B": "F = K_T u_d + Lambda_v n + Lambda_p c (u in N)"}
PLANTS = {"encoder": {}, "exact": {"encoder_resolution": 0.0}}
LAWS = ("sc-dc", "apd-dc")
SATURATION_FLAG = 0.01   # a run with more than 1 % of samples at the force limit is not stable
# Judging rho at fine steps: stability.MARGIN (1e-6 per step) is a decay time of h / 1e-6,
# 0.5 s at 0.5 us, so it would call a loop with a 0.9 s slowest mode marginal. Here rho is
# judged against the finite-difference error of the linearization (about 1e-9, see
# stability's module doc) and the time constant -h / ln(rho) is reported beside it.
FD_TOL = 1e-9
_MASSES = ("m_p", "m_1", "m_2", "m_3", "I_y")
_COLUMNS = ["time", "trajectory.q1_d", "trajectory.q2_d", "trajectory.q3_d",
            "plant.q1_true", "plant.q2_true", "plant.q3_true",
            "trajectory.X_d", "trajectory.Z_d", "trajectory.B_d", "plant.X", "plant.Z", "plant.B"]
_BLOCK = 20000  # rows per ErrorStatistics.add (its pairwise update depends on the blocks)
# the columns of tapmp.closed_loop.COLUMNS that make _COLUMNS, and the command F
_ROW = [COLUMNS.index(c) for c in ("t", "q_d1", "q_d2", "q_d3", "q1_true", "q2_true", "q3_true",
                                   "X_d", "Z_d", "B_d", "X", "Z", "B")]
_F = [COLUMNS.index(c) for c in ("F1", "F2", "F3")]


def reading_b(gains: Gains, controller: dict) -> tuple[dict, dict]:
    """(gain_overrides, controller table) that run reading B with the unchanged controller.

    gains: the preset's gains; controller: the scenario's [controller] table. Returns
    Lambda_p, Lambda_v times K_T and the nominal m_p, m_1..m_3 [kg], I_y [kg m^2] times K_T
    (module doc). ValueError if K_T differs between motors.
    """
    kt = gains.K_T
    if not kt[0] == kt[1] == kt[2]:
        raise UsageError(f"K_T = {kt!r} is invalid for reading B: allowed is one K_T on all three motors "
                         "(the feedforward u_d mixes the motors)")
    k = kt[0]
    overrides = {"Lambda_p": [k * x for x in gains.Lambda_p], "Lambda_v": [k * x for x in gains.Lambda_v]}
    nominal = model_tuple(ModelParams, controller)
    table = dict(controller)
    for name in _MASSES:
        table[name] = k * getattr(nominal, name)
    return overrides, table


def paper_scenario(case: str, law: str, step: float, stop_time: float, reading: str = "A",
                   plant: str = "encoder", root: Path = ROOT) -> Scenario:
    """The scenario of one run: the case's TOML file with its paper gains, law, step [s],
    stop_time [s], reading ("A" or "B") and plant variant ("encoder" or "exact"); ``root`` is
    the folder of the case's scenario file."""
    for name, value, allowed in (("case", case, CASES), ("law", law, LAWS), ("reading", reading, READINGS),
                                 ("plant", plant, PLANTS)):
        if value not in allowed:
            raise UsageError(f"{name} = {value!r} is invalid: allowed are {', '.join(allowed)}")
    path, preset = CASES[case]
    sc = load(Path(root) / path)
    sc = sc.with_changes(gains=preset, law=law, step=step, stop_time=stop_time, gain_overrides={},
                         plant={**sc.plant, **PLANTS[plant]})
    if reading == "B":
        overrides, table = reading_b(sc.gain_values(), sc.controller)
        sc = sc.with_changes(gain_overrides=overrides, controller=table)
    return sc


def run_scenario(sc: Scenario) -> dict:
    """Run a scenario through the plain loop; metrics, saturation, stability and wall time.

    Returns the metrics.json fields (tracking_mae_um, sync_mae_um, ... over the samples
    reached), saturation_fraction (per motor, share of samples with |F_i| >= the plant's
    force_limit), diverged_at [s] (None if the run finished; the divergence envelope of
    the scenario's [limits] or a model error stops it), spectral_radius, verdict and
    time_constant_s (-h / ln rho: decay > 0, growth < 0 [s]) of stability.check, stable (no divergence, at most SATURATION_FLAG of the samples at the
    limit, rho <= 1 + FD_TOL), status (in words) and wall_s (the loop alone) /
    check_s (the stability check) [s].
    """
    plant, ctrl, traj = sc.plain_models()
    L1 = sc.parameters()["trajectory"].get("L_1", ModelParams().L_1)  # the trajectory FMU's q_d
    lim = sc.limit_values()
    travel, angle = lim["motor_travel"] or math.inf, lim["platform_angle"] or math.inf
    f_lim = plant.cfg.force_limit
    stats = ErrorStatistics(_COLUMNS)
    pending = []  # rows not yet added, re-cut into blocks of _BLOCK as one row at a time would be
    sat = np.zeros(3, dtype=np.int64)

    class _Diverged(Exception):
        pass

    def record_rows(block):
        data = block[:, _ROW]
        diverged = ((np.abs(data[:, 4:7]) > travel).any(axis=1)) | (np.abs(data[:, 12]) > angle)
        stop = int(np.argmax(diverged)) if diverged.any() else None
        if stop is not None:
            data, block = data[:stop + 1], block[:stop + 1]
        if f_lim > 0.0:
            sat[:] += (np.abs(block[:, _F]) >= f_lim).sum(axis=0)
        pending.append(data)
        n = sum(len(b) for b in pending)
        if n >= _BLOCK:
            rows = np.concatenate(pending)
            full = n - n % _BLOCK
            for i in range(0, full, _BLOCK):
                stats.add(rows[i:i + _BLOCK])
            pending[:] = [rows[full:]]
        if stop is not None:
            raise _Diverged(float(data[-1, 0]))

    diverged_at = None
    t0 = time.perf_counter()
    try:
        run(plant, ctrl, traj, sc.start_time, sc.n_steps, sc.step, sc.ordering, record_rows, L1_ref=L1)
    except _Diverged as d:
        diverged_at = d.args[0]
    except ModelInputError as err:  # KinematicDomainError: the plant left its domain
        diverged_at = err.time if err.time is not None else float("nan")
    wall = time.perf_counter() - t0
    if pending:
        stats.add(np.concatenate(pending))
    out = stats.result()
    n = out["samples"]
    out["saturation_fraction"] = [int(s) / n for s in sat]
    t1 = time.perf_counter()
    rep = stability.check(sc)
    out["check_s"] = time.perf_counter() - t1
    out["spectral_radius"] = rep.spectral_radius
    out["verdict"] = rep.verdict
    out["time_constant_s"] = rep.time_constant
    out["diverged_at"] = diverged_at
    saturated = max(out["saturation_fraction"]) > SATURATION_FLAG
    rho = rep.spectral_radius
    grows, decays = rho > 1.0 + FD_TOL, rho < 1.0 - FD_TOL
    out["stable"] = diverged_at is None and not saturated and not grows
    out["status"] = ("diverged" if diverged_at is not None else
                     "chatters at the force limit" if saturated else
                     "bounded over the run, but rho > 1" if grows else
                     "stable" if decays else f"marginal (|rho - 1| < {FD_TOL:g})")
    out["wall_s"] = wall
    return out


def _run_one(spec: dict) -> dict:
    sc = paper_scenario(spec["case"], spec["law"], spec["step"], spec["stop_time"], spec["reading"],
                        spec["plant"], spec["root"])
    row = {k: v for k, v in spec.items() if k != "root"}
    row.update(run_scenario(sc))
    return row


def run_paper_gains(steps=(1e-6, 1e-5, 1e-4), stop_time: float = 0.5, readings=("A", "B"),
                    cases=tuple(CASES), laws=LAWS, plants=tuple(PLANTS), workers: int = 1,
                    root: Path = ROOT, progress=None) -> list[dict]:
    """Run every combination of case x plant x reading x law x step [s] for stop_time [s].

    Returns one dict per run: case, plant, reading, law, step, stop_time and the fields of
    run_scenario. workers > 1 runs that many processes. ``progress(done, total, row)``, if
    given, is called after each run, in the order of the rows. ValueError names a bad argument.
    """
    if not (isinstance(workers, int) and workers >= 1):
        raise UsageError(f"workers = {workers!r} is invalid: allowed is an integer >= 1")
    specs = [{"case": c, "plant": p, "reading": r, "law": law, "step": float(h), "stop_time": float(stop_time),
              "root": str(root)}
             for c in cases for p in plants for r in readings for law in laws for h in steps]
    for s in specs:  # validate everything before the first run
        paper_scenario(s["case"], s["law"], s["step"], s["stop_time"], s["reading"], s["plant"], root)
    rows = []

    def collect(results):
        for row in results:
            rows.append(row)
            if progress is not None:
                progress(len(rows), len(specs), row)
        return rows

    if workers == 1:
        return collect(map(_run_one, specs))
    with ProcessPoolExecutor(workers) as pool:
        return collect(pool.map(_run_one, specs))


def _um(values) -> str:
    return ", ".join(f"{v:.3g}" for v in values)


def paper_gains_table(rows: list[dict]) -> str:
    """Markdown table of run_paper_gains rows (MAE per motor in um, saturation in %)."""
    lines = ["| gains | plant | reading | law | step | status | rho - 1 | tau [s] | tracking MAE q1, q2, q3 [um] "
             "| sync MAE q1, q2, q3 [um] | at force limit [%] | wall [s] |",
             "|---" * 12 + "|"]
    for r in rows:
        status = r["status"] + (f" at t = {r['diverged_at']:.4g} s" if r["diverged_at"] is not None else "")
        lines.append(f"| {r['case']} | {r['plant']} | {r['reading']} | {r['law'].upper()} | {r['step'] * 1e6:g} us "
                     f"| {status} | {r['spectral_radius'] - 1.0:+.3g} | {r['time_constant_s']:.3g} | {_um(r['tracking_mae_um'])} "
                     f"| {_um(r['sync_mae_um'])} | {_um([100 * s for s in r['saturation_fraction']])} "
                     f"| {r['wall_s']:.1f} |")
    return "\n".join(lines)
