"""Figures of a run, a comparison or any runs side by side (matplotlib, PNG and optionally SVG),
after the paper's Fig. 4-7, plus the force commands per motor.

A folder says what it holds (results.folder_kind): a single run (run.json) gets
run_fig4_trajectory.png ... run_fig8_force_commands.png, a comparison (comparison.json)
fig4_trajectory.png ... fig8_force_commands.png with one trace per shown law, so a
figure of one kind never overwrites one of the other. Errors are in µm (µrad for B),
legends sit outside the axes (below them), titles name the laws shown. Each run has its
own line style and marker, so coincident traces stay distinguishable; the proposed law
(SC-DC) is drawn on top. The force figure explains chatter: a sliding mean with a band of
± the sliding RMS of the chatter (the force minus its sliding mean), the force limit as a
labelled line, and a zoom panel with every sample of a short window.
"""

import difflib
import math
import os
import re
from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from tapmp.laws import LAWS  # noqa: E402

from ..errors import UsageError  # noqa: E402
from .metrics import error_signals  # noqa: E402
from .folders import (COMPARISON_JSON, FORMATS, PART_FILE, add_to_marker, check_targets, folder_kind,  # noqa: E402
                      marker, PLOTS_JSON, output_lock, save_figure)
from .reading import ResultFolderError, json_object, read_results  # noqa: E402

LAW_LABELS = {**{law.name: law.label for law in LAWS}, "apd-dc-matched": "APD-DC matched",
              # the other runs of `tapmp compare` (orchestrator.tool.baselines): one label each
              "apd-dc-diff-stiffness": "APD-DC diff. stiffness", "apd-dc-mode-matched": "APD-DC mode-matched",
              "apd-dc-ms-matched": "APD-DC Ms-matched", "pid-dc-mode-matched": "PID-DC mode-matched",
              "pid-dc-full": "PID-DC full integral", "sc-dc-b0": "SC-DC b = 0",
              "sc-dc-lp0": "SC-DC Lambda_p = 0"}
PROPOSED = "sc-dc"  # the proposed law: drawn on top of every other trace
# The runs a comparison figure shows by default: the proposed law, the paper's baseline and the
# better (lower mean tracking MAE) of the two fair baselines.
DEFAULT_RUNS = ("sc-dc", "apd-dc")
FAIR_BASELINES = ("apd-dc-mode-matched", "apd-dc-ms-matched")
ERRORS = (  # key of error_signals, file stem, title, y labels, scale from SI
    ("tracking", "fig5_tracking_errors", "Tracking error of each motor (cf. Fig. 5)",
     ("e1 [µm]", "e2 [µm]", "e3 [µm]"), 1e6),
    ("sync", "fig6_sync_errors", "Synchronization error of each motor (cf. Fig. 6)",
     ("es1 [µm]", "es2 [µm]", "es3 [µm]"), 1e6),
    ("axis", "fig7_axis_errors", "Tracking error of each drive axis (cf. Fig. 7)",
     ("X [µm]", "Z [µm]", "B [µrad]"), 1e6))

# Named signals of `tapmp plot --signals`: name -> (description, unit, scale from SI, source).
# source: ("tracking" | "sync" | "axis", index) of error_signals, or a recorded column.
SIGNALS = {
    **{f"e{i}": (f"tracking error of motor {i}, q{i}_d - q{i}", "µm", 1e6, ("tracking", i - 1)) for i in (1, 2, 3)},
    **{f"es{i}": (f"synchronization error {i}, e{i} - e{i % 3 + 1}", "µm", 1e6, ("sync", i - 1)) for i in (1, 2, 3)},
    "eX": ("axis error X, X_d - X", "µm", 1e6, ("axis", 0)), "eZ": ("axis error Z, Z_d - Z", "µm", 1e6, ("axis", 1)),
    "eB": ("axis error B, B_d - B", "µrad", 1e6, ("axis", 2)),
    **{f"F{i}": (f"force command of motor {i}", "N", 1.0, f"controller.F{i}") for i in (1, 2, 3)},
    **{f"q{i}": (f"position of motor {i}", "mm", 1e3, f"plant.q{i}_true") for i in (1, 2, 3)},
    "X": ("platform X", "mm", 1e3, "plant.X"), "Z": ("platform Z", "mm", 1e3, "plant.Z"),
    "B": ("platform B", "deg", 180 / math.pi, "plant.B"),
}
ALIASES = {**{f"q{i}_err": f"e{i}" for i in (1, 2, 3)}, **{f"q{i}_sync": f"es{i}" for i in (1, 2, 3)}}
SIGNALS_HELP = ("e1..e3 tracking error of each motor [µm] (also q1_err..q3_err), es1..es3 synchronization "
                "errors [µm], eX, eZ [µm], eB [µrad] axis errors, F1..F3 force commands [N], q1..q3 motor positions "
                "[mm], X, Z [mm], B [deg] platform pose, or a recorded column by its full name (e.g. controller.u1) "
                "in SI units")

DPI = 110  # of the PNG files
# Pixel columns a trace is reduced to: as many as the figure is wide (8 in at 110 dpi = 880 px,
# wider than its axes), so the drawn trace covers the same pixels as with every sample.
COLUMNS = 880
CHATTER_WINDOW = 0.01  # [s] sliding window of the force figure's mean and RMS envelope
ZOOM_SAMPLES = 60  # samples in the force figure's zoom panel (each one drawn)
STYLES = (  # (line style, marker) per shown run, in order; the first (SC-DC) solid and on top
    ("-", "o"), ("--", "s"), (":", "^"), ("-.", "D"), ((0, (5, 1, 1, 1)), "v"), ((0, (1, 2)), "x"),
    ((0, (8, 2)), "P"), ((0, (3, 1, 1, 1, 1, 1)), "*"), ((0, (2, 1)), "<"), ((0, (6, 1, 1, 1)), ">"))


def decimate(x, y, columns: int = COLUMNS):
    """(x, y) reduced for drawing: the samples split into at most ``columns`` consecutive
    groups of equal count; each keeps its first sample, its minimum and its maximum (in time
    order), so every pixel column shows the full range of the samples that fall into it
    (min/max decimation). The last sample and any remainder are kept. Fewer than 4 samples
    per group: returned unchanged."""
    x, y = np.asarray(x), np.asarray(y)
    n = len(y)
    m = -(-n // columns)  # samples per group
    if m < 4:
        return x, y
    groups = n // m
    body = y[:groups * m].reshape(groups, m)
    base = np.arange(groups) * m
    keep = np.concatenate([base, base + body.argmin(1), base + body.argmax(1), np.arange(groups * m, n), [n - 1]])
    keep = np.unique(keep)  # sorted: time order
    return x[keep], y[keep]


def label(name: str, law: str | None = None) -> str:
    """Legend label of a run: by its comparison folder name, else by its law."""
    return LAW_LABELS.get(name) or LAW_LABELS.get(law or "", (law or name).upper())


def _suggest(value: str, allowed) -> str:
    """' (did you mean X?)' for the closest allowed name, else ''."""
    close = difflib.get_close_matches(value, list(allowed), n=1, cutoff=0.5)
    return f" (did you mean {close[0]}?)" if close else ""


def parse_window(text: str | None) -> tuple[float, float] | None:
    """--window "START:STOP" [s] -> (start, stop); either side may be empty (from the first /
    to the last sample). ValueError (one line) for anything else."""
    if text is None:
        return None
    m = re.fullmatch(r"\s*([^:]*):([^:]*)\s*", text)
    allowed = "allowed is START:STOP in seconds with START < STOP, e.g. 0.5:1.0, 0.5: or :1.0"
    try:
        if not m:
            raise ValueError
        start = float(m[1]) if m[1].strip() else -math.inf
        stop = float(m[2]) if m[2].strip() else math.inf
    except ValueError:
        raise UsageError(f"--window = {text!r} is invalid: {allowed}") from None
    if math.isnan(start) or math.isnan(stop) or not start < stop:
        raise UsageError(f"--window = {text!r} is invalid: {allowed}")
    return start, stop


def _metrics(path: Path) -> dict:
    """metrics.json of a run folder, {} if none; ResultFolderError if it is damaged."""
    return json_object(path, "metrics.json")


def _run_info(path: Path) -> dict:
    """The scenario a run folder recorded (run.json), {} if none; ResultFolderError if run.json is damaged."""
    scenario = json_object(path, "run.json").get("scenario")
    return scenario if isinstance(scenario, dict) else {}


def horizon(path: Path) -> tuple | None:
    """(start_time, stop_time, step) [s] of a run folder (run.json), None if it records none."""
    s = _run_info(path)
    try:
        return float(s["start_time"]), float(s["stop_time"]), float(s["step"])
    except (KeyError, TypeError, ValueError):
        return None


def force_limit(path: Path) -> float:
    """The force limit [N] of a run (metrics.json, else its scenario's plant or controller
    force_limit; the smaller non-zero one acts first); 0 = none."""
    m = _metrics(path)
    if isinstance(m.get("force_limit_n"), (int, float)):
        return float(m["force_limit_n"])
    s = _run_info(path)
    limits = [t.get("force_limit") for t in (s.get("plant"), s.get("controller")) if isinstance(t, dict)]
    limits = [float(v) for v in limits if isinstance(v, (int, float)) and v > 0]
    return min(limits) if limits else 0.0


def _mean_tracking_mae(path: Path, rows=None) -> float:
    """Mean tracking MAE [µm] over the three motors of a run (metrics.json, else its rows)."""
    m = _metrics(path).get("tracking_mae_um")
    if isinstance(m, list) and m and all(isinstance(v, (int, float)) for v in m):
        return float(np.mean(m))
    try:
        columns, data = rows or read_results(path)
    except ResultFolderError:
        return math.inf  # a run that left no rows (failed) is never the better baseline
    return float(np.mean(np.abs(error_signals(columns, data)["tracking"])) * 1e6)


def select_runs(folder: Path, names: list[str], wanted: list[str] | None = None, rows: dict | None = None) -> list[str]:
    """The runs of a comparison to show: ``wanted`` (folder names; "all" for every run), or by
    default the proposed law, the paper's baseline and the better fair baseline (the lower mean
    tracking MAE of apd-dc-mode-matched and apd-dc-ms-matched), those of them present.
    ValueError (one line) for a name the comparison does not hold."""
    if wanted:
        if wanted == ["all"]:
            return list(names)
        for w in wanted:
            if w not in names:
                raise UsageError(f"--runs: {w!r} is not a run of {folder}{_suggest(w, names)}: allowed are "
                                 f"{', '.join(names)} or all")
        return list(dict.fromkeys(wanted))
    fair = [n for n in FAIR_BASELINES if n in names]
    best = [min(fair, key=lambda n: _mean_tracking_mae(Path(folder) / n, (rows or {}).get(n)))] if fair else []
    chosen = [n for n in DEFAULT_RUNS if n in names] + best
    return chosen or list(names)


def _load_run(path: Path, rows=None, window=None) -> dict:
    """A run as the figures draw it: error_signals of its rows (in ``window`` [s] if given) plus
    "columns", "data", "name" (folder name), "force_limit" [N] and "horizon"."""
    path = Path(path)
    if rows is None and not any(os.path.lexists(path / n) for n in (*FORMATS.values(), PART_FILE)):
        status = json_object(path, "run.json").get("status", "unknown")
        raise ResultFolderError(f"{path} holds no rows to plot (its run is {status}; run.json says why)")
    columns, data = rows or read_results(path)
    if window is not None:
        t = data[:, 0]
        data = data[(t >= window[0]) & (t <= window[1])]
        if len(data) < 2:
            raise UsageError(f"--window = {window[0]:g}:{window[1]:g} s holds {len(data)} sample(s) of {path} "
                             f"(its time runs {t[0]:g} to {t[-1]:g} s): allowed is a window with 2 or more samples")
    return error_signals(columns, data) | {"columns": columns, "data": data, "name": Path(path).name,
                                           "force_limit": force_limit(path), "horizon": horizon(path)}


def not_a_result_folder(path: Path) -> "ResultFolderError":
    """The one-line error for a result-folder argument ``path`` that is no folder: missing, or a
    file (a run's results.csv given for its folder: the folder is named)."""
    allowed = "allowed is a folder written by tapmp run or tapmp compare"
    if path.is_file():
        return ResultFolderError(f"result folder {path} is a file, not a folder: {allowed}"
                                 + (f" (this file's folder is {path.parent})" if path.parent.name else ""))
    return ResultFolderError(f"result folder {path} does not exist: {allowed}")


def load_folder(folder: Path, rows: dict | None = None, show: list[str] | None = None,
                window: tuple | None = None) -> tuple[str, dict[str, dict]]:
    """(kind, {label: run}) of a result folder, kind "run" or "comparison"; each run is the
    error_signals of its rows plus "columns" and "data". ResultFolderError (one line)
    for a folder that is missing or holds no readable results. ``rows`` ({run folder name:
    (columns, rows)}) gives rows already in memory (the runs just made) instead of reading them.
    ``show``: the runs of a comparison to load (see select_runs; None: every run);
    ``window``: (start, stop) [s] of the rows to keep."""
    folder = Path(folder)
    if not folder.is_dir():
        raise not_a_result_folder(folder)
    kind = folder_kind(folder)
    if kind == "run":
        paths = {label(folder.name, _run_info(folder).get("law")): folder}
    elif kind == "comparison":
        names = _runs_of(folder)
        present = {n: law for n, law in names.items() if folder_kind(folder / n) == "run"}
        if show is not None:
            present = {n: present[n] for n in show if n in present}
        paths = {label(n, law): folder / n for n, law in present.items()}
    else:
        raise ResultFolderError(f"result folder {folder} holds no results of tapmp run or tapmp compare "
                                "(no run.json, comparison.json or run folders)")
    runs = {name: _load_run(path, (rows or {}).get(path.name), window) for name, path in paths.items()}
    if not runs:
        raise ResultFolderError(f"comparison folder {folder} holds none of its runs yet")
    return kind, runs


def _title(text: str, runs: dict, width: int = 80, sep: str = " vs ") -> str:
    """``text: run vs run vs ...``, broken between runs (never inside a name) to fit the figure;
    a separator ends its line, so no line starts with one."""
    lines, line = [], f"{text}:"
    for i, name in enumerate(runs):
        piece = (" " if i == 0 else sep) + name
        if len(line) + len(piece) > width and line:
            if i > 0:
                line += sep.rstrip()
            lines.append(line)
            piece = name
            line = ""
        line += piece
    return "\n".join(lines + [line])


def _legend_below(fig, axes) -> None:
    """One legend for the figure, below the axes (never over a trace)."""
    handles, labels = axes[0].get_legend_handles_labels()
    # at most three entries a row, so eight runs still fit the figure's width
    fig.legend(handles, labels, loc="outside lower center", ncols=max(1, min(3, len(labels))), frameon=False)


def _style(runs: dict) -> dict:
    """{label: plot keywords}: a line style, a marker (a few per trace, at offsets that differ
    between runs) and a layer per run; the proposed law solid, thicker and on top (zorder 3)."""
    out = {}
    rest = iter(STYLES[1:])
    for k, (name, run) in enumerate(runs.items()):
        proposed = run.get("name") == PROPOSED or name == LAW_LABELS[PROPOSED]
        ls, marker = STYLES[0] if proposed else next(rest, STYLES[-1])
        n = len(run["data"])
        every = max(1, min(n, COLUMNS) // 12)
        out[name] = dict(ls=ls, marker=marker, markersize=4, markevery=(k * every // max(1, len(runs)), every),
                         lw=1.3 if proposed else 0.9, zorder=3 if proposed else 2, color=f"C{k}",
                         markerfacecolor="none")
    return out


def trajectory_figure(runs: dict):
    """Fig. 4: the desired trajectory (X-Z in mm, B in deg over time [s]) of the first run."""
    name, run = next(iter(runs.items()))
    c = {n: i for i, n in enumerate(run["columns"])}
    data = run["data"]
    fig, ax = plt.subplots(1, 2, figsize=(10, 4.4), layout="constrained")
    ax[0].plot(data[:, c["trajectory.X_d"]] * 1e3, data[:, c["trajectory.Z_d"]] * 1e3, label="desired")
    ax[0].set(xlabel="X [mm]", ylabel="Z [mm]", title="(a) X- and Z-axis", aspect="equal")
    ax[1].plot(*decimate(data[:, 0], data[:, c["trajectory.B_d"]] * 180 / math.pi), label="desired")
    ax[1].set(xlabel="time [s]", ylabel="B [deg]", title="(b) B-axis")
    fig.suptitle(_title("Desired trajectory in task space (cf. paper Fig. 4), the reference of", runs, sep=", "))
    return fig


def error_figure(runs: dict, key: str):
    """Fig. 5-7: the errors ``key`` ("tracking", "sync" or "axis") of every run, in µm (µrad)."""
    _, _, title, ylabels, scale = next(e for e in ERRORS if e[0] == key)
    styles = _style(runs)
    fig, axes = plt.subplots(3, 1, figsize=(8, 8.6), sharex=True, layout="constrained")
    for name, sig in runs.items():
        for i in range(3):
            axes[i].plot(*decimate(sig["time"], sig[key][:, i] * scale), label=name, **styles[name])
    for i in range(3):
        axes[i].set_ylabel(ylabels[i])
        axes[i].grid(True, alpha=0.3)
    axes[-1].set_xlabel("time [s]")
    _legend_below(fig, axes)
    fig.suptitle(_title(title, runs))
    return fig


def force_columns(columns: list[str]) -> list[int]:
    """Indices of the force commands F1, F2, F3 [N] (controller.F1.. if present, else any *.F1..)."""
    out = []
    for i in (1, 2, 3):
        exact = [k for k, c in enumerate(columns) if c == f"controller.F{i}"]
        anywhere = [k for k, c in enumerate(columns) if c.endswith(f".F{i}")]
        if not (exact or anywhere):
            raise ResultFolderError(f"the results hold no force command F{i} (a column controller.F{i})")
        out.append((exact or anywhere)[0])
    return out


def sliding_mean_rms(t, f, window: float = CHATTER_WINDOW):
    """(mean, rms) of ``f`` over a centred sliding window of ``window`` seconds (at least one
    sample): the sliding mean and the sliding RMS of the chatter f - mean, same units as f."""
    f = np.asarray(f, dtype=float)
    dt = float(np.median(np.diff(t))) if len(t) > 1 else window
    w = int(max(1, min(len(f), round(window / dt) if dt > 0 else 1)))
    kernel = np.ones(w) / w
    pad = (w // 2, w - 1 - w // 2)  # edge samples repeated, so the ends are no artefact of zeros
    mean = np.convolve(np.pad(f, pad, mode="edge"), kernel, mode="valid")
    sq = np.convolve(np.pad(f * f, pad, mode="edge"), kernel, mode="valid")
    return mean, np.sqrt(np.maximum(sq - mean * mean, 0.0))


def _band(x, lo, hi, columns: int = COLUMNS):
    """(x, lo, hi) of a band reduced for drawing as decimate reduces a trace: per group of
    samples its first x, the minimum of ``lo`` and the maximum of ``hi``, so the drawn band
    covers every sample's band. Fewer than 4 samples per group: unchanged."""
    x, lo, hi = np.asarray(x), np.asarray(lo), np.asarray(hi)
    n = len(x)
    m = -(-n // columns)
    if m < 4:
        return x, lo, hi
    groups = n // m
    gx = np.append(x[:groups * m:m], x[groups * m:])
    glo = np.append(lo[:groups * m].reshape(groups, m).min(1), lo[groups * m:])
    ghi = np.append(hi[:groups * m].reshape(groups, m).max(1), hi[groups * m:])
    return gx, glo, ghi


def _zoom_range(runs: dict) -> tuple[int, int]:
    """Sample range of the zoom panel: ZOOM_SAMPLES around the largest chatter RMS of the
    first run (the proposed law if shown), summed over the three motors."""
    run = next(iter(runs.values()))
    t, data = run["data"][:, 0], run["data"]
    total = sum(sliding_mean_rms(t, data[:, c])[1] for c in force_columns(run["columns"]))
    n = len(t)
    mid = int(np.argmax(total))
    lo = max(0, min(mid - ZOOM_SAMPLES // 2, n - ZOOM_SAMPLES))
    return lo, min(n, lo + ZOOM_SAMPLES)


def force_figure(runs: dict):
    """Fig. 8: the force command F_i [N] the controller sends to each motor, every run. Left:
    the sliding mean over CHATTER_WINDOW with a band of ± the sliding RMS of the chatter (the
    force minus that mean); middle: every sample of a short zoom window (grey span on the left);
    right: the peak |F_i| of each run against the force limit, drawn as a labelled dashed line."""
    styles = _style(runs)
    fig, axes = plt.subplots(3, 3, figsize=(12, 8.6), layout="constrained",
                             gridspec_kw={"width_ratios": (2.2, 1, 0.7)})
    lo, hi = _zoom_range(runs)
    first = next(iter(runs.values()))["data"][:, 0]
    t0, t1 = first[lo], first[hi - 1]
    limits = sorted({run["force_limit"] for run in runs.values() if run["force_limit"] > 0})
    for k, (name, run) in enumerate(runs.items()):
        cols = force_columns(run["columns"])
        t = run["data"][:, 0]
        st = styles[name]
        for i in range(3):
            f = run["data"][:, cols[i]]
            mean, rms = sliding_mean_rms(t, f)
            axes[i, 0].plot(*decimate(t, mean), label=name, **st)
            axes[i, 0].fill_between(*_band(t, mean - rms, mean + rms), color=st["color"], alpha=0.25, lw=0,
                                    zorder=st["zorder"] - 1)
            sel = (t >= t0) & (t <= t1)
            axes[i, 1].plot(t[sel] * 1e3, f[sel], **{**st, "markevery": 1, "markersize": 3})
            axes[i, 2].bar(k, np.abs(f).max(), color=st["color"], zorder=st["zorder"])
    for i in range(3):
        axes[i, 0].axvspan(t0, t1, color="0.85", zorder=0)
        axes[i, 0].set_ylabel(f"F{i + 1} [N]")
        axes[i, 1].set_ylabel(f"F{i + 1} [N]")
        axes[i, 2].set_ylabel(f"peak |F{i + 1}| [N]")
        axes[i, 2].set_xticks(range(len(runs)), [str(k + 1) for k in range(len(runs))])
        for lim in limits:
            axes[i, 2].axhline(lim, color="r", ls=(0, (6, 3)), lw=1.2, zorder=4, label=f"force limit {lim:g} N")
            axes[i, 2].annotate(f"force limit {lim:g} N", (0.03, lim), xycoords=("axes fraction", "data"),
                                va="bottom", fontsize=7, color="r")
        if not limits:
            axes[i, 2].annotate("no force limit\n(force_limit = 0)", (0.03, 0.97), xycoords="axes fraction",
                                va="top", fontsize=7, color="r")
        for ax in axes[i]:
            ax.grid(True, alpha=0.3)
    for col in (0, 1):
        axes[0, col].sharex(axes[1, col])
        axes[2, col].sharex(axes[1, col])
    axes[0, 0].set_title(f"sliding mean over {CHATTER_WINDOW * 1e3:g} ms, band ± RMS of the chatter", fontsize=9)
    axes[0, 1].set_title(f"zoom (grey span): every sample,\n{t0 * 1e3:.4g} to {t1 * 1e3:.4g} ms", fontsize=9)
    axes[0, 2].set_title("headroom: peak |F|\nper run (legend order)", fontsize=9)
    axes[-1, 0].set_xlabel("time [s]")
    axes[-1, 1].set_xlabel("time [ms]")
    axes[-1, 2].set_xlabel("run number [-]")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    if limits:
        h2, l2 = axes[0, 2].get_legend_handles_labels()
        handles, labels = handles + h2, labels + l2
    fig.legend(handles, labels, loc="outside lower center", ncols=max(1, min(4, len(labels))), frameon=False)
    fig.suptitle(_title("Force command of each motor", runs))
    return fig


def _makers() -> dict:
    """{file stem: function(runs) -> Figure} of Fig. 4-8."""
    out = {"fig4_trajectory": trajectory_figure}
    for key, stem, *_ in ERRORS:
        out[stem] = lambda runs, key=key: error_figure(runs, key)
    out["fig8_force_commands"] = force_figure
    return out


def figures(runs: dict) -> dict:
    """{file stem: Figure} of Fig. 4-8 for ``runs`` ({label: run} as load_folder gives)."""
    return {stem: make(runs) for stem, make in _makers().items()}


def resolve_signal(name: str, columns: list[str]) -> tuple[str, str]:
    """(canonical name, axis label with unit) of a --signals entry; ValueError (one line, with
    the closest allowed name) for one that is neither a named signal nor a recorded column."""
    key = ALIASES.get(name, name)
    if key in SIGNALS:
        desc, unit, _, _ = SIGNALS[key]
        return key, f"{key} [{unit}]"
    if key in columns and key != "time":
        return key, f"{key} [{_column_unit(key)}]"
    allowed = list(SIGNALS) + list(ALIASES) + [c for c in columns if c != "time"]
    raise UsageError(f"--signals: {name!r} is not a signal{_suggest(name, allowed)}: allowed are {SIGNALS_HELP}")


def _column_unit(column: str) -> str:
    """SI unit of a recorded column ``element.variable`` (tapmp.interface), '-' if it has none."""
    from tapmp.interface import ELEMENT, VARIABLES
    element, _, var = column.partition(".")
    for fmu, el in ELEMENT.items():
        if el == element:
            for v in VARIABLES[fmu]:
                if v.name == var:
                    return v.unit or "-"
    return "-"


def signal_values(run: dict, key: str) -> np.ndarray:
    """Values of a resolved signal ``key`` of ``run`` in the unit of its axis label."""
    if key in SIGNALS:
        _, _, scale, source = SIGNALS[key]
        if isinstance(source, tuple):
            return run[source[0]][:, source[1]] * scale
        return run["data"][:, run["columns"].index(source)] * scale
    return run["data"][:, run["columns"].index(key)]


def signals_figure(runs: dict, keys: list[tuple[str, str]]):
    """One panel per signal (``keys``: (name, axis label) from resolve_signal), every run overlaid."""
    styles = _style(runs)
    fig, axes = plt.subplots(len(keys), 1, figsize=(8, 1.2 + 2.5 * len(keys)), sharex=True, layout="constrained",
                             squeeze=False)
    axes = axes[:, 0]
    for name, run in runs.items():
        for ax, (key, _) in zip(axes, keys):
            ax.plot(*decimate(run["data"][:, 0], signal_values(run, key)), label=name, **styles[name])
    for ax, (key, ylabel) in zip(axes, keys):
        ax.set_ylabel(ylabel)
        ax.grid(True, alpha=0.3)
        if key in SIGNALS:
            ax.set_title(SIGNALS[key][0], fontsize=9)
    axes[-1].set_xlabel("time [s]")
    _legend_below(fig, list(axes))
    fig.suptitle(_title("Signals " + ", ".join(k for k, _ in keys), runs))
    return fig


_RUNS = {}  # the runs a forked figure worker draws (inherited from the parent, never pickled)


def _draw(stem: str, path: str) -> str:
    """Draw and write one figure of _RUNS (in this process or a forked worker)."""
    fig = _makers()[stem](_RUNS)
    try:
        save_figure(fig, path, dpi=DPI)
    finally:
        plt.close(fig)
    return path


class FigureSet:
    """The figures of a run or comparison folder (see :func:`plot`), drawn one at a time
    (:meth:`draw_next`: while a comparison's other runs still run) or the rest at once
    (:meth:`draw_rest`). ``names``: the comparison's runs (default: those its folder holds
    now); ``rows``, ``show``: see :func:`plot`."""

    def __init__(self, folder: Path, rows: dict | None = None, show: list[str] | None = None,
                 names: list[str] | None = None):
        folder = Path(folder)
        if folder_kind(folder) == "comparison":
            show = select_runs(folder, names if names is not None else _comparison_names(folder), show, rows)
        self.kind, self.runs = load_folder(folder, rows, show)
        prefix = "run_" if self.kind == "run" else ""
        self.paths = {stem: folder / f"{prefix}{stem}.png" for stem in _makers()}
        self.left = list(reversed(list(self.paths)))  # not drawn yet, the heaviest first

    def draw_next(self) -> bool:
        """Draw and write the next figure in this process; False if none was left."""
        global _RUNS
        if not self.left:
            return False
        stem = self.left[0]
        _RUNS = self.runs
        try:
            _draw(stem, str(self.paths[stem]))
        finally:
            _RUNS = {}
        self.left.pop(0)  # only once written: a figure that fails stays to be drawn again
        return True

    def draw_rest(self, jobs: int = 1) -> list[Path]:
        """Draw every figure not drawn yet (``jobs`` > 1: in that many forked processes); returns
        the paths of all figures."""
        global _RUNS
        left, self.left = self.left, []
        _RUNS = self.runs
        try:
            if jobs > 1 and len(left) > 1:
                from concurrent.futures import ProcessPoolExecutor
                from multiprocessing import get_context
                with ProcessPoolExecutor(min(jobs, len(left)), mp_context=get_context("fork")) as pool:
                    list(pool.map(_draw, left, [str(self.paths[s]) for s in left]))
            else:
                for stem in left:
                    _draw(stem, str(self.paths[stem]))
        finally:
            _RUNS = {}
        return list(self.paths.values())


def plot(folder: Path, rows: dict | None = None, jobs: int = 1, show: list[str] | None = None) -> list[Path]:
    """Write the figures of a run folder (run_fig4_trajectory.png ... run_fig8_force_commands.png)
    or of a comparison folder (fig4_trajectory.png ... fig8_force_commands.png) into ``folder``;
    return their paths. ``rows``: see load_folder. ``jobs`` > 1 draws the figures in that many
    forked processes (the same files). ``show``: the comparison's runs to draw (folder names;
    default: see select_runs)."""
    return FigureSet(folder, rows, show).draw_rest(jobs)


def figure_runs(names: list[str], show: list[str] | None = None) -> list[str]:
    """The runs of a comparison (folder names ``names``) whose results the figures need before
    they can be drawn: the runs ``show`` names ("all": every run), else the default ones and
    both fair baselines (select_runs picks the better of them by its metrics)."""
    if show:
        return list(names) if show == ["all"] else [n for n in names if n in show]
    return [n for n in names if n in DEFAULT_RUNS or n in FAIR_BASELINES] or list(names)


def _comparison_names(folder: Path) -> list[str]:
    """Folder names of the runs a comparison folder holds, in comparison.json's order."""
    return [n for n in _runs_of(folder) if folder_kind(Path(folder) / n) == "run"]


def _runs_of(folder: Path) -> dict:
    """{run folder name: law or None} of a comparison folder: comparison.json's runs, else (a
    comparison written before it existed) its subfolders with a run.json. ResultFolderError if
    comparison.json is damaged."""
    runs = json_object(folder, COMPARISON_JSON).get("runs")
    if runs is not None:
        if not (isinstance(runs, dict) and all(isinstance(n, str) and n and "/" not in n and n not in (".", "..")
                                               for n in runs)):
            raise ResultFolderError(f"{Path(folder) / COMPARISON_JSON} is damaged: its runs are not a table of run "
                                    "folder names")
        return {n: law if isinstance(law, str) else None for n, law in runs.items()}
    return {p.name: None for p in sorted(Path(folder).iterdir()) if (p / "run.json").is_file()}


def default_out(folders: list[Path], labels: list[str]) -> Path:
    """Output folder of an overlay of several runs: results/plots/<label>_vs_<label>... under the
    current directory (characters other than letters, digits, '.', '-' and '_' become '_')."""
    name = "_vs_".join(re.sub(r"[^A-Za-z0-9._-]+", "_", lab) for lab in labels)
    return Path("results") / "plots" / name[:150]


def plot_runs(folders: list, labels: list[str] | None = None, signals: list[str] | None = None,
              window: tuple | None = None, out: Path | None = None, svg: bool = False,
              allow_different_horizons: bool = False, show: list[str] | None = None) -> list[Path]:
    """`tapmp plot`: the figures of one result folder (as :func:`plot`, into the folder unless
    ``out``) or of several run folders overlaid (into ``out``, default :func:`default_out`).
    ``signals`` (names of SIGNALS, aliases or recorded columns) gives one figure signals.png
    instead of Fig. 4-8; ``window`` (start, stop) [s] keeps only those rows. Every input is
    checked before anything is written (ValueError / ResultFolderError, one line)."""
    folders = [Path(f) for f in folders]
    if labels and len(labels) != len(folders):
        raise UsageError(f"--label given {len(labels)} time(s) for {len(folders)} folder(s): allowed is one "
                         "--label per folder, or none (labels from the folder names)")
    for f in folders:
        if not f.is_dir():
            raise not_a_result_folder(f)
        kind = folder_kind(f)
        if kind is None:
            raise ResultFolderError(f"result folder {f} holds no results of tapmp run or tapmp compare (no "
                                    "run.json, comparison.json or run folders)")
        if kind == "comparison" and len(folders) > 1:
            raise ResultFolderError(f"result folder {f} is a comparison: overlay its run folders instead "
                                    f"(e.g. {f / 'sc-dc'}) or plot it alone")
    if show is not None and (len(folders) > 1 or folder_kind(folders[0]) != "comparison"):
        raise UsageError("--runs selects the runs of one comparison folder: allowed only with a single "
                         "comparison folder")
    if len(folders) == 1 and folder_kind(folders[0]) == "comparison":
        if labels:
            raise UsageError("--label names run folders: allowed only with run folders (a comparison's runs are "
                             "labelled by their law)")
        kind, runs = load_folder(folders[0], None, select_runs(folders[0], _comparison_names(folders[0]), show),
                                 window)
        paths = [folders[0] / n for n in (r["name"] for r in runs.values())]
    else:
        kind = "run" if len(folders) == 1 else "overlay"
        paths = folders
        names = labels or _unique_names(folders)
        runs = {}
        for name, f in zip(names, paths):
            if name in runs:
                raise UsageError(f"--label {name!r} is given twice: allowed are distinct labels")
            runs[name] = _load_run(f, None, window)
        if not labels and len(folders) == 1:
            runs = {label(folders[0].name, _run_info(folders[0]).get("law")): runs[names[0]]}
    _check_horizons(paths, allow_different_horizons)
    keys = None
    if signals:
        columns = next(iter(runs.values()))["columns"]
        keys = [resolve_signal(s.strip(), columns) for s in signals if s.strip()]
        if not keys:
            raise UsageError("--signals is empty: allowed are " + SIGNALS_HELP)
        for name, run in runs.items():
            for key, _ in keys:
                src = SIGNALS[key][3] if key in SIGNALS else key
                if isinstance(src, str) and src not in run["columns"]:
                    raise UsageError(f"--signals: {key!r} needs the column {src}, which run {name} did not record")
    if out is None:  # a comparison's chosen runs beside it, not over the comparison's own figures
        out = (folders[0] if len(folders) == 1 and show is None
               else default_out(folders, [p.name for p in paths] if show is not None else list(runs)))
    out = Path(out)
    prefix = "run_" if kind == "run" and not keys else ""
    names = [f"{prefix}{stem}.{ext}" for stem in (["signals"] if keys else _makers())
             for ext in (("png", "svg") if svg else ("png",))]
    with output_lock(out):  # one writer: its marker's record of the figures is rewritten
        found = marker(out)  # none: plots.json will put the figures on record
        check_targets(out, names if found else [*names, PLOTS_JSON], found)  # else nothing is drawn
        figs = {"signals": signals_figure(runs, keys)} if keys else figures(runs)
        written = []
        try:
            for stem, fig in figs.items():
                for ext in ("png", "svg") if svg else ("png",):
                    written.append(save_figure(fig, out / f"{prefix}{stem}.{ext}", dpi=DPI))
            add_to_marker(out, [p.name for p in written])
        except BaseException:
            for p in written:  # no partial output
                p.unlink(missing_ok=True)
            raise
        finally:
            for fig in figs.values():
                plt.close(fig)
    return written


def _unique_names(folders: list[Path]) -> list[str]:
    """Labels from folder names; a name two folders share gets its parent folder as a prefix."""
    names = [f.name for f in folders]
    out = []
    for f in folders:
        if names.count(f.name) > 1:
            out.append(f"{f.resolve().parent.name}/{f.name}")
        else:
            out.append(f.name)
    if len(set(out)) < len(out):  # still equal: the full paths
        out = [str(f) for f in folders]
    return out


def _check_horizons(paths: list[Path], allow: bool) -> None:
    """ValueError (one line) if the runs' (start, stop, step) differ, unless ``allow``."""
    found = {str(p): horizon(p) for p in paths}
    distinct = {h for h in found.values() if h is not None}
    if len(distinct) > 1 and not allow:
        text = "; ".join(f"{p}: {h[0]:g} to {h[1]:g} s, step {h[2]:g} s" for p, h in found.items() if h)
        raise UsageError(f"the runs have different horizons ({text}): allowed are runs of the same start, stop and "
                         "step, or pass --allow-different-horizons")
