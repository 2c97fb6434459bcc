"""Figures of `tapmp analyze` (matplotlib, PNG): Bode plots of the loop gain with the margins
marked, |S| and |T|, and the disturbance sensitivity (force to error), with SC-DC and the
baselines of `tapmp compare` on one figure (orchestrator.tool.analysis)."""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from tapmp.laws import MODE_LABELS as MODES  # noqa: E402

from .folders import save_figure  # noqa: E402
from .plots import PROPOSED, label  # noqa: E402

MOTORS = ("motor 1", "motor 2", "motor 3")
_STYLE = ("-", "--", "-.", ":")


def _db(x):
    return 20.0 * np.log10(np.maximum(np.abs(x), 1e-300))


def _phase(f, L, f_ref):
    """arg L [deg], unwrapped along f and shifted by whole turns so that it lies in (-360, 0] at
    f_ref (the gain crossover; the highest frequency if None), where the phase margin is read."""
    ph = np.degrees(np.unwrap(np.angle(L)))
    k = len(f) - 1 if f_ref is None else int(np.argmin(np.abs(np.log(f / f_ref))))
    return ph - 360.0 * np.ceil(ph[k] / 360.0)


def _legend(fig, axes):
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=3, fontsize=8, frameon=False)


def _save(fig, axes, title, path):
    """``fig`` with the title ``title`` and the legend of its first panel below the panels, written
    to ``path`` (PNG) and closed; returns ``path``."""
    fig.suptitle(title, fontsize=10)
    _legend(fig, axes)
    fig.tight_layout(rect=(0, 0.08, 1, 0.95))
    try:
        save_figure(fig, path, dpi=110)  # under a temporary name, then renamed; a link there is refused
    finally:
        plt.close(fig)
    return path


def _lines(result):
    """(run name, label, color, linestyle) per run with a stable closed loop (an unstable one has
    no steady-state response to draw), SC-DC first and drawn thickest."""
    colors = plt.get_cmap("tab10").colors
    return [(name, label(name, r["law"]), colors[k % 10], _STYLE[k // 10 % 4])
            for k, (name, r) in enumerate(result["runs"].items()) if r["verdict"] == "stable"]


def _bode(result, breaks, title, path):
    f = np.asarray(result["frequencies_hz"])
    fig, axes = plt.subplots(2, 3, figsize=(14, 8.5), sharex=True)
    for col, b in enumerate(breaks):
        mag, ph = axes[0, col], axes[1, col]
        for name, lab, color, ls in _lines(result):
            x = result["runs"][name]["loops"][b]
            L = x["response"]["L"]
            lw = 2.0 if name == PROPOSED else 1.0
            mag.semilogx(f, _db(L), ls, color=color, lw=lw, label=lab)
            ph.semilogx(f, _phase(f, L, x["f_gc_hz"]), ls, color=color, lw=lw)
            if x["f_pc_hz"] is not None:  # gain margin: from |L| up to 0 dB at the phase crossover
                g = -x["gm_db"]
                mag.plot([x["f_pc_hz"]] * 2, [g, 0.0], color=color, lw=1.5)
                mag.plot(x["f_pc_hz"], g, "v", color=color, ms=5)
            if x["f_gc_hz"] is not None:  # phase margin: from -180 deg up to arg L at the gain crossover
                ph.plot([x["f_gc_hz"]] * 2, [-180.0, -180.0 + x["pm_deg"]], color=color, lw=1.5)
                ph.plot(x["f_gc_hz"], -180.0 + x["pm_deg"], "^", color=color, ms=5)
        mag.axhline(0.0, color="k", lw=0.6)
        ph.axhline(-180.0, color="k", lw=0.6)
        mag.set_title(f"break at the plant input: {b}", fontsize=10)
        mag.set_ylabel("|L| [dB]")
        ph.set_ylabel("arg L [deg]")
        ph.set_xlabel("frequency [Hz]")
        ph.set_ylim(-360.0, 0.0)
        mag.set_ylim(-60.0, 80.0)
        for a in (mag, ph):
            a.grid(True, which="both", lw=0.3)
    return _save(fig, axes, f"{title} ({result['scenario']}, h = {result['h']:g} s; bars: gain margin at the "
                 "phase crossover, phase margin at the gain crossover)", path)


def _sensitivity(result, path):
    f = np.asarray(result["frequencies_hz"])
    fig, axes = plt.subplots(2, 3, figsize=(14, 8.5), sharex=True)
    for col, b in enumerate(MODES):
        for row, key in enumerate(("S", "T")):
            a = axes[row, col]
            for name, lab, color, ls in _lines(result):
                x = result["runs"][name]["loops"][b]
                a.semilogx(f, _db(x["response"][key]), ls, color=color, lw=2.0 if name == PROPOSED else 1.0,
                           label=lab)
            a.axhline(0.0, color="k", lw=0.6)
            a.axhline(-3.01, color="k", lw=0.4, ls=":")
            a.set_ylabel(f"|{key}| [dB]")
            a.set_ylim(-80.0 if key == "S" else -60.0, 15.0)
            a.grid(True, which="both", lw=0.3)
            if row == 0:
                a.set_title(f"{b}: sensitivity S = 1/(1+L)", fontsize=10)
            else:
                a.set_title(f"{b}: complementary sensitivity T = L/(1+L)", fontsize=10)
                a.set_xlabel("frequency [Hz]")
    return _save(fig, axes, f"Sensitivity at the plant input per mode ({result['scenario']}; dotted: -3 dB)", path)


def _disturbance(result, path):
    f = np.asarray(result["frequencies_hz"])
    fig, axes = plt.subplots(2, 3, figsize=(14, 8.5), sharex=True)
    for row, breaks in enumerate((MODES, MOTORS)):
        for col, b in enumerate(breaks):
            a = axes[row, col]
            for name, lab, color, ls in _lines(result):
                E = result["runs"][name]["loops"][b]["response"]["e_per_d"]
                a.loglog(f, np.abs(E) * 1e6, ls, color=color, lw=2.0 if name == PROPOSED else 1.0, label=lab)
            a.set_title(f"{b}: force at the plant input to tracking error", fontsize=10)
            a.set_ylabel("|e / d| [µm/N]")
            a.grid(True, which="both", lw=0.3)
            if row == 1:
                a.set_xlabel("frequency [Hz]")
    return _save(fig, axes, f"Disturbance sensitivity (compliance) per mode and per motor ({result['scenario']})",
                 path)


def plot_analysis(result: dict, out: Path) -> list[Path]:
    """Write the figures of an analysis result into ``out``; returns their paths."""
    out = Path(out)
    return [_bode(result, MODES, "Loop gain per mode", out / "analysis_loop_modes.png"),
            _bode(result, MOTORS, "Loop gain per motor", out / "analysis_loop_motors.png"),
            _sensitivity(result, out / "analysis_sensitivity_modes.png"),
            _disturbance(result, out / "analysis_disturbance.png")]
