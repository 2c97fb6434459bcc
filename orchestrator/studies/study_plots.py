"""Figures of studies: MAE against swept parameters, robustness histograms, tuning progress.

All errors in micrometres (µm); a swept key is labelled with its quantity and unit (from the
model interface, tapmp/interface.py). Written as PNG with matplotlib's Agg backend.
"""

import textwrap
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402
import numpy as np  # noqa: E402

from ..tool.folders import save_figure, write_text  # noqa: E402
from .study import PENALTY_UM, STUDY_CSV, case_value, read_study_csv  # noqa: E402

_MAE = (("tracking_mae_um_mean", "tracking MAE (mean of q1-q3) [µm]"),
        ("sync_mae_um_mean", "synchronization MAE (mean of q1-q3) [µm]"))

_TOP_KEYS = {"stop_time": ("stop time", "s"), "start_time": ("start time", "s"), "step": ("communication step", "s"),
             "record_every": ("recorded every", "steps")}


def _short(text: str, width: int = 38) -> str:
    """The first clause of a description, cut at a word boundary to ``width`` characters."""
    text = text.split(";")[0].split(",")[0].split(" (")[0].strip()
    if len(text) <= width:
        return text
    return text[:width].rsplit(" ", 1)[0] + " ..."


def key_label(key: str) -> str:
    """Axis label of a swept scenario key: its quantity and unit, e.g. "gain_overrides.D" ->
    "D, error-filter gain (all motors) [1/s]", "plant.k_pull" -> "k_pull, mutual pulling
    stiffness ... [N/m]"; the unit from tapmp/interface.py ("-" for a number without unit)."""
    from tapmp.interface import ELEMENT, VARIABLES
    from tapmp.settings import GAIN_NAMES, SETTING
    head, _, name = key.partition(".")
    if not name:
        if key in _TOP_KEYS:
            what, unit = _TOP_KEYS[key]
            return f"{what} [{unit}]"
        return f"{key} [-]"
    if head == "gain_overrides":
        base = name.rstrip("123") if name not in GAIN_NAMES else name
        if base in GAIN_NAMES:
            motor = name[len(base):]
            where = f"motor {motor}" if motor else "all motors"
            return f"{SETTING[base].label} ({where}) [{SETTING[base].unit or '-'}]"
        head = "controller"
    for fmu, element in ELEMENT.items():
        if element == head:
            for v in VARIABLES[fmu]:
                if v.name == name:
                    return f"{name}, {_short(v.description)} [{v.unit or '-'}]"
    return f"{key} [-]"


def _numeric(values) -> bool:
    return all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values)


def plot_study(out: Path, study, params: list) -> list:
    """Figures of a grid / Monte Carlo study from its study.csv, and a Monte Carlo study's
    summary.md (monte_carlo_summary); returns the paths written."""
    paths = []
    for path, fig in study_figures(out, study).items():
        try:
            save_figure(fig, path, dpi=110)
        finally:
            plt.close(fig)
        paths.append(path)
    text = monte_carlo_summary(out, study)
    if text:
        paths.append(write_text(Path(out) / SUMMARY_MD, text))
    return paths


SUMMARY_MD = "summary.md"


def monte_carlo_summary(out: Path, study) -> str:
    """Markdown table of a Monte Carlo study from out/study.csv, one row per grid point (e.g. per
    law or baseline): cases completed of cases, and the median / 90th percentile / maximum over
    the samples of the mean tracking and synchronization MAE [um]; "" for a study without samples."""
    if not study.samples:
        return ""
    # in case order (study.csv has them in the order they finished): within a grid point, sample i is row i
    rows = sorted((r for r in read_study_csv(Path(out) / STUDY_CSV) if r["case"].startswith("c")),
                  key=lambda r: r["case"])
    group_keys = list(study.grid)
    groups = {}
    for r in rows:
        groups.setdefault(tuple(str(r[k]) for k in group_keys), []).append(r)
    lines = [f"# {study.name}: {study.samples} samples (seed {study.seed}) of "
             + ", ".join(f.name for f in study.factors), "",
             f"| {', '.join(group_keys) or 'cases'} | cases completed | tracking MAE, median / 90th pct / max [um] "
             "| sync MAE, median / 90th pct / max [um] |", "|---|---|---|---|"]
    for g, rs in groups.items():
        done = [r for r in rs if r["status"] == "completed" and all(isinstance(r.get(k), float) for k, _ in _MAE)]
        cells = []
        for key, _ in _MAE:
            d = np.array([r[key] for r in done])
            cells.append(" / ".join(f"{v:.3f}" for v in (np.median(d), np.percentile(d, 90), d.max()))
                         if len(d) else "none completed")
        lines.append(f"| {', '.join(g) or 'all'} | {len(done)} / {len(rs)} | {cells[0]} | {cells[1]} |")
    if len(groups) > 1:
        lines += ["", *_paired_lines(groups, group_keys, study.samples)]
    return "\n".join(lines) + "\n"


def _paired_lines(groups: dict, group_keys: list, samples: int) -> list[str]:
    """Markdown: the first grid point against each other one, sample by sample (the same sampled
    plant: the cases of a grid point are its samples in draw order): in how many samples its mean
    MAE is the smaller, and the median of its reduction 100 (other - first) / other [%]."""
    (first, base), *others = groups.items()
    name = ", ".join(first)
    lines = [f"Sample by sample (the same sampled plant), `{name}` against each other row: in how many samples "
             f"its mean MAE is the smaller, and the median of its reduction 100 (other - {name}) / other over the "
             "samples where both completed.", "",
             f"| {', '.join(group_keys)} | tracking: {name} smaller in | tracking: median reduction [%] "
             f"| sync: {name} smaller in | sync: median reduction [%] |", "|---|---|---|---|---|"]
    for g, rs in others:
        cells = []
        for key, _ in _MAE:
            pairs = [(a[key], b[key]) for a, b in zip(base[:samples], rs[:samples])
                     if isinstance(a.get(key), float) and isinstance(b.get(key), float)
                     and a["status"] == b["status"] == "completed"]
            red = [100.0 * (b - a) / b for a, b in pairs if b > 0]
            cells += [f"{sum(a < b for a, b in pairs)} of {len(pairs)}",
                      f"{np.median(red):+.1f}" if red else "n/a"]
        lines.append(f"| {', '.join(g)} | " + " | ".join(cells) + " |")
    return lines


def study_figures(out: Path, study) -> dict:
    """{path: Figure} of a grid / Monte Carlo study from out/study.csv (not yet written):
    robustness.png (Monte Carlo), sweep.png (MAE over one or two swept numeric keys)."""
    rows = [r for r in read_study_csv(Path(out) / STUDY_CSV) if r["case"].startswith("c")]
    done = [r for r in rows if r["status"] == "completed" and all(isinstance(r.get(k), float) for k, _ in _MAE)]
    if not done:
        return {}
    numeric_grid = [k for k in study.grid if _numeric(study.grid[k]) and len(study.grid[k]) > 1]
    group_keys = [k for k in study.grid if k not in numeric_grid]
    groups = {}
    for r in done:
        groups.setdefault(tuple(str(r[k]) for k in group_keys), []).append(r)
    if study.samples:
        return {Path(out) / "robustness.png": _histograms(study, groups, group_keys)}
    if len(numeric_grid) == 1:
        return {Path(out) / "sweep.png": _lines(study, groups, group_keys, numeric_grid[0])}
    if len(numeric_grid) >= 2:
        flagged = {}
        for r in rows:
            if r.get("flag"):
                flagged.setdefault(tuple(str(r[k]) for k in group_keys), []).append(r)
        return {Path(out) / "sweep.png": _heatmaps(study, groups, group_keys, numeric_grid[:2], flagged)}
    return {}


def _label(group_keys, group) -> str:
    return ", ".join(f"{k} = {v}" for k, v in zip(group_keys, group)) or "all cases"


def _histograms(study, groups, group_keys):
    fig, axes = plt.subplots(1, 2, figsize=(11, 4 + 0.25 * len(groups)))
    for (key, title), ax in zip(_MAE, axes):
        data = {g: np.array([r[key] for r in rs]) for g, rs in groups.items()}
        lo = min(d.min() for d in data.values())
        hi = max(d.max() for d in data.values())
        wide = lo > 0 and hi / lo > 5  # laws an order of magnitude apart: log bins keep each visible
        bins = (np.geomspace(lo, hi, 30) if wide else np.linspace(lo, hi if hi > lo else lo + 1e-9, 25))
        for g, d in data.items():
            # outlines, not filled bars: several laws overlap on the same bins
            ax.hist(d, bins=bins, histtype="step", lw=1.6, label=f"{_label(group_keys, g)} (n = {len(d)}, "
                    f"median {np.median(d):.3f})")
        if wide:
            ax.set_xscale("log")
        ax.set_xlabel(title)
        ax.set_ylabel("cases [count]")
        ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.16))  # below: the outlines stay visible
    fig.suptitle(f"{study.name}: {study.samples} samples of "
                 + ", ".join(f.name for f in study.factors) + f" (seed {study.seed})", fontsize=10)
    fig.tight_layout()
    return fig


def _lines(study, groups, group_keys, x_key):
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for (key, title), ax in zip(_MAE, axes):
        for g, rs in groups.items():
            rs = sorted(rs, key=lambda r: r[x_key])
            ax.plot([r[x_key] for r in rs], [r[key] for r in rs], "o-", label=_label(group_keys, g))
        ax.set_xlabel(key_label(x_key))
        ax.set_ylabel(title)
        ax.set_yscale("log")
        ax.legend(fontsize=8)
    fig.suptitle(study.name, fontsize=10)
    fig.tight_layout()
    return fig


def _heatmaps(study, groups, group_keys, keys, flagged):
    """Heat maps of the MAE over two swept keys; cells of flagged cases (study.csv ``flag``:
    unstable, marginal, saturated) are cross-hatched and labelled with the flag."""
    kx, ky = keys
    xs, ys = sorted(set(study.grid[kx])), sorted(set(study.grid[ky]))
    fig, axes = plt.subplots(len(groups), 2, figsize=(13, 4.8 * len(groups)), squeeze=False)
    cells = []  # the value labels, one per cell (fitted into their cells below)
    for row_axes, (g, rs) in zip(axes, groups.items()):
        for (key, title), ax in zip(_MAE, row_axes):
            z = np.full((len(ys), len(xs)), np.nan)
            for r in rs:
                z[ys.index(r[ky]), xs.index(r[kx])] = r[key]
            im = ax.imshow(np.log10(z), origin="lower", aspect="auto", cmap="viridis")
            flags = {}
            for r in flagged.get(g, []):
                flags[(ys.index(r[ky]), xs.index(r[kx]))] = r["flag"]
            for (i, j), v in np.ndenumerate(z):
                text = "failed" if np.isnan(v) else f"{v:.3g}"
                if (i, j) in flags:
                    ax.add_patch(Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False, hatch="xx", edgecolor="r", lw=0))
                    text += "\n" + "\n".join(flags[(i, j)].split("+"))  # one flag a line: narrower
                cells.append(ax.text(j, i, text, ha="center", va="center", fontsize=7, color="w",
                                     bbox=dict(facecolor="black", alpha=0.5, lw=0, pad=1.0)))
            ax.set_xticks(range(len(xs)), [f"{v:g}" for v in xs])
            ax.set_yticks(range(len(ys)), [f"{v:g}" for v in ys])
            ax.set_xlabel(key_label(kx))
            ax.set_ylabel(key_label(ky))
            ax.set_title(f"{title}\n{_label(group_keys, g)}", fontsize=9)
            fig.colorbar(im, ax=ax, label="log10 of the MAE in µm [-]")
    fig.suptitle(textwrap.fill(f"{study.name} (blank/failed: the case did not complete; cross-hatched: flagged "
                               "unstable (spectral radius > 1) or saturated (force at the limit in > 1 % of "
                               "samples))", 130), fontsize=9)
    fig.tight_layout()
    fit_cell_labels(fig, cells)
    return fig


def fit_cell_labels(fig, texts, smallest: float = 3.0) -> None:
    """Shrink each heat-map cell label (a Text at data (column, row)) until it lies inside its
    cell (a unit square of the image), down to ``smallest`` points."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    for t in texts:
        ax = t.axes
        j, i = t.get_position()
        (x0, y0), (x1, y1) = ax.transData.transform([(j - 0.5, i - 0.5), (j + 0.5, i + 0.5)])
        while t.get_fontsize() > smallest:
            box = t.get_window_extent(renderer)
            if box.x0 >= x0 and box.x1 <= x1 and box.y0 >= y0 and box.y1 <= y1:
                break
            t.set_fontsize(max(smallest, t.get_fontsize() - 0.5))


def plot_objective(path: Path, results: dict) -> Path:
    """Objective of every tuning evaluation (log scale) and the best so far, one panel per law."""
    fig, axes = plt.subplots(1, len(results), figsize=(5.5 * len(results), 4), squeeze=False)
    for ax, (law, r) in zip(axes[0], results.items()):
        vals = np.array([case_value(row) for row in r["rows"]])
        ok = vals < PENALTY_UM
        n = np.arange(len(vals))
        ax.semilogy(n[ok], vals[ok], ".", label="candidate")
        ax.semilogy(n, np.minimum.accumulate(vals), "-", label="best so far")
        if (~ok).any():
            ax.plot(n[~ok], np.full((~ok).sum(), vals[ok].max() if ok.any() else 1.0), "x", color="r",
                    label="rejected (not stable or beyond the Ms bound) / failed")
        if r["start"] is not None:  # the start gains were run (not rejected)
            ax.axhline(r["start"], color="grey", ls="--", label=f"start gains ({r['start']:.4f} µm)")
        ax.set_title(f"{law}: tuned {r['tuned']:.4f} µm", fontsize=10)
        ax.set_xlabel("evaluation [count]")
        ax.set_ylabel("objective (tracking + sync MAE)/2 [µm]")
        ax.legend(fontsize=8)
    fig.tight_layout()
    try:
        save_figure(fig, path, dpi=110)
    finally:
        plt.close(fig)
    return Path(path)
