"""Figures of `tapmp frf` (matplotlib, PNG): per run, the measured points of the loop gain L of each
break point (Bode magnitude and phase, and the Nyquist plot near -1) beside the analytic curve of
the linearized loop where there is one (orchestrator.tool.frf)."""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .folders import save_figure  # noqa: E402

CURVE_POINTS = 400  # frequencies of an analytic curve


def _phase(L):
    """arg L [deg] unwrapped along f, starting in (-360, 0]."""
    ph = np.degrees(np.unwrap(np.angle(L)))
    return ph - 360.0 * np.ceil(ph[0] / 360.0)


def _wrapped(L):
    """arg L [deg] of each measured point in (-360, 0]: scattered points are not unwrapped (one noisy
    point would shift every later one by a turn)."""
    ph = np.angle(L, deg=True)
    return ph - 360.0 * np.ceil(ph / 360.0)


def plot_run(run: str, r: dict, path: Path, analytic_L=None) -> Path:
    """One run's figure: |L| [dB], arg L [deg] over f [Hz] and L in the complex plane near -1, every
    break point in its own colour, the measured points as markers and the analytic curve as a line
    (``analytic_L``: {break point: callable of f [Hz] -> L}, or None)."""
    fig, (mag, pha, nyq) = plt.subplots(1, 3, figsize=(15, 4.8))
    colors = plt.get_cmap("tab10").colors
    for k, (b, x) in enumerate(r["loops"].items()):
        c = colors[k % 10]
        f, L = x["f_hz"], x["L"]
        if analytic_L and b in analytic_L:
            fa = np.geomspace(f[0], f[-1], CURVE_POINTS)
            La = analytic_L[b](fa)
            mag.semilogx(fa, 20.0 * np.log10(np.abs(La)), color=c, lw=1.0)
            pha.semilogx(fa, _phase(La), color=c, lw=1.0)
            nyq.plot(La.real, La.imag, color=c, lw=1.0)
        mag.semilogx(f, 20.0 * np.log10(np.abs(L)), "o", color=c, ms=3.5, label=b)
        pha.semilogx(f, _wrapped(L), "o", color=c, ms=3.5)
        nyq.plot(L.real, L.imag, "o", color=c, ms=3.5)
    t = np.linspace(0.0, 2.0 * np.pi, 200)
    nyq.plot(np.cos(t), np.sin(t), color="0.6", lw=0.6)
    nyq.plot([-1.0], [0.0], "k+", ms=10)
    nyq.set_xlim(-3.0, 1.5)
    nyq.set_ylim(-2.5, 2.0)
    nyq.set_aspect("equal")
    mag.axhline(0.0, color="0.6", lw=0.6)
    pha.axhline(-180.0, color="0.6", lw=0.6)
    mag.set(xlabel="f [Hz]", ylabel="|L| [dB]")
    pha.set(xlabel="f [Hz]", ylabel="arg L [deg]")
    nyq.set(xlabel="Re L", ylabel="Im L")
    for ax in (mag, pha, nyq):
        ax.grid(True, which="both", lw=0.3)
    mag.legend(fontsize=8)
    what = "markers: measured in the co-simulation" + ("; lines: the linearized loop" if analytic_L else "")
    fig.suptitle(f"{run} ({r['law']}): loop gain L at the plant input force, {what}", fontsize=10)
    fig.tight_layout(rect=(0, 0, 1, 0.94))
    try:
        save_figure(fig, path, dpi=110)
    finally:
        plt.close(fig)
    return path


def plot_frf(result: dict, paths: list, analytic: dict | None = None) -> list[Path]:
    """A figure per run of ``result`` at ``paths`` (one each, in the runs' order); ``analytic``:
    {run: {break point: callable L(f)}}."""
    analytic = analytic or {}
    return [plot_run(run, r, Path(path), analytic.get(run)) for (run, r), path in zip(result["runs"].items(), paths)]
