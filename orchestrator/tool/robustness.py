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
from tapmp.laws import MODE_LABELS as MODES

from ..errors import UsageError
from . import analysis
from .scenario import model_tuple

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


# The margins of one scenario's sampled loop, the measures a worst case is taken over
# (orchestrator.studies.worst_case).

MEASURES = ("Ms", "gm_upper", "gm_lower", "disk_margin", "delay_margin_all_s")


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
