"""Worst case over a region rather than samples: the margins of each law (robustness.point_margins)
at poses along the trajectory, at the corners of the platform's envelope and at the vertices of a
study's parameter box, and the worst of each (`tapmp analyze --worst-case`)."""

import itertools
import time

from tapmp.kinematics import inverse
from tapmp.params import ModelParams

from ..errors import UsageError
from ..tool import analysis
from ..tool.baselines import compare_runs
from ..tool.robustness import MEASURES, point_margins
from ..tool.scenario import model_tuple
from .study_file import apply_changes, base_value

WORSE = {"Ms": max, "gm_upper": min, "gm_lower": max, "disk_margin": min, "delay_margin_all_s": min}
# plant parameters the linearization sets to zero (stability.loop_models): a box factor that only
# moves these leaves every margin as it is
LINEARIZED_AWAY = {"plant.encoder_resolution", "plant.F_c1", "plant.F_c2", "plant.F_c3", "plant.noise_rms"}
POSE_KEYS = ("X0", "Z0", "B0", "dX0", "dZ0", "dB0")


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
    return model_tuple(ModelParams, scenario.parameters()["plant"]).L_1


def box_vertices(study, scenario) -> tuple[list, list]:
    """([(label, scenario)], [left-out factor names]): the vertices of a study's parameter box, every
    uniform (or loguniform) Monte Carlo factor at its low and at its high end (relative ones times
    the scenario's value), applied to ``scenario``; a factor that only moves what the linearization
    sets to zero (LINEARIZED_AWAY: quantization, Coulomb friction, noise) changes no margin and is left
    out. UsageError if the study has no such factor."""
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
