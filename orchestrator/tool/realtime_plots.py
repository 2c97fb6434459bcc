"""The figure of a paced run (`tapmp run --real-time`), real_time.png beside its other files: the
histogram of the steps' lateness (completion minus deadline) as the core binned it, and the worst
lateness per window of steps over simulated time, both from run.json's "real_time" record."""

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from .folders import save_figure  # noqa: E402


def plot_real_time(rt: dict, path, start_time: float = 0.0) -> None:
    """Draw ``rt`` (run.json's "real_time": histogram, lateness_window, factor, period) into ``path``.
    Times in microseconds; the deadline is at 0, overruns right of it (histogram) and above it
    (over time). ``start_time`` [s]: the simulated time of the run's first step."""
    fig, (hist, over) = plt.subplots(1, 2, figsize=(12, 4.2))
    try:
        bins = rt["histogram"]["lateness"]
        if bins:
            lo = [b[0] * 1e6 for b in bins]
            width = [(b[1] - b[0]) * 1e6 or 1e-3 for b in bins]
            hist.bar(lo, [b[2] for b in bins], width=width, align="edge", color="tab:blue")
        hist.axvline(0.0, color="tab:red", lw=1, label="deadline")
        hist.set_yscale("log")
        hist.set_xlabel("lateness [us] (completion - deadline; > 0: overrun)")
        hist.set_ylabel("steps")
        late = rt["lateness_s"]
        if late["p50"] is not None:
            hist.set_title(f"p50 {late['p50'] * 1e6:.1f} us, p99 {late['p99'] * 1e6:.1f} us, "
                           f"max {late['max'] * 1e6:.1f} us; {rt['overruns']} overruns", fontsize=10)
        hist.legend(loc="upper right")
        win = rt["lateness_window"]
        h = rt["period_s"] * rt["factor"]
        t = [start_time + (i + 1) * win["steps"] * h for i in range(len(win["worst_s"]))]
        over.plot(t, [v * 1e6 for v in win["worst_s"]], lw=0.8, color="tab:blue",
                  label=f"worst of each {win['steps']} steps")
        over.axhline(0.0, color="tab:red", lw=1, label="deadline")
        over.set_xlabel("simulated time [s]")
        over.set_ylabel("lateness [us]")
        over.set_title(f"factor {rt['factor']:g} (period {rt['period_s'] * 1e6:g} us), overrun policy "
                       f"{rt['overrun_policy']}, achieved {rt['achieved_factor'] or 0:.3g}", fontsize=10)
        over.legend(loc="upper right")
        fig.tight_layout()
        save_figure(fig, path, dpi=110)
    finally:
        plt.close(fig)
