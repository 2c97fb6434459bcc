"""Frequency response, margins and closed-loop poles of the sampled loop (`tapmp analyze`).

The loop is the one ``tapmp check`` linearizes (orchestrator.tool.stability): the
one-step map of the sampled loop from communication point t to t + h, built from the
model functions the FMUs run, linearized by central differences about the scenario's
start with the nonlinear parts left out (quantization, Coulomb friction, saturation).
Here the map is split at the **plant input force**: the plant steps with a force w
[N, per motor] instead of the force the controller hands it, and the controller's force
y [N] (the command F of the sample, or with the ``jacobi`` ordering the command held from
the previous sample) is an output. Linearized, that is the discrete-time system

    x_{k+1} = A x_k + B w_k,    y_k = C x_k (+ D w_k, D = 0: the command of a sample
                                            depends on the state at that sample only)

with the loop closed by w = y; A + B C is the matrix whose eigenvalues ``check`` reports
(on the same invariant subspace: SC-DC's constant sum of the integrals of c and
PID-DC's unused integral modes are removed).

Break points. A break point is a direction v in the space of the three motor forces:
a motor (v = e_i) or a mode of the synchronization coupling (tapmp.modal.MODES: common
(1, 1, 1)/sqrt(3), differential Z (1, 0, -1)/sqrt(2), differential B (1, -2, 1)/sqrt(6)).
The loop is opened in that direction only, with the other two directions closed (a
loop-at-a-time break):

    w = (I - v v^T) y + v w_v,   y_v = v^T y,   L_v(z) = -y_v / w_v  (negative feedback)

so that scaling the force in direction v by a factor k turns the closed loop into
A + B (I + (k - 1) v v^T) C, and the gain margin is the k at which its spectral radius
crosses 1. For each break point:

* L: the loop gain L_v(e^{j 2 pi f h}), dimensionless (force over force);
* S = 1 / (1 + L): sensitivity at the plant input (a force disturbance d in direction v
  to the total force there); T = L / (1 + L) = 1 - S: complementary sensitivity;
* gain margin GM (factor and dB) at the phase crossover, phase margin PM [deg] at the
  gain crossover (``margins``: crossings of L evaluated exactly on the unit circle);
* Ms = max |S| (1 / Ms is the smallest distance of L to -1), Mt = max |T| on the grid;
* bandwidth: the lowest frequency at which |S| rises to 1/sqrt(2) (-3 dB): below it a
  disturbance at the plant input is attenuated (Skogestad and Postlethwaite, Sec. 2.4.5);
* the disturbance sensitivity (compliance) e_v / d_v [m/N]: the closed loop (all
  directions closed) from a force d v added at the plant input to the tracking error
  v^T e, e = q_d - q (true motor positions), with its peak and its value at the lowest
  frequency of the grid (the static stiffness is its inverse).

A run whose closed loop is not stable (the verdict of ``check``) gets no margins, peaks or
bandwidth (None): they measure a stable loop's distance to instability, and its responses are
no steady state (the figures leave it out).

The closed-loop poles z (eigenvalues of A + B C) are given as s = ln(z) / h: natural
frequency |s| / (2 pi) [Hz] and damping -Re(s) / |s| (python-control's damp).

Frequencies are in Hz, up to the Nyquist frequency 1 / (2 h) of the scenario's step h.
"""

import json
import math
import warnings
from pathlib import Path
from typing import NamedTuple

import numpy as np
from scipy import linalg

from tapmp.laws import MODE_LABELS
from tapmp.modal import MODES

from .folders import atomic_file, write_text
from .scenario import ScenarioError
from .stability import OneStepMap, invariant_basis, verdict_for

F_SCALE = 1e-3  # [N] finite-difference step of the plant-input force (as stability's F_held)
BREAK_POINTS = ("motor 1", "motor 2", "motor 3", *MODE_LABELS)
POINTS = 400  # default number of frequencies
F_MIN = 0.1   # default lowest frequency [Hz]


def break_directions() -> dict:
    """{break point name: unit vector v in motor-force space} (module doc)."""
    eye = np.eye(3)
    out = {f"motor {i + 1}": eye[i] for i in range(3)}
    for name, (_, v) in zip(BREAK_POINTS[3:], MODES):
        out[name] = np.array(v)
    return out


class SplitLoop:
    """The linearized sampled loop split at the plant input force (module doc).

    Attributes: h [s]; A, B, C, D (scaled coordinates: the state as in
    ``stability.OneStepMap``, the force in units of F_SCALE newtons, so B and C map
    force to force); Ce: tracking error [m] per unit of scaled state; names: the states.
    """

    def __init__(self, scenario):
        m = self.map = OneStepMap(scenario, linear=True)
        self.h = m.h
        self.jacobi = m.jacobi
        x0 = m.start_state()
        _, y0 = self.step(x0, np.zeros(3), closed=True)
        self.w0 = y0  # operating point: the plant steps with the controller's force
        n = len(x0)
        A, B = np.empty((n, n)), np.empty((n, 3))
        C, D = np.empty((3, n)), np.empty((3, 3))
        for j in range(n):
            d = np.zeros(n)
            d[j] = m.scale[j]
            (xp, yp), (xm, ym) = self.step(x0 + d, y0), self.step(x0 - d, y0)
            A[:, j] = (xp - xm) / 2.0 / m.scale
            C[:, j] = (yp - ym) / 2.0 / F_SCALE
        for j in range(3):
            d = np.zeros(3)
            d[j] = F_SCALE
            (xp, yp), (xm, ym) = self.step(x0, y0 + d), self.step(x0, y0 - d)
            B[:, j] = (xp - xm) / 2.0 / m.scale
            D[:, j] = (yp - ym) / 2.0 / F_SCALE
        # tracking error e = q_d - q_true: minus the motor positions' change with the pose
        Ce = np.zeros((3, n))
        for j in range(3):
            d = np.zeros(6)
            d[j] = m.scale[j]
            m.plant.state = [float(v) for v in x0[:6] + d]
            qp = np.array(m.plant.joint_positions())
            m.plant.state = [float(v) for v in x0[:6] - d]
            qm = np.array(m.plant.joint_positions())
            Ce[:, j] = -(qp - qm) / 2.0
        T = invariant_basis(m)
        self.T, self.x0 = T, x0
        self.A, self.B, self.C, self.D = T.T @ A @ T, T.T @ B, C @ T, D
        self.Ce = Ce @ T
        self.names = m.names

    def step(self, x: np.ndarray, w: np.ndarray, closed: bool = False):
        """(state at t + h, controller force y [N]) from the state x at t with the plant stepping
        under the force w [N] (``closed``: under y itself, the loop of ``tapmp run``)."""
        return self.map.split_step(x, None if closed else w)

    def closed_loop(self) -> np.ndarray:
        """A + B C: the closed loop's one-step matrix (scaled coordinates)."""
        return self.A + self.B @ self.C

    def loop(self, v, gain: float = 1.0) -> "StateSpace":
        """-L_v as a discrete-time StateSpace (input w_v, output y_v), the loop opened in direction
        v with the other directions closed; ``gain`` scales the closed part (1 = the loop as it runs)."""
        v = np.asarray(v, dtype=float).reshape(3, 1)
        P = gain * (np.eye(3) - v @ v.T)
        A = self.A + self.B @ P @ self.C
        return StateSpace(A, self.B @ v, v.T @ self.C, v.T @ self.D @ v, self.h)

    def disturbance(self, v) -> "StateSpace":
        """The closed loop from a force d v at the plant input [N] to the tracking error v^T e [m]."""
        v = np.asarray(v, dtype=float).reshape(3, 1)
        return StateSpace(self.closed_loop(), self.B @ v / F_SCALE, v.T @ self.Ce, np.zeros((1, 1)), self.h)


class StateSpace(NamedTuple):
    """A discrete-time system x+ = A x + B u, y = C x + D u with sample time h [s]: the matrices
    python-control's StateSpace holds (``control.ss(*sys)`` makes one), without importing it, which
    alone takes about 1 s; the frequency responses here evaluate the matrices themselves."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    h: float

    def __neg__(self) -> "StateSpace":
        return StateSpace(self.A, self.B, -self.C, -self.D, self.h)


def batch_response(A, B, C, D, h: float, freqs) -> np.ndarray:
    """G(z) = C (z I - A)^-1 B + D at z = exp(j 2 pi f h) for every f of freqs [Hz] at once
    (one LU solve per frequency, stacked): an array of shape (len(freqs), outputs, inputs)."""
    A, B, C, D = (np.asarray(M, dtype=float) for M in (A, B, C, D))
    z = np.exp(1j * 2.0 * np.pi * np.asarray(freqs, dtype=float) * h)
    stack = z[:, None, None] * np.eye(A.shape[0])[None] - A[None]
    X = np.linalg.solve(stack, np.broadcast_to(B.astype(complex), (len(z), *B.shape)))
    return C[None] @ X + D[None]


def _response(sys, freqs: np.ndarray, h: float) -> np.ndarray:
    """Complex frequency response of a discrete-time SISO system at freqs [Hz] (exact evaluation
    on the unit circle)."""
    return batch_response(sys.A, sys.B, sys.C, sys.D, h, freqs)[:, 0, 0]


SEARCH_POINTS = 4000  # frequencies on which crossings are bracketed before brentq refines them


def margins(L, h: float, f_low: float = 1e-3) -> dict:
    """Gain and phase margins of the loop gain L (a discrete-time StateSpace or python-control
    system, negative feedback), from crossings bracketed on a log grid from f_low [Hz] to the Nyquist
    frequency and refined by brentq on L evaluated exactly at z = exp(j 2 pi f h).

    gm: the upper gain margin, the smallest factor > 1 at a phase crossover (L real and
    negative) that makes |L| = 1 there (inf if none); gm_lower: the largest such factor < 1
    (a loop that goes unstable when its gain drops, e.g. one holding a negative stiffness, whose
    L is negative at f = 0; None if none), gm_lower_db and its frequency f_pc_lower_hz [Hz];
    gm_db = 20 log10(gm);
    pm_deg: the phase margin 180 deg + arg L at the gain crossover |L| = 1 of smallest |PM|
    (inf if none); f_pc_hz, f_gc_hz: the frequencies of gm and pm [Hz] (None if none).
    """
    from scipy.optimize import brentq
    nyq = 0.5 / h
    if not hasattr(L, "A"):  # a transfer function: its state-space realization
        import control
        L = control.ss(L)
    A, B, C, D = (np.asarray(M, dtype=float) for M in (L.A, L.B, L.C, L.D))
    eye = np.eye(A.shape[0])

    def Lf(f):
        z = np.exp(1j * 2.0 * math.pi * f * h)
        return complex((C @ linalg.solve(z * eye - A, B))[0, 0] + D[0, 0])

    grid = np.geomspace(f_low, nyq, SEARCH_POINTS)
    grid[-1] = nyq
    vals = batch_response(A, B, C, D, h, grid)[:, 0, 0]
    pcs = []  # phase crossovers: Im L = 0 with Re L < 0
    for k in np.nonzero(np.diff(np.sign(vals.imag)))[0]:
        f = brentq(lambda x: Lf(x).imag, grid[k], grid[k + 1], xtol=1e-14, rtol=1e-15)
        if Lf(f).real < 0.0:
            pcs.append(f)
    if vals[-1].real < 0.0 and abs(vals[-1].imag) <= 1e-12 * abs(vals[-1]):
        pcs.append(nyq)  # at Nyquist the response of a real system is real
    if min(abs(linalg.eigvals(A) - 1.0), default=1.0) > 1e-9:  # no integrator: L(z = 1) is finite and real
        with warnings.catch_warnings():  # a slow pole near z = 1 makes I - A ill-conditioned, L(1) large: still right
            warnings.simplefilter("ignore", linalg.LinAlgWarning)
            dc = complex((C @ linalg.solve(eye - A, B))[0, 0] + D[0, 0])
        if dc.real < 0.0:
            pcs.append(0.0)  # L < 0 at f = 0 (a negative stiffness the loop holds): a crossover at DC
    gcs = [brentq(lambda x: abs(Lf(x)) - 1.0, grid[k], grid[k + 1], xtol=1e-14, rtol=1e-15)
           for k in np.nonzero(np.diff(np.sign(np.abs(vals) - 1.0)))[0]]
    gms = [(1.0 / abs(Lf(f) if f > 0.0 else dc), f) for f in pcs]
    upper = [g for g in gms if g[0] > 1.0]
    lower = [g for g in gms if g[0] <= 1.0]
    gm, f_pc = min(upper) if upper else (math.inf, None)
    pms = [(float(np.remainder(np.angle(Lf(f), deg=True), 360.0) - 180.0), f) for f in gcs]
    pm, f_gc = min(pms, key=lambda p: abs(p[0])) if pms else (math.inf, None)
    gm_lower, f_lower = max(lower) if lower else (None, None)
    return {"gm": gm, "gm_db": 20.0 * math.log10(gm) if gm < math.inf else math.inf,
            "gm_lower": gm_lower, "gm_lower_db": None if gm_lower is None else 20.0 * math.log10(gm_lower),
            "f_pc_lower_hz": f_lower, "pm_deg": pm, "f_pc_hz": f_pc, "f_gc_hz": f_gc}


def poles(split: SplitLoop) -> list:
    """Closed-loop poles: [{"z": [re, im], "f_n_hz": natural frequency, "zeta": damping}],
    least damped first (s = ln(z) / h, f_n = |s| / (2 pi), zeta = -Re(s) / |s|)."""
    out = []
    for z in linalg.eigvals(split.closed_loop()):
        s = np.log(complex(z)) / split.h if z != 0 else complex(-math.inf, 0.0)
        wn = abs(s)
        zeta = -s.real / wn if wn > 0 and np.isfinite(wn) else 1.0
        out.append({"z": [float(z.real), float(z.imag)], "f_n_hz": float(wn / (2.0 * math.pi)),
                    "zeta": float(zeta)})
    return sorted(out, key=lambda p: (p["zeta"], p["f_n_hz"]))


MAX_POINTS = 100_000  # frequencies: each one solves the loop at every break point (bounded work)


def frequency_grid(h: float, f_min: float = F_MIN, f_max: float | None = None, points: int = POINTS) -> np.ndarray:
    """Log-spaced frequencies [Hz] from f_min to f_max (default: the Nyquist frequency 1/(2h));
    ScenarioError names a bound outside (0, Nyquist] or fewer than 2 points."""
    nyq = 0.5 / h
    f_max = nyq if f_max is None else f_max
    for key, f in (("--f-min", f_min), ("--f-max", f_max)):
        if not (math.isfinite(f) and 0.0 < f <= nyq * (1.0 + 1e-12)):
            raise ScenarioError(f"{key} = {f!r} is invalid: allowed is a frequency in (0, {nyq:g}] Hz "
                                f"(up to the Nyquist frequency 1/(2 step), step = {h:g} s)")
    if not f_min < f_max:
        raise ScenarioError(f"--f-min = {f_min!r} is invalid: allowed is a frequency below --f-max = {f_max!r} Hz")
    if not (isinstance(points, int) and 2 <= points <= MAX_POINTS):
        raise ScenarioError(f"--points = {points!r} is invalid: allowed is an integer from 2 to {MAX_POINTS}")
    return np.geomspace(f_min, min(f_max, nyq), points)


def _bandwidth(freqs, S) -> float | None:
    """Lowest frequency [Hz] where |S| reaches 1/sqrt(2) from below (linear interpolation in
    log f); None if |S| stays below (or starts above) it on the grid."""
    mag = np.abs(S)
    level = 1.0 / math.sqrt(2.0)
    if mag[0] >= level:
        return None
    above = np.nonzero(mag >= level)[0]
    if len(above) == 0:
        return None
    k = above[0]
    lf0, lf1 = math.log(freqs[k - 1]), math.log(freqs[k])
    return float(math.exp(lf0 + (level - mag[k - 1]) / (mag[k] - mag[k - 1]) * (lf1 - lf0)))


def analyze_loop(split: SplitLoop, freqs: np.ndarray) -> dict:
    """Per break point (BREAK_POINTS): margins, Ms, Mt, bandwidth, compliance, and the
    responses L, S, T, e/d on freqs (complex arrays under "response")."""
    out = {}
    for name, v in break_directions().items():
        G = split.loop(v)           # y_v / w_v
        L = -G
        Lf = -_response(G, freqs, split.h)
        S = 1.0 / (1.0 + Lf)
        Tc = Lf / (1.0 + Lf)
        E = _response(split.disturbance(v), freqs, split.h)
        r = margins(L, split.h)
        r.update({"Ms": float(np.max(np.abs(S))), "Mt": float(np.max(np.abs(Tc))),
                  "bandwidth_hz": _bandwidth(freqs, S),
                  "compliance_peak_m_per_n": float(np.max(np.abs(E))),
                  "compliance_peak_hz": float(freqs[int(np.argmax(np.abs(E)))]),
                  "compliance_low_m_per_n": float(abs(E[0])),
                  "response": {"L": Lf, "S": S, "T": Tc, "e_per_d": E}})
        out[name] = r
    return out


def analyze_runs(runs: dict, freqs: np.ndarray, say=None) -> dict:
    """{run name: {"law", "spectral_radius", "poles", "loops"}} for the scenarios of ``runs``;
    ``say(line)``, if given, is told each run's step as it starts (seconds each on a long grid)."""
    out = {}
    say = say or (lambda line: None)
    for i, (name, sc) in enumerate(runs.items(), 1):
        split = SplitLoop(sc)
        rho = float(max(abs(linalg.eigvals(split.closed_loop()))))
        verdict = verdict_for(rho)
        say(f"analyze: run {i}/{len(runs)} {name}: the loop at {len(freqs)} frequencies per break point")
        loops = analyze_loop(split, freqs)
        every = None
        if verdict == "stable":
            say(f"analyze: run {i}/{len(runs)} {name}: disk, gain and delay margins and the actuator bandwidth")
            rob = robustness(split, freqs)
            for b, x in rob["loops"].items():
                loops[b].update(x)
            every = rob["all_loops"]
        else:
            # margins, peaks and bandwidth describe a stable loop's distance to instability; the
            # responses of an unstable loop are no steady state that any run would show
            for x in loops.values():
                x.update({k: None for k in ("gm", "gm_db", "gm_lower", "gm_lower_db", "f_pc_lower_hz", "pm_deg", "f_pc_hz", "f_gc_hz", "Ms", "Mt",
                                            "bandwidth_hz", "compliance_peak_m_per_n", "compliance_peak_hz",
                                            "compliance_low_m_per_n")})
        out[name] = {"law": sc.law, "spectral_radius": rho, "verdict": verdict, "poles": poles(split),
                     "loops": loops, "all_loops": every}
    return out


def _plain(x):
    """JSON-ready copy: complex arrays as {"re": [...], "im": [...]}, inf as the string "inf"."""
    if isinstance(x, dict):
        return {k: _plain(v) for k, v in x.items()}
    if isinstance(x, np.ndarray):
        return {"re": x.real.tolist(), "im": x.imag.tolist()}
    if isinstance(x, float) and not math.isfinite(x):
        return "inf" if x > 0 else "-inf" if x < 0 else "nan"
    if isinstance(x, list):
        return [_plain(v) for v in x]
    return x


def _fmt(x, spec=".3g") -> str:
    if x is None:
        return "-"
    if isinstance(x, float) and math.isinf(x):
        return "inf"
    return format(x, spec)


def table(result: dict, breaks=BREAK_POINTS) -> str:
    """Markdown table: one row per run and break point, margins and the other numbers."""
    lines = ["| run | break point | GM [dB] | f_pc [Hz] | lower GM [dB] | PM [deg] | f_gc [Hz] | Ms | Mt "
             "| bandwidth [Hz] | peak e/d [um/N] | low-f e/d [um/N] |", "|---" * 12 + "|"]
    for run, r in result["runs"].items():
        if r["verdict"] != "stable":
            lines.append(f"| {run} | all | the closed loop is {r['verdict']} (spectral radius {r['spectral_radius']:.4g}): "
                         "no margins |" + " |" * 10)
            continue
        for b in breaks:
            x = r["loops"][b]
            lines.append(f"| {run} | {b} | {_fmt(x['gm_db'], '.2f')} | {_fmt(x['f_pc_hz'], '.4g')} "
                         f"| {_fmt(x['gm_lower_db'], '.1f')} | {_fmt(x['pm_deg'], '.2f')} | {_fmt(x['f_gc_hz'], '.4g')} | {_fmt(x['Ms'], '.3f')} "
                         f"| {_fmt(x['Mt'], '.3f')} | {_fmt(x['bandwidth_hz'], '.4g')} "
                         f"| {_fmt(x['compliance_peak_m_per_n'] * 1e6, '.4g')} "
                         f"| {_fmt(x['compliance_low_m_per_n'] * 1e6, '.4g')} |")
    return "\n".join(lines)


def robustness_table(result: dict, breaks=BREAK_POINTS) -> str:
    """Markdown table: per run, the disk margins of each break point (alpha, as gain [dB] and phase
    [deg]) and of all three motors at once, the all-loops gain margin with the K_T error it covers,
    the smallest delay margin [ms] of one direction, the delay margin [ms] of all motors delayed at
    once and the lowest actuator bandwidth [Hz]."""
    lines = ["| run | disk margin per loop: " + ", ".join(breaks) + " | all loops: disk margin (gain dB, phase deg) "
             "| all-loops gain margin (K_T error) | " + DELAY_COLUMNS + " | lowest actuator bandwidth [Hz] |",
             "|---" * 7 + "|"]
    for run, r in result["runs"].items():
        if r["verdict"] != "stable":
            lines.append(f"| {run} | the closed loop is {r['verdict']} (spectral radius {r['spectral_radius']:.4g}) "
                         "| - | - | - | - | - |")
            continue
        lines.append("| " + " | ".join(robustness_cells(run, r, breaks)) + " |")
    return "\n".join(lines)


DELAY_COLUMNS = "delay margin [ms] (loop) | delay margin, all motors [ms]"  # the two delay cells' headers


def robustness_cells(run: str, r: dict, breaks=BREAK_POINTS) -> list[str]:
    """The cells of robustness_table for one stable run of analyze_runs."""
    a = r["all_loops"]
    kt = a["kt_error_pct"]
    low = f"{a['gm_lower']:.3g}x ({kt[0]:+.0f} %)" if a["gm_lower"] is not None else f"below {GAIN_SPAN[0]:g}x"
    up = f"{a['gm_upper']:.3g}x ({kt[1]:+.0f} %)" if a["gm_upper"] is not None else f"above {GAIN_SPAN[1]:g}x"
    delays = {b: r["loops"][b]["delay_margin_s"] for b in breaks}
    worst = min(delays, key=delays.get)
    bw = a["actuator_bandwidth_hz"]
    return [run, ", ".join(f"{r['loops'][b]['disk_margin']:.3f}" for b in breaks),
            f"{a['disk_margin']:.3f} ({_fmt(a['disk_gm_db'], '.2f')}, {a['disk_pm_deg']:.1f})",
            f"{low} to {up}",
            f"{_fmt(delays[worst] * 1e3, '.4g')} ({worst})", _fmt(a["delay_margin_all_s"] * 1e3, ".4g"),
            f"{bw:.4g}" if bw > ACTUATOR_SPAN[0] else f"below {ACTUATOR_SPAN[0]:g}"]


def pole_table(result: dict, count: int = 3) -> str:
    """Markdown table: per run the ``count`` least damped closed-loop poles (f_n, zeta)."""
    lines = ["| run | spectral radius | slowest pole: f_n [Hz] (zeta) | least damped poles: f_n [Hz] (zeta) |",
             "|---|---|---|---|"]
    for run, r in result["runs"].items():
        seen, shown = set(), []
        for p in r["poles"]:
            key = (round(p["f_n_hz"], 6), round(p["zeta"], 6))
            if key in seen:  # a conjugate pair once
                continue
            seen.add(key)
            shown.append(f"{p['f_n_hz']:.4g} ({p['zeta']:.3f})")
            if len(shown) == count:
                break
        slow = min(r["poles"], key=lambda p: p["f_n_hz"])
        lines.append(f"| {run} | {r['spectral_radius']:.6f} | {slow['f_n_hz']:.4g} ({slow['zeta']:.3f}) "
                     f"| {', '.join(shown)} |")
    return "\n".join(lines)


def write_responses(result: dict, path: Path) -> Path:
    """frequency_response.csv: the frequency [Hz], then per run, break point and response (L, S,
    T dimensionless; e_per_d in m/N) its magnitude and phase [deg], one row per frequency."""
    import csv
    cols, data = ["frequency_hz"], [np.asarray(result["frequencies_hz"])]
    for run, r in result["runs"].items():
        for b, x in r["loops"].items():
            for key, H in x["response"].items():
                cols += [f"{run}|{b}|{key}|mag", f"{run}|{b}|{key}|phase_deg"]
                data += [np.abs(H), np.angle(H, deg=True)]
    with atomic_file(path) as f:  # under a temporary name, then renamed; a link there is refused
        w = csv.writer(f)
        w.writerow(cols)
        w.writerows(np.column_stack(data).tolist())
    return path


def analyze(scenario, out: Path | None = None, f_min: float = F_MIN, f_max: float | None = None,
            points: int = POINTS, runs: dict | None = None, figures: bool = True,
            responses: bool = False, say=None) -> dict:
    """Analyze the sampled loops of ``runs`` ({name: Scenario}; `tapmp analyze` passes SC-DC and the
    baselines of `tapmp compare`, None: the scenario alone under its own law) at the scenario's step.

    Returns {"scenario", "h", "nyquist_hz", "frequencies_hz", "runs"} (each break point's complex
    responses under "response"); with ``out`` writes out/analysis.json (everything but the
    responses), the Bode figures (``figures``) and frequency_response.csv (``responses``),
    listed under "files". ``say(line)``: progress, a line as each run's step starts.
    """
    freqs = frequency_grid(scenario.step, f_min, f_max, points)
    runs = {scenario.law: scenario} if runs is None else runs
    result = {"scenario": scenario.name, "h": scenario.step, "nyquist_hz": 0.5 / scenario.step,
              "ordering": scenario.ordering, "break": "plant input force, one direction at a time, the others "
              "closed; L = -y_v / w_v (negative feedback)",
              "frequencies_hz": freqs, "runs": analyze_runs(runs, freqs, say)}
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        files = []
        if figures:
            from .analysis_plots import plot_analysis
            if say:
                say(f"analyze: the figures -> {out}")
            files = [str(p) for p in plot_analysis(result, out)]
        if responses:
            files.append(str(write_responses(result, out / "frequency_response.csv")))
        result["files"] = files
        data = {k: v for k, v in result.items() if k != "frequencies_hz"}
        data["frequency_grid"] = {"from_hz": float(freqs[0]), "to_hz": float(freqs[-1]), "points": len(freqs),
                                  "spacing": "logarithmic"}
        data["runs"] = {run: {**r, "loops": {b: {k: v for k, v in x.items() if k != "response"}
                                             for b, x in r["loops"].items()}} for run, r in result["runs"].items()}
        write_text(out / "analysis.json", json.dumps(_plain(data), indent=1) + "\n")
    return result


# Robustness beyond one loop's Ms: disk margins, the all-loops gain margin, delay margins and the
# slowest actuator the loop tolerates. Every measure is taken on the split loop above (the loop of
# `tapmp check`); a measure that inserts something into the loop (a delay, an actuator lag, a gain
# on all three forces) reads the spectral radius of the loop with it inserted.

GAIN_SPAN = (0.01, 100.0)  # all-loops gain factors searched: a K_T from 1 % to 100 x the model's
DELAY_SAMPLES = 200        # delays searched: up to this many steps h
ACTUATOR_SPAN = (0.1, 1e3)  # actuator bandwidths searched [Hz]: from 0.1 Hz to 1000 x the Nyquist frequency


def disk_gain_phase(alpha: float) -> dict:
    """The symmetric (skew 0) disk margin alpha as the gain and phase variations it covers (Seiler,
    Packard and Gahinet, An introduction to disk margins, IEEE Control Systems 40(5), 2020, Eq. 9-10):
    any gain in [(2 - alpha)/(2 + alpha), (2 + alpha)/(2 - alpha)] or phase within +-2 atan(alpha/2),
    applied to every perturbed loop at once, keeps the loop stable. Gains as factors and dB, phase in deg."""
    up = (2.0 + alpha) / (2.0 - alpha) if alpha < 2.0 else math.inf
    return {"disk_margin": alpha, "disk_gm": up, "disk_gm_db": 20.0 * math.log10(up) if up < math.inf else math.inf,
            "disk_gm_lower": 1.0 / up, "disk_pm_deg": math.degrees(2.0 * math.atan(alpha / 2.0))}


def frequency_matrix(A, B, C, D, h: float, f: float) -> np.ndarray:
    """G(z) = C (z I - A)^-1 B + D at z = exp(j 2 pi f h) (f [Hz], h [s])."""
    z = np.exp(1j * 2.0 * math.pi * f * h)
    return C @ linalg.solve(z * np.eye(A.shape[0]) - A, B) + D


def _mu_diagonal(M: np.ndarray, d0=None):
    """(mu, log-scaling) of M for a diagonal complex perturbation, one scalar per channel: the
    D-scaled upper bound min_D sigma_max(D M D^-1), which equals mu for up to three channels
    (Packard and Doyle, The complex structured singular value, Automatica 29(1), 1993, Sec. 9)."""
    from scipy.optimize import minimize
    n = M.shape[0]
    if n == 1:
        return float(abs(M[0, 0])), None

    def sigma(d):
        e = np.exp(np.concatenate([d, [0.0]]))
        return float(np.linalg.norm((e[:, None] * M) / e[None, :], 2))

    x0 = np.zeros(n - 1) if d0 is None else d0
    r = minimize(sigma, x0, method="Nelder-Mead", options={"xatol": 1e-10, "fatol": 1e-13, "maxiter": 4000})
    best = min(sigma(x0), float(r.fun))
    return best, (r.x if r.fun <= sigma(x0) else x0)


def disk_margin(A, B, C, D, h: float, freqs: np.ndarray) -> dict:
    """Symmetric disk margin of the discrete loop G = C (zI - A)^-1 B + D closed by w = y
    (L = -G, negative feedback) with one independent complex perturbation per channel:
    alpha = 1 / max_f mu(S - I/2), S = (I + L)^-1 (Seiler et al. 2020, skew 0; for one channel
    1 / max |S - 1/2|). The peak is bracketed on ``freqs`` [Hz] (the Nyquist frequency added) and
    refined between its neighbours. Returns disk_gain_phase(alpha) plus "disk_f_hz", the
    frequency of the peak."""
    from scipy.optimize import minimize_scalar
    nyq = 0.5 / h
    grid = np.unique(np.append(np.asarray(freqs, dtype=float), nyq))
    n = B.shape[1]
    eye = np.eye(n)

    def M(f):
        G = frequency_matrix(A, B, C, D, h, f)
        return linalg.inv(eye - G) - 0.5 * eye

    Ms = np.linalg.inv(eye[None] - batch_response(A, B, C, D, h, grid)) - 0.5 * eye[None]
    sig = np.linalg.norm(Ms, 2, axis=(1, 2))
    lower = np.array([np.max(np.abs(np.diag(m))) for m in Ms])  # mu >= each channel's own |M_ii|
    best, k_best, d_best = -1.0, 0, None
    for k in np.argsort(-sig):  # an upper bound below the best mu so far cannot hold the peak
        if sig[k] <= best:
            break
        if lower[k] > sig[k] * (1.0 - 1e-12):
            mu, d = float(sig[k]), d_best
        else:
            mu, d = _mu_diagonal(Ms[k], d_best)
        if mu > best:
            best, k_best, d_best = mu, k, d
    lo, hi = grid[max(k_best - 1, 0)], grid[min(k_best + 1, len(grid) - 1)]
    if hi > lo:
        r = minimize_scalar(lambda lf: -_mu_diagonal(M(math.exp(lf)), d_best)[0],
                            bounds=(math.log(lo), math.log(hi)), method="bounded", options={"xatol": 1e-9})
        if -r.fun > best:
            best, f_peak = float(-r.fun), math.exp(r.x)
        else:
            f_peak = grid[k_best]
    else:
        f_peak = grid[k_best]
    return {**disk_gain_phase(1.0 / best), "disk_f_hz": float(f_peak)}


def _radius(M: np.ndarray) -> float:
    return float(max(abs(linalg.eigvals(M))))


def _first_crossing(rho, values, rtol: float = 1e-7):
    """The first value of the monotone sequence ``values`` at which rho(value) >= 1 after the loop
    was stable (rho < 1) at the one before, refined by bisection to rtol; None if rho stays < 1."""
    prev = values[0]
    for v in values[1:]:
        if rho(v) >= 1.0:
            a, b = prev, v  # stable at a, not at b
            while abs(b - a) > rtol * abs(b):
                mid = 0.5 * (a + b)
                a, b = (mid, b) if rho(mid) < 1.0 else (a, mid)
            return 0.5 * (a + b)
        prev = v
    return None


def all_loops_gain_margin(split: SplitLoop) -> dict:
    """The gain margin with all three plant-input forces scaled by one factor k, the closed loop
    A + k B C (what a motor constant K_T k times the model's does to the feedback, since F = u / K_T
    scales the feedback, not the feedforward): gm_upper, the smallest k > 1 and gm_lower, the largest
    k < 1 at which the spectral radius reaches 1, searched in GAIN_SPAN (None: none there); with
    kt_error_pct the K_T errors (k - 1) 100 % between which the loop stays stable."""
    A, BC = split.A, split.B @ split.C

    def rho(k):
        return _radius(A + k * BC)

    if rho(1.0) >= 1.0:
        return {"gm_upper": None, "gm_lower": None, "kt_error_pct": None}
    ups = [1.0] + list(np.geomspace(1.02, GAIN_SPAN[1], 240))
    downs = [1.0] + list(np.geomspace(1.0 / 1.02, GAIN_SPAN[0], 240))
    up, low = _first_crossing(rho, ups), _first_crossing(rho, downs)
    return {"gm_upper": up, "gm_upper_db": None if up is None else 20.0 * math.log10(up),
            "gm_lower": low, "gm_lower_db": None if low is None else 20.0 * math.log10(low),
            "kt_error_pct": [None if low is None else 100.0 * (low - 1.0), None if up is None else 100.0 * (up - 1.0)]}


def plant_rates(split: SplitLoop):
    """(Ac, Bc): the continuous-time plant d x_p/dt = Ac x_p + Bc w linearized at the loop's start
    (central differences of tapmp.plant.PlantModel.derivatives), embedded in the split loop's
    coordinates: Ac acts on the plant rows of a full loop state, both scaled as SplitLoop's A and B."""
    m = split.map
    s0, w0 = split.x0[:6], split.w0
    sc = m.scale[:6]
    Ac, Bc = np.empty((6, 6)), np.empty((6, 3))
    for j in range(6):
        d = np.zeros(6)
        d[j] = sc[j]
        Ac[:, j] = (np.array(m.plant.derivatives(s0 + d, *w0)) - np.array(m.plant.derivatives(s0 - d, *w0))) / 2.0 / sc
    for j in range(3):
        d = np.zeros(3)
        d[j] = F_SCALE
        Bc[:, j] = (np.array(m.plant.derivatives(s0, *(w0 + d))) - np.array(m.plant.derivatives(s0, *(w0 - d)))) / 2.0 / sc
    return Ac, Bc


def _input_response(split: SplitLoop, Ac, Bc, duration: float, after: float, decay: float = 0.0) -> np.ndarray:
    """The plant's state at the end of a step (split loop coordinates, n x 3) from a unit force per
    channel applied for ``duration`` [s] with weight exp(-decay t), then ``after`` [s] unforced.
    Kept per split loop: the delay search asks for the same fractions of a step in every direction."""
    key = (duration, after, decay, Ac.tobytes(), Bc.tobytes())
    cache = split.__dict__.setdefault("_responses", {})
    if key not in cache:
        cache[key] = _response_of(split, Ac, Bc, duration, after, decay)
    return cache[key]


def _response_of(split: SplitLoop, Ac, Bc, duration: float, after: float, decay: float) -> np.ndarray:
    n6 = Ac.shape[0]
    big = np.zeros((n6 + 3, n6 + 3))
    big[:n6, :n6], big[:n6, n6:] = Ac, Bc
    big[n6:, n6:] = -decay * np.eye(3)
    x = linalg.expm(big * duration)[:n6, n6:]
    if after > 0.0:
        x = linalg.expm(Ac * after) @ x
    full = np.zeros((split.T.shape[0], 3))
    full[:n6] = x
    return split.T.T @ full


def delayed_loop(split: SplitLoop, v, delay: float, rates=None) -> np.ndarray:
    """The one-step matrix of the split loop with the force in direction v delayed by ``delay`` [s]
    = (m + phi) h: during a step the plant gets the command of m + 1 samples before for the first
    phi h, then that of m samples before (the other directions as they run). v: a unit vector, or
    a 3 x k matrix of orthonormal directions delayed alike (the identity: every motor). State: the
    loop's, then V^T y of the last m + 1 samples."""
    Ac, Bc = plant_rates(split) if rates is None else rates
    h = split.h
    m = int(math.floor(delay / h + 1e-12))
    phi = delay / h - m
    V = np.asarray(v, dtype=float).reshape(3, -1)
    k = V.shape[1]
    A, B, C = split.A, split.B, split.C
    N = A.shape[0]
    c = V.T @ C
    Bv = B @ V
    Gv = _input_response(split, Ac, Bc, phi * h, (1.0 - phi) * h) @ V if phi > 0.0 else np.zeros((N, k))
    M = np.zeros((N + (m + 1) * k, N + (m + 1) * k))
    M[:N, :N] = A + B @ (np.eye(3) - V @ V.T) @ C

    def reg(j):  # the columns of register j (V^T y of j + 1 samples before)
        return slice(N + j * k, N + (j + 1) * k)

    if m == 0:
        M[:N, :N] += (Bv - Gv) @ c
    else:
        M[:N, reg(m - 1)] += Bv - Gv
    M[:N, reg(m)] += Gv
    M[reg(0), :N] = c
    for j in range(1, m + 1):
        M[reg(j), reg(j - 1)] = np.eye(k)
    return M


def delay_margin(split: SplitLoop, v, rates=None) -> float | None:
    """The smallest delay [s] of the force in direction v at which the loop (delayed_loop) reaches a
    spectral radius of 1, searched in steps of h/4 up to DELAY_SAMPLES steps and refined by
    bisection; None if the loop is not stable without delay, inf if none within the search."""
    rates = plant_rates(split) if rates is None else rates
    if _radius(split.closed_loop()) >= 1.0:
        return None
    found = _first_crossing(lambda d: _radius(delayed_loop(split, v, d, rates)),
                            list(np.arange(0, 4 * DELAY_SAMPLES + 1) * split.h / 4.0), rtol=1e-6)
    return math.inf if found is None else found


def actuator_loop(split: SplitLoop, bandwidth_hz: float, rates=None) -> np.ndarray:
    """The one-step matrix of the split loop with a first-order actuator 1 / (s / (2 pi f_a) + 1) on
    each motor between the controller's force and the plant (f_a = bandwidth_hz [Hz]), integrated
    exactly over the step. State: the loop's, then the three actuator forces."""
    Ac, Bc = plant_rates(split) if rates is None else rates
    A, B, C = split.A, split.B, split.C
    N = A.shape[0]
    decay = 2.0 * math.pi * bandwidth_hz
    e = math.exp(-decay * split.h)
    Ge = _input_response(split, Ac, Bc, split.h, 0.0, decay)
    M = np.zeros((N + 3, N + 3))
    M[:N, :N] = A + (B - Ge) @ C
    M[:N, N:] = Ge
    M[N:, :N] = (1.0 - e) * C
    M[N:, N:] = e * np.eye(3)
    return M


def actuator_bandwidth(split: SplitLoop, rates=None) -> float | None:
    """The lowest actuator bandwidth [Hz] (actuator_loop, every motor) above which the loop stays
    stable: searched downward from ACTUATOR_SPAN's top (x the Nyquist frequency) in steps of 25 %
    and refined by bisection; ACTUATOR_SPAN[0] if stable down to it, None if the loop is not
    stable without the actuator."""
    rates = plant_rates(split) if rates is None else rates
    if _radius(split.closed_loop()) >= 1.0:
        return None
    top = ACTUATOR_SPAN[1] * 0.5 / split.h
    f = _first_crossing(lambda b: _radius(actuator_loop(split, b, rates)),
                        list(np.geomspace(top, ACTUATOR_SPAN[0], int(math.log(top / ACTUATOR_SPAN[0]) / math.log(1.25)))),
                        rtol=1e-6)
    return ACTUATOR_SPAN[0] if f is None else f


def inserted_radius(scenario, delay: float = 0.0, actuator_hz: float | None = None) -> dict:
    """The spectral radius of the scenario's sampled loop with ``delay`` [s] on every motor's force
    (delayed_loop) and, separately, with a first-order actuator of ``actuator_hz`` [Hz] on every
    motor (actuator_loop): {"delay": rho or None, "actuator": rho or None} (None: not asked)."""
    split = SplitLoop(scenario)
    rates = plant_rates(split)
    return {"delay": _radius(delayed_loop(split, np.eye(3), delay, rates)) if delay > 0.0 else None,
            "actuator": _radius(actuator_loop(split, actuator_hz, rates)) if actuator_hz is not None else None}


def robustness(split: SplitLoop, freqs: np.ndarray) -> dict:
    """The robustness measures of a stable split loop: per break point the disk margin (disk_margin of
    the loop opened in that direction) and the delay margin [s]; for all three motors at once the disk
    margin, the gain margin (all_loops_gain_margin), the delay margin [s] of one delay on every motor's
    force (a shared computation delay: "delay_margin_all_s") and the lowest actuator bandwidth [Hz]."""
    rates = plant_rates(split)
    loops = {}
    for name, v in break_directions().items():
        G = split.loop(v)
        A, B, C, D = (np.asarray(M, dtype=float) for M in (G.A, G.B, G.C, G.D))
        loops[name] = {**disk_margin(A, B, C, D, split.h, freqs), "delay_margin_s": delay_margin(split, v, rates)}
    every = {**disk_margin(split.A, split.B, split.C, split.D, split.h, freqs), **all_loops_gain_margin(split),
             "delay_margin_all_s": delay_margin(split, np.eye(3), rates),
             "actuator_bandwidth_hz": actuator_bandwidth(split, rates)}
    return {"loops": loops, "all_loops": every}
