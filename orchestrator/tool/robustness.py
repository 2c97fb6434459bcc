"""A baseline at SC-DC's robustness: a PD per mode whose peak sensitivity Ms equals SC-DC's.

SC-DC's stiffer differential modes cost robustness: with the default gains its differential
modes have Ms about 2.5 (phase margin about 23 deg) where the paper's APD-DC has 1.2 (about
51 deg), docs/analysis.md. A comparison at unequal robustness credits SC-DC with what any
stiffer, less robust loop would give. ``ms_matched`` tunes the baseline that removes this:
PID-DC (law 2) without integral (ki_c = ki_d = 0), SC-DC's derivative gains per mode, and the
proportional gains kp_c and kp_d chosen (brentq) so that Ms of the common mode and the mean Ms
of the two differential modes equal SC-DC's, on the same frequency grid, loop broken at the plant
input force as ``tapmp analyze`` does (orchestrator.tool.analysis).
"""

from typing import NamedTuple

import numpy as np
from scipy.optimize import brentq

from tapmp.control import ModalGains

from ..errors import UsageError
from . import analysis
from .scenario import model_tuple

MODES = ("common", "diff. Z", "diff. B")
RTOL = 1e-4  # relative tolerance of the matched Ms


def _sensitivity_peaks(split: "analysis.SplitLoop", freqs: np.ndarray, names=MODES) -> dict[str, float]:
    """max |S| per break point of ``names`` (default the modes) of a split loop, on freqs [Hz]
    (S = 1 / (1 + L))."""
    out = {}
    z = np.exp(1j * 2.0 * np.pi * freqs * split.h)
    for name in names:
        sys = split.loop(analysis.break_directions()[name])
        A, B, C, D = (np.asarray(M, dtype=float) for M in (sys.A, sys.B, sys.C, sys.D))
        # (z I - A)^-1 B for every z at once through the eigenvectors (A is diagonalizable here;
        # the check below falls back to one solve per frequency if it is not well conditioned)
        w, V = np.linalg.eig(A)
        if np.linalg.cond(V) < 1e8:
            g = (C @ V)[0] * np.linalg.solve(V, B)[:, 0]
            G = (g[None, :] / (z[:, None] - w[None, :])).sum(axis=1) + D[0, 0]
        else:
            G = np.array([(C @ np.linalg.solve(zk * np.eye(len(A)) - A, B))[0, 0] + D[0, 0] for zk in z])
        out[name] = float(np.max(np.abs(1.0 / (1.0 - G))))  # L = -G (module analysis)
    return out


def mode_peaks(scenario, freqs: np.ndarray | None = None) -> dict[str, float]:
    """Ms of the common and the two differential modes of a scenario's sampled loop."""
    split = analysis.SplitLoop(scenario)
    return _sensitivity_peaks(split, analysis.frequency_grid(split.h) if freqs is None else freqs)


class Matched(NamedTuple):
    """The tuned baseline: its modal gains, SC-DC's Ms per mode (target), its own (achieved), and
    a note: "" when matched, else why the mode-matched gains were kept."""

    gains: ModalGains
    target: dict
    achieved: dict
    note: str = ""

    def text(self) -> str:
        """One sentence for comparison.md: the Ms of both per mode, or why they were not matched."""
        if self.note:
            return f"Robustness-matched baseline: not tuned ({self.note}); it runs with the mode-matched gains."
        return ("Robustness-matched baseline: kp_c = {:.4g}, kp_d = {:.4g} give Ms ".format(
            self.gains.kp_c, self.gains.kp_d) + ", ".join(
            f"{m} {self.achieved[m]:.3f}" for m in MODES) + " against SC-DC's " + ", ".join(
            f"{self.target[m]:.3f}" for m in MODES) + ".")


def ms_matched(scdc_run, pd_run) -> Matched:
    """Tune ``pd_run`` (a PID-DC scenario without integral, e.g. compare's apd-dc-mode-matched)
    so that its Ms per mode equals ``scdc_run``'s (module doc). If SC-DC's sampled loop is not
    stable (Ms then measures nothing) or no P gain reaches its Ms, the start gains are kept and
    the note says why."""
    freqs = analysis.frequency_grid(scdc_run.step)
    start = model_tuple(ModalGains, pd_run.controller)._replace(ki_c=0.0, ki_d=0.0)
    split = analysis.SplitLoop(scdc_run)
    rho = float(max(abs(np.linalg.eigvals(split.closed_loop()))))
    if analysis.verdict_for(rho) != "stable":
        return Matched(start, {}, {}, f"SC-DC's sampled loop is not stable, spectral radius {rho:.6g}")
    target = _sensitivity_peaks(split, freqs)

    def peaks(gains: ModalGains) -> dict:
        return mode_peaks(pd_run.with_changes(controller={**pd_run.controller, **gains._asdict()}), freqs)

    def solve(field: str, value_of, goal: float, gains: ModalGains) -> float:
        k0 = getattr(gains, field)

        def f(log_k):
            return value_of(peaks(gains._replace(**{field: float(np.exp(log_k))}))) - goal

        lo = hi = np.log(k0)
        f0 = f(lo)
        step = 0.25 if f0 < 0 else -0.25  # Ms grows with the stiffness
        for _ in range(40):
            hi = lo + step
            if f(hi) * f0 <= 0:
                break
            lo, step = hi, step * 1.5
        else:
            raise UsageError(f"{field}: no value within reach of {k0:g} gives Ms = {goal:.4g}")
        a, b = sorted((lo, hi))
        return float(np.exp(brentq(f, a, b, rtol=RTOL * 1e-2)))

    try:
        gains = start._replace(kp_d=solve("kp_d", lambda p: (p["diff. Z"] + p["diff. B"]) / 2.0,
                                          (target["diff. Z"] + target["diff. B"]) / 2.0, start))
        gains = gains._replace(kp_c=solve("kp_c", lambda p: p["common"], target["common"], gains))
    except ValueError as err:
        return Matched(start, target, {}, str(err))
    return Matched(gains, target, peaks(gains))


# Worst case over a region rather than samples: the margins of each law at poses along the
# trajectory, at the corners of the platform's envelope and at the vertices of a study's parameter
# box (its uniform Monte Carlo factors at their low and high ends), and the worst of each.

MEASURES = ("Ms", "gm_upper", "gm_lower", "disk_margin", "delay_margin_all_s")
WORSE = {"Ms": max, "gm_upper": min, "gm_lower": max, "disk_margin": min, "delay_margin_all_s": min}
# plant parameters the linearization sets to zero (stability.loop_models): a box factor that only
# moves these leaves every margin as it is
LINEARIZED_AWAY = {"plant.encoder_resolution", "plant.F_c1", "plant.F_c2", "plant.F_c3", "plant.noise_rms"}
POSE_KEYS = ("X0", "Z0", "B0", "dX0", "dZ0", "dB0")


def point_margins(scenario, points: int = analysis.POINTS) -> dict:
    """The margins of a scenario's sampled loop at its start: Ms, the largest peak sensitivity over
    the six break points (analysis.BREAK_POINTS, on ``points`` frequencies up to Nyquist); gm_upper
    and gm_lower, the all-loops gain margin factors (analysis.all_loops_gain_margin; gm_lower None:
    stable down to 0.01x); disk_margin, the all-loops symmetric disk margin; delay_margin_all_s [s],
    one delay on all three motors' forces; with the spectral radius and verdict. A loop that is not
    stable gets None for every margin."""
    split = analysis.SplitLoop(scenario)
    rho = float(max(abs(np.linalg.eigvals(split.closed_loop()))))
    out = {"spectral_radius": rho, "verdict": analysis.verdict_for(rho)}
    if out["verdict"] != "stable":
        return {**out, **{m: None for m in MEASURES}}
    freqs = analysis.frequency_grid(split.h, points=points)
    gm = analysis.all_loops_gain_margin(split)
    return {**out, "Ms": max(_sensitivity_peaks(split, freqs, analysis.BREAK_POINTS).values()),
            "gm_upper": gm["gm_upper"], "gm_lower": gm["gm_lower"],
            "disk_margin": analysis.disk_margin(split.A, split.B, split.C, split.D, split.h, freqs)["disk_margin"],
            "delay_margin_all_s": analysis.delay_margin(split, np.eye(3))}


def _on_trajectory(scenario, **changes):
    """The scenario started on its reference (the plant's initial state left to the trajectory)."""
    plant = {k: v for k, v in scenario.plant.items() if k not in POSE_KEYS}
    return scenario.with_changes(start_on_trajectory=True, plant=plant, **changes)


def trajectory_poses(scenario, count: int) -> list:
    """[(label, scenario)]: the loop at ``count`` communication points evenly spread over the run
    [start_time, stop_time), each with the plant on the reference there (pose and velocity)."""
    h = scenario.step
    span = scenario.stop_time - scenario.start_time
    out = []
    for k in range(count):
        t = scenario.start_time + round(k * span / count / h) * h  # on the sample grid
        out.append((f"trajectory t = {t:.4g} s", _on_trajectory(scenario, start_time=t)))
    return out


def at_pose(scenario, pose) -> "object":
    """The scenario resting at ``pose`` (X [m], Z [m], B [rad]): the reference a step move from the
    pose to itself (so it rests there), the plant started on it at rest."""
    X, Z, B = (float(v) for v in pose)
    move = {"profile": 1, "X_a": X, "Z_a": Z, "B_a": B, "X_b": X, "Z_b": Z, "B_b": B,
            "t_move": 0.5 * (scenario.start_time + scenario.stop_time)}
    return _on_trajectory(scenario, trajectory={**scenario.trajectory, **move})


def domain_corners(scenario) -> list:
    """[(label, scenario)]: the eight corners (+-d, +-d, +-B_max) of the platform's envelope, B_max
    its limits.platform_angle [rad] and d [m] the largest displacement in X and Z at which every
    corner keeps each motor within limits.motor_travel (bisection to 1 um), each resting there."""
    from tapmp.kinematics import inverse
    lim = scenario.limit_values()
    b, travel = lim["platform_angle"], lim["motor_travel"]
    L1 = _platform_width(scenario)
    signs = [(sx, sz, sb) for sx in (-1, 1) for sz in (-1, 1) for sb in (-1, 1)]

    def inside(d):
        return all(max(abs(q) for q in inverse(sx * d, sz * d, sb * b, L1)) <= travel for sx, sz, sb in signs)

    lo, hi = 0.0, travel
    while hi - lo > 1e-6:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if inside(mid) else (lo, mid)
    return [(f"corner X {sx * lo * 1e3:+.2f} mm, Z {sz * lo * 1e3:+.2f} mm, B {sb * b:+.3f} rad",
             at_pose(scenario, (sx * lo, sz * lo, sb * b))) for sx, sz, sb in signs]


def _platform_width(scenario) -> float:
    """L1 [m], the plant's platform width as its FMU gets it."""
    from tapmp.params import ModelParams
    from .scenario import model_tuple
    return model_tuple(ModelParams, scenario.parameters()["plant"]).L_1


def box_vertices(study, scenario) -> tuple[list, list]:
    """([(label, scenario)], [left-out factor names]): the vertices of a study's parameter box, every
    uniform (or loguniform) Monte Carlo factor at its low and at its high end (relative ones times
    the scenario's value), applied to ``scenario``; a factor that only moves what the linearization
    sets to zero (LINEARIZED_AWAY: quantization, Coulomb friction, noise) changes no margin and is left
    out. UsageError if the study has no such factor."""
    import itertools
    from ..studies.study_file import apply_changes, base_value
    factors = [f for f in study.factors if f.distribution in ("uniform", "loguniform")]
    kept = [f for f in factors if not set(f.targets) <= LINEARIZED_AWAY]
    if not kept:
        raise UsageError(f"--box {study.source}: no uniform Monte Carlo factor ([monte_carlo.vary]) that changes "
                         "the linearized loop: allowed is a study whose box moves a plant or controller parameter")
    out = []
    for ends in itertools.product(*[(("low", f.low), ("high", f.high)) for f in kept]):
        changes = {}
        for f, (_, value) in zip(kept, ends):
            for t in f.targets:
                b = base_value(scenario, t) if f.relative else 1.0
                changes[t] = [value * x for x in b] if isinstance(b, list) else (value * b if f.relative else value)
        label = "box " + ", ".join(f"{f.name} {end}" for f, (end, _) in zip(kept, ends))
        out.append((label, apply_changes(scenario, changes, f"--box {study.source}")))
    return out, [f.name for f in factors if f not in kept]


def worst_case(runs: dict, study, poses: int = 8, points: int = analysis.POINTS, say=print) -> dict:
    """The worst margins of each run ({name: Scenario}) over the region: its start, ``poses`` poses
    along its trajectory (trajectory_poses), the corners of the envelope (domain_corners) and the
    vertices of ``study``'s parameter box (box_vertices; at the start pose, the controller's own model
    unchanged). Returns {"left_out": [factor names], "points": count per run, "runs": {name: {measure:
    {"value", "where"}, "unstable": [labels]}}} with the measures of point_margins, each at its worst
    (WORSE: the largest Ms and lower gain margin, the smallest of the others) over the stable points.
    ``say`` gets a progress line at the end of each run and after any point that ends 20 s or more
    after the last line (a point takes a few seconds, so a line comes well within 30 s)."""
    import time
    out, left = {}, []
    last = time.monotonic()
    for name, sc in runs.items():
        boxed, left = box_vertices(study, sc)
        region = [("start", sc)] + trajectory_poses(sc, poses) + domain_corners(sc) + boxed
        found, unstable = {m: None for m in MEASURES}, []
        for i, (label, point) in enumerate(region, start=1):
            r = point_margins(point, points)
            if r["verdict"] != "stable":
                unstable.append(label)
            for m in MEASURES:
                v = r[m]
                if v is None:
                    continue
                v = float(v)
                if found[m] is None or WORSE[m](v, found[m]["value"]) != found[m]["value"]:
                    found[m] = {"value": v, "where": label}
            if time.monotonic() - last > 20.0 or i == len(region):
                say(f"worst case: {name}: {i}/{len(region)} points")
                last = time.monotonic()
        out[name] = {**found, "unstable": unstable}
    return {"left_out": left, "points": len(region) if runs else 0, "runs": out}


def worst_case_table(result: dict) -> str:
    """Markdown table: per run the worst of each measure and where it occurs."""
    def cell(x, fmt, scale=1.0):
        return "-" if x is None else f"{x['value'] * scale:{fmt}} ({x['where']})"

    lines = ["| run | largest Ms (where) | smallest all-loops gain margin, upper [x] | largest lower gain margin [x] "
             "| smallest disk margin, all loops | smallest delay margin, all motors [ms] | unstable points |",
             "|---" * 7 + "|"]
    for name, r in result["runs"].items():
        lines.append(f"| {name} | {cell(r['Ms'], '.3f')} | {cell(r['gm_upper'], '.3g')} | {cell(r['gm_lower'], '.3g')} "
                     f"| {cell(r['disk_margin'], '.3f')} | {cell(r['delay_margin_all_s'], '.4g', 1e3)} "
                     f"| {', '.join(r['unstable']) or 'none'} |")
    return "\n".join(lines)


def worst_case_runs(scenario, study, names: str | None = None) -> dict:
    """{name: Scenario}: the runs of `tapmp compare` for ``scenario`` named by ``names`` (comma-separated),
    default the baselines the study's grid runs (its ``baseline`` key), else every run. UsageError names
    an unknown run and lists the allowed ones."""
    from .baselines import compare_runs
    runs = compare_runs(scenario)
    wanted = ([n.strip() for n in names.split(",") if n.strip()] if names is not None
              else list(study.grid.get("baseline", runs)))
    unknown = [n for n in wanted if n not in runs]
    if unknown or not wanted:
        raise UsageError(f"--runs = {names!r} is invalid: allowed is a comma-separated list of {', '.join(runs)}")
    return {n: runs[n] for n in wanted}


def check_poses(poses) -> int:
    """``poses`` if it is an integer from 0 to MAX_POSES, else UsageError naming it."""
    if not (isinstance(poses, int) and 0 <= poses <= MAX_POSES):
        raise UsageError(f"--poses = {poses!r} is invalid: allowed is an integer from 0 to {MAX_POSES}")
    return poses


MAX_POSES = 1000  # poses along the trajectory: each is one linearization and its margins (bounded work)
