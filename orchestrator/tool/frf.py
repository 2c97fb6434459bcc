"""Margins measured from the co-simulation (`tapmp frf`): the loop's frequency response identified
from a closed-loop run of any SSP, with a seeded excitation injected at the plant inputs.

Excitation. A periodic multisine with random phases (seeded: the same seed gives the same numbers
bit for bit), not a swept sine: every frequency is excited at once for the whole run, its period is a
whole number N of communication steps so that after the transient every excited frequency falls on
an exact DFT bin (no leakage, no window), and averaging P periods shrinks what is not periodic (the
trajectory's own forces, the encoder quantization) by about sqrt(P). The excited bins are
log-spaced and dealt round robin to the directions, so that at every excited bin exactly one
direction is excited (interleaved grids): one run measures all directions of a basis at once.
Two runs per controller: the motor basis (each plant input alone, the others closed) and, with three
inputs, the mode basis of the synchronization coupling (tapmp.laws.MODE_BASIS: common, diff. Z,
diff. B), the break points of `tapmp analyze`.

Injection. The engine's input perturbation (orchestrator.engine.perturbation) adds d_k to what the
connection delivers to each plant input at every step, so the plant steps with u = y + d, y the
controller's force, and the master keeps u as it was set. From the co-simulation's own signals, at a
bin excited in direction v (v^T d = D, v^T u = U, v^T y = Y = U - D):

    S_v = U / D   (input sensitivity),    L_v = -Y / U   (the loop broken in direction v, the others closed)

which are the quantities ``orchestrator.tool.analysis`` computes from the linearized loop
(L_v = -y_v / w_v at the plant input force).

Margins from the measured points (``margins_from_points``): Ms = max |S|; the disk margin
1 / max |S - 1/2| (symmetric, one loop); the gain margin 1 / |L| where the phase of L crosses
-180 deg and the phase margin 180 deg + arg L where |L| crosses 1, both interpolated between the two
neighbouring measured points (linearly in log f); the delay margin PM / (2 pi f_gc), the smallest over
the gain crossovers. Measured on a grid, Ms and the disk margin can only miss a peak between two
points, and a crossover beyond the highest measured frequency is not seen.
"""

import json
import math
from dataclasses import dataclass

import numpy as np

from ..engine.master import CoSimulation
from ..errors import UsageError
from .frf_settings import AMPLITUDE, LINEAR_SHARE, PERIOD, PERIODS, POINTS, TRANSIENT


@dataclass(frozen=True)
class Excitation:
    """A periodic multisine per direction: ``bins`` (one int array per direction, DFT bins of the
    period of ``period_steps`` steps), RMS ``amplitude`` [input unit] per direction, random phases
    from ``seed``."""

    period_steps: int
    bins: tuple
    amplitude: float
    seed: int

    def signals(self, n_steps: int) -> np.ndarray:
        """(directions, n_steps): each direction's multisine at steps 0 .. n_steps - 1, one period
        computed and repeated (so every period is the same to the bit)."""
        rng = np.random.default_rng(self.seed)
        k = np.arange(self.period_steps)
        one = np.zeros((len(self.bins), self.period_steps))
        for m, bins in enumerate(self.bins):
            phases = rng.uniform(0.0, 2.0 * math.pi, len(bins))
            a = self.amplitude * math.sqrt(2.0 / len(bins))  # RMS of the sum: amplitude
            for b, p in zip(bins, phases):
                one[m] += a * np.cos(2.0 * math.pi * b * k / self.period_steps + p)
        return np.tile(one, -(-n_steps // self.period_steps))[:, :n_steps]


def excitation(h: float, period: float, f_min: float, f_max: float | None, points: int, directions: int,
               amplitude: float, seed: int) -> Excitation:
    """The multisine of a run at step h [s]: ``points`` log-spaced DFT bins per direction from f_min to
    f_max [Hz] (default: the highest bin below the Nyquist frequency), dealt round robin. UsageError
    naming the option for a value out of range."""
    nyq = 0.5 / h
    n = int(round(period / h)) if math.isfinite(period) else 0
    if not (period > 0.0 and n >= 4 and abs(n * h - period) <= 1e-9 * period):
        raise UsageError(f"--period = {period!r} is invalid: allowed is a whole number (>= 4) of steps of "
                         f"{h:g} s")
    f_res = 1.0 / (n * h)
    top = (n - 1) // 2  # the highest bin below Nyquist
    if f_max is None:
        f_max = top * f_res
    for key, f in (("--f-min", f_min), ("--f-max", f_max)):
        if not (math.isfinite(f) and f_res * (1.0 - 1e-9) <= f < nyq):
            raise UsageError(f"{key} = {f!r} is invalid: allowed is a frequency in [{f_res:g}, {nyq:g}) Hz "
                             f"(from 1 / --period to below the Nyquist frequency 1/(2 step), step = {h:g} s)")
    if not f_min < f_max:
        raise UsageError(f"--f-min = {f_min!r} is invalid: allowed is a frequency below --f-max = {f_max!r} Hz")
    lo, hi = max(1, int(math.ceil(f_min / f_res - 1e-9))), min(top, int(math.floor(f_max / f_res + 1e-9)))
    if not (isinstance(points, int) and points >= 2 and points * directions <= hi - lo + 1):
        raise UsageError(f"--points = {points!r} is invalid: allowed is an integer from 2 to "
                         f"{(hi - lo + 1) // directions} (the {hi - lo + 1} bins between --f-min and --f-max "
                         f"at 1 / --period = {f_res:g} Hz, shared by {directions} directions)")
    if not (math.isfinite(amplitude) and amplitude > 0.0):
        raise UsageError(f"--amplitude = {amplitude!r} is invalid: allowed is an RMS force > 0 (finite)")
    if not (isinstance(seed, int) and 0 <= seed < 2 ** 63):
        raise UsageError(f"--seed = {seed!r} is invalid: allowed is an integer from 0 to {2 ** 63 - 1}")
    bins = _log_bins(lo, hi, points * directions)
    return Excitation(n, tuple(bins[m::directions] for m in range(directions)), float(amplitude), int(seed))


def _log_bins(lo: int, hi: int, count: int) -> np.ndarray:
    """``count`` distinct integers from lo to hi, as close to log-spaced as distinct integers allow."""
    out = []
    for i in range(count):  # the i-th of the remaining bins, log-spaced between the last taken and hi
        start = out[-1] + 1 if out else lo
        left = count - i
        if hi - start + 1 <= left:
            out += list(range(start, start + left))
            break
        nxt = int(round(start * (hi / start) ** (1.0 / (left - 1)))) if left > 1 else hi
        out.append(start if i == 0 else max(start, min(nxt, hi - left + 1)))
    return np.array(out[:count])


def basis(name: str, n_inputs: int) -> np.ndarray:
    """The directions (columns) of a basis: ``inputs`` (the identity) or ``modes`` (tapmp.laws.MODE_BASIS)."""
    if name == "inputs":
        return np.eye(n_inputs)
    from tapmp.laws import MODE_BASIS
    return np.array([v for _, _, v in MODE_BASIS], dtype=float).T


def identify(u: np.ndarray, d: np.ndarray, V: np.ndarray, exc: Excitation, periods: int) -> dict:
    """S and L per direction (columns of V) from the plant inputs u and the injected d (inputs x
    steps, the last ``periods`` periods of the run): {direction index: (bins, S, L, spread)}, spread
    the largest relative standard error of S over the periods."""
    n = exc.period_steps
    u, d = (x[:, -periods * n:].reshape(x.shape[0], periods, n) for x in (u, d))
    Uk, Dk = np.fft.rfft(u, axis=2), np.fft.rfft(d, axis=2)  # (inputs, periods, bins)
    out = {}
    for m, bins in enumerate(exc.bins):
        Uv = np.einsum("i,ipk->pk", V[:, m], Uk[:, :, bins])
        Dv = np.einsum("i,ipk->pk", V[:, m], Dk[:, :, bins])
        S_each = Uv / Dv
        S = Uv.mean(axis=0) / Dv.mean(axis=0)
        spread = float(np.max(np.std(S_each, axis=0) / np.abs(S) / math.sqrt(periods))) if periods > 1 else None
        out[m] = (bins, S, 1.0 / S - 1.0, spread)  # L = -(U - D) / U = D / U - 1
    return out


def _interp(f, y, i, target):
    """The point between f[i] and f[i + 1] where the real sequence y reaches ``target``, linear in log f."""
    a = (target - y[i]) / (y[i + 1] - y[i])
    return math.exp(math.log(f[i]) + a * (math.log(f[i + 1]) - math.log(f[i]))), a


def margins_from_points(f: np.ndarray, L: np.ndarray) -> dict:
    """Margins of a loop from its measured points L at f [Hz] (module doc): Ms, disk_margin, gm (upper,
    inf if none measured), gm_lower (None if none), pm_deg (inf if |L| never crosses 1), f_gc_hz, f_pc_hz,
    delay_margin_s (None if no crossover with a positive phase margin)."""
    S = 1.0 / (1.0 + L)
    mag = np.log(np.abs(L))
    phase = np.unwrap(np.angle(L))
    gms, pms = [], []
    for i in np.nonzero(np.diff(np.sign(mag)))[0]:
        fc, a = _interp(f, mag, i, 0.0)
        ph = phase[i] + a * (phase[i + 1] - phase[i])
        pms.append((float(np.remainder(math.degrees(ph), 360.0) - 180.0), fc))
    rel = np.remainder(phase + math.pi, 2.0 * math.pi) - math.pi  # arg L in (-pi, pi]: -180 deg is +-pi
    for i in np.nonzero(np.diff(np.sign(np.sin(rel))))[0]:
        if abs(rel[i]) < math.pi / 2.0 or abs(rel[i + 1]) < math.pi / 2.0:
            continue  # Im L changes sign with Re L > 0: a crossing of 0 deg, not of -180
        fc, a = _interp(f, np.sin(rel), i, 0.0)  # Im L changes sign where sin(arg L) does
        gms.append((1.0 / math.exp(mag[i] + a * (mag[i + 1] - mag[i])), fc))
    upper = [g for g in gms if g[0] > 1.0]
    lower = [g for g in gms if g[0] <= 1.0]
    gm, f_pc = min(upper) if upper else (math.inf, None)
    pm, f_gc = min(pms, key=lambda p: abs(p[0])) if pms else (math.inf, None)
    delays = [math.radians(p) / (2.0 * math.pi * fc) for p, fc in pms if p > 0.0]
    return {"Ms": float(np.max(np.abs(S))), "disk_margin": float(1.0 / np.max(np.abs(S - 0.5))),
            "gm": gm, "gm_lower": max(lower)[0] if lower else None, "pm_deg": pm, "f_gc_hz": f_gc,
            "f_pc_hz": f_pc, "delay_margin_s": min(delays) if delays else None}


def plant_inputs(scenario) -> list[str]:
    """The plant's force inputs of a TAPMP scenario, by role: "plant.<input>" for each input of the
    plant that the controller drives (tapmp.interface.PLANT_SOURCES)."""
    from tapmp.interface import PLANT_SOURCES
    from tapmp.models import PLANT
    from .roles import ROLES
    plant = next(role for role, model in ROLES.items() if model == PLANT)
    return [f"{plant}.{name}" for name in PLANT_SOURCES]


def run_excited(scenario, ssp, inputs: list[str], V: np.ndarray, exc: Excitation, transient: int,
                periods: int) -> dict:
    """One closed-loop co-simulation of ``scenario`` on ``ssp`` with d = V s added to ``inputs``
    ("element.variable" or "role.variable"), s the excitation's multisines, for transient + periods
    periods: {"u": plant inputs as set (inputs x steps), "d": the injection, "models": the SSP's
    modelNames}."""
    from dataclasses import replace
    from .results import run_options
    n_steps = (transient + periods) * exc.period_steps
    d = V @ exc.signals(n_steps)
    options = replace(run_options(scenario), perturb={name: d[i] for i, name in enumerate(inputs)}, stepper="python")
    with CoSimulation(ssp, scenario.parameters(), options) as sim:
        rows = np.empty((n_steps, len(sim.columns)))
        sim.advance(rows)
        applied = sim.perturbed_inputs
        models = sorted({u.md.modelName for u in sim.units.values()})
    return {"u": np.array([applied[name] for name in inputs]), "d": d, "models": models}


def analytic_loops(scenario, bases: dict) -> dict:
    """The linearized loop of `tapmp analyze` (orchestrator.tool.analysis) for the break points of
    ``bases`` ({basis: (names, V)}): {name: (split loop's L at any f, margins)}."""
    from . import analysis
    split = analysis.SplitLoop(scenario)
    freqs = analysis.frequency_grid(split.h)
    result = analysis.analyze_runs({"run": scenario}, freqs)["run"]
    out = {}
    for names, V in bases.values():
        for m, name in enumerate(names):
            G = split.loop(V[:, m])
            loop = result["loops"].get(name, {})
            out[name] = {"L": (lambda f, G=G: -analysis._response(G, np.asarray(f, dtype=float), split.h)),
                         "margins": {k: loop.get(k) for k in ("Ms", "disk_margin", "gm", "gm_lower", "pm_deg",
                                                               "f_gc_hz", "f_pc_hz", "delay_margin_s")}}
    return out


def measure(runs: dict, ssp, inputs: list[str] | None = None, period: float = PERIOD, f_min: float | None = None,
            f_max: float | None = None, points: int = POINTS, amplitude: float = AMPLITUDE, seed: int = 0,
            transient: int = TRANSIENT, periods: int = PERIODS, analytic: bool = True, say=None) -> dict:
    """The measured loops of each scenario of ``runs`` ({name: Scenario}) on ``ssp``: two excited runs
    each (the inputs' basis and, with three inputs, the modes), identified and reduced to margins,
    beside the analytic ones of the linearized TAPMP loop when ``analytic``. ``inputs``: the plant's
    force inputs ("element.variable"; default: the TAPMP plant's by role)."""
    say = say or (lambda line: None)
    first = next(iter(runs.values()))
    inputs = list(inputs) if inputs else plant_inputs(first)
    for key, n, least in (("--periods", periods, 1), ("--transient", transient, 0)):
        if not (isinstance(n, int) and least <= n <= 1000):
            raise UsageError(f"{key} = {n!r} is invalid: allowed is an integer from {least} to 1000")
    for name, sc in runs.items():
        if sc.event_mode:  # the engine's perturbation holds an input over the macro step (engine/perturbation.py)
            raise UsageError(f"event_mode = true is invalid for a frequency response measurement (run {name}): "
                             "allowed is false (an event inside a macro step would set the excited input again)")
    h = first.step
    exc = excitation(h, period, 1.0 / period if f_min is None else f_min, f_max, points, len(inputs), amplitude, seed)
    bases = {"inputs": ([f"motor {i + 1}" for i in range(len(inputs))], basis("inputs", len(inputs)))}
    if len(inputs) == 3:
        from tapmp.laws import MODE_LABELS
        bases["modes"] = (list(MODE_LABELS), basis("modes", 3))
    result = {"ssp": _shown(ssp), "inputs": inputs, "h": h, "nyquist_hz": 0.5 / h, "seed": exc.seed,
              "excitation": {"kind": "periodic multisine, random phases, interleaved grids", "period_s": exc.period_steps * h,
                             "period_steps": exc.period_steps, "transient_periods": transient,
                             "measured_periods": periods, "rms_per_direction": exc.amplitude,
                             "points_per_direction": points,
                             "from_hz": float(min(b[0] for b in exc.bins)) / (exc.period_steps * h),
                             "to_hz": float(max(b[-1] for b in exc.bins)) / (exc.period_steps * h)},
              "runs": {}}
    for i, (name, sc) in enumerate(runs.items(), 1):
        tell = (lambda line, i=i, name=name: say(f"frf: run {i}/{len(runs)} {name}: {line}"))
        result["runs"][name] = _measured_run(sc, ssp, inputs, bases, exc, transient, periods, analytic, tell)
    return result


def _measured_run(sc, ssp, inputs, bases, exc, transient, periods, analytic, say) -> dict:
    """One controller's measurement (``measure``): a run per basis, identified and reduced to margins, its
    largest plant input against the force limit, and the analytic loop where the SSP has it as its twin."""
    from .metrics import saturation_limit
    h = sc.step
    run = {"law": sc.law, "loops": {}, "u_max": 0.0, "force_limit": saturation_limit(sc.parameters())}
    models = []
    for basis_name, (names, V) in bases.items():
        say(f"the {basis_name} excited, {(transient + periods) * exc.period_steps} steps")
        r = run_excited(sc, ssp, inputs, V, exc, transient, periods)
        models = r["models"]
        run["u_max"] = max(run["u_max"], float(np.max(np.abs(r["u"]))))
        for m, (bins, S, L, spread) in identify(r["u"], r["d"], V, exc, periods).items():
            f = bins / (exc.period_steps * h)
            run["loops"][names[m]] = {"f_hz": f, "S": S, "L": L, "spread": spread,
                                      "measured": margins_from_points(f, L)}
    run["linear"] = bool(run["force_limit"] <= 0.0 or run["u_max"] < LINEAR_SHARE * run["force_limit"])
    foreign = _not_linearized(models)
    if not analytic:
        run["analytic"] = "not asked"
    elif foreign:
        run["analytic"] = f"none: the linearized loop does not model {', '.join(foreign)} of the SSP"
    else:
        say("the analytic loop")
        run["analytic"] = "the linearized TAPMP loop at the scenario's start"
        _add_analytic(run, analytic_loops(sc, bases))
    return run


def _add_analytic(run: dict, loops: dict) -> None:
    """Each measured loop of ``run`` beside its analytic twin (``analytic_loops``): the analytic margins and L at
    the measured points, the analytic Ms on those points, and the largest |S measured - S analytic| there."""
    run["_analytic_L"] = {}  # {break point: L(f)} for the figures, not written
    for b, a in loops.items():
        run["_analytic_L"][b] = a["L"]
        x = run["loops"][b]
        La = a["L"](x["f_hz"])
        x["analytic"] = a["margins"]
        x["L_analytic"] = La
        x["Ms_analytic_on_points"] = float(np.max(np.abs(1.0 / (1.0 + La))))
        # the measurement's error on S: it bounds how far the measured Ms and disk margin can be off
        x["S_error"] = float(np.max(np.abs(x["S"] - 1.0 / (1.0 + La))))


def _shown(path) -> str:
    """``path`` relative to the current directory if it is inside it (a result written into the repository
    names no machine's folders), else as given."""
    from pathlib import Path
    try:
        return str(Path(path).resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(path)


# The roles whose models the linearized loop reproduces (tool/stability.OneStepMap: the trajectory, the
# controller and the plant, one step each): an SSP with any other FMU has no analytic twin.
LINEARIZED_ROLES = ("trajectory", "controller", "plant")


def _not_linearized(models) -> list:
    """The modelNames of ``models`` that the linearized loop (orchestrator.tool.analysis) does not step: an SSP
    with none of them has it as its analytic twin. The roles' models count with their variants (the clocked
    controller)."""
    from tapmp.models import MODELS
    from .roles import ROLES
    linearized = {ROLES[role] for role in LINEARIZED_ROLES}
    described = {r.name for r in MODELS if (r.variant_of or r.name) in linearized}
    return sorted(set(models) - described)


MEASURES = (("Ms", "Ms", ".3f"), ("GM", "gm", ".3g"), ("PM [deg]", "pm_deg", ".1f"), ("disk", "disk_margin", ".3f"),
            ("delay [us]", "delay_margin_s", "us"))


def _cell(v, spec) -> str:
    if v is None:
        return "-"
    if isinstance(v, float) and math.isinf(v):
        return "inf"
    return f"{v * 1e6:.1f}" if spec == "us" else format(v, spec)


def table(result: dict) -> str:
    """Markdown table: per run and break point, each margin measured (and analytic, where there is one)."""
    head = ("| run | break point | " + " | ".join(f"{t} meas. / anal." for t, _, _ in MEASURES)
            + " | anal. Ms on the points | max abs(S meas. - S anal.) |")
    lines = [head, "|" + "---|" * (len(MEASURES) + 4)]
    for run, r in result["runs"].items():
        for b, x in r["loops"].items():
            a = x.get("analytic") or {}
            cells = [f"{_cell(x['measured'][k], s)} / {_cell(a.get(k), s)}" if a else _cell(x["measured"][k], s)
                     for _, k, s in MEASURES]
            extra = [f"{x['Ms_analytic_on_points']:.3f}", f"{x['S_error']:.3f}"] if "S_error" in x else ["-", "-"]
            lines.append(f"| {run} | {b} | " + " | ".join(cells + extra) + " |")
    return "\n".join(lines)


def _plain(x):
    if isinstance(x, dict):
        return {k: _plain(v) for k, v in x.items() if k not in ("S", "L", "L_analytic") and not k.startswith("_")}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if isinstance(x, np.ndarray):
        return _plain(x.tolist())
    if isinstance(x, float) and not math.isfinite(x):
        return str(x)
    if isinstance(x, (np.floating, np.integer)):
        return _plain(x.item())
    return x


def files_of(out, runs) -> list:
    """The files :func:`write` makes in ``out`` for the runs ``runs`` (names): frf.json and a figure per run."""
    from pathlib import Path
    return [Path(out) / "frf.json", *(Path(out) / f"frf_{run}.png" for run in runs)]


def write(result: dict, out, figures: bool = True) -> list:
    """frf.json (margins, the measured points as magnitude and phase of L and S) and the figures into out."""
    from pathlib import Path
    from .folders import write_text
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    data = _plain(result)
    for run, r in result["runs"].items():
        for b, x in r["loops"].items():
            data["runs"][run]["loops"][b]["points"] = {
                "L_mag": np.abs(x["L"]).tolist(), "L_phase_deg": np.angle(x["L"], deg=True).tolist(),
                "S_mag": np.abs(x["S"]).tolist()}
    files = []
    if figures:
        from .frf_plots import plot_frf
        files = [str(p) for p in plot_frf(result, files_of(out, result["runs"])[1:],
                                          {run: r.get("_analytic_L") for run, r in result["runs"].items()})]
    data["files"] = files
    write_text(out / "frf.json", json.dumps(data, indent=1) + "\n")
    return [str(out / "frf.json"), *files]
