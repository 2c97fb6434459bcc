"""Figures of a run or a comparison (matplotlib, PNG), after the paper's Fig. 4-7, plus
the force commands per motor.

A folder says what it holds (results.folder_kind): a single run (run.json) gets
run_fig4_trajectory.png ... run_fig8_force_commands.png, a comparison (comparison.json)
fig4_trajectory.png ... fig8_force_commands.png with one trace per compared law, so a
figure of one kind never overwrites one of the other. Errors are in µm (µrad for B),
legends sit outside the axes (below them), titles name the laws shown.
"""

import math
from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from .metrics import error_signals  # noqa: E402
from .results import COMPARISON_JSON, ResultFolderError, _read_json, folder_kind, read_results  # noqa: E402

LAW_LABELS = {"sc-dc": "SC-DC (proposed)", "apd-dc": "APD-DC", "apd-dc-matched": "APD-DC matched",
              "pid-dc": "PID-DC",
              # the other runs of `tapmp compare` (orchestrator.experiments.baselines): one label each
              "apd-dc-diff-stiffness": "APD-DC diff. stiffness", "apd-dc-mode-matched": "APD-DC mode-matched",
              "apd-dc-ms-matched": "APD-DC Ms-matched", "pid-dc-mode-matched": "PID-DC mode-matched", "sc-dc-b0": "SC-DC b = 0",
              "sc-dc-lp0": "SC-DC Lambda_p = 0"}
ERRORS = (  # key of error_signals, file stem, title, y labels, scale from SI
    ("tracking", "fig5_tracking_errors", "Tracking error of each motor (cf. Fig. 5)",
     ("e1 [µm]", "e2 [µm]", "e3 [µm]"), 1e6),
    ("sync", "fig6_sync_errors", "Synchronization error of each motor (cf. Fig. 6)",
     ("es1 [µm]", "es2 [µm]", "es3 [µm]"), 1e6),
    ("axis", "fig7_axis_errors", "Tracking error of each drive axis (cf. Fig. 7)",
     ("X [µm]", "Z [µm]", "B [µrad]"), 1e6))


DPI = 110  # of the PNG files
# Pixel columns a trace is reduced to: as many as the figure is wide (8 in at 110 dpi = 880 px,
# wider than its axes), so the drawn trace covers the same pixels as with every sample.
COLUMNS = 880


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


def load_folder(folder: Path, rows: dict | None = None) -> tuple[str, dict[str, dict]]:
    """(kind, {label: run}) of a result folder, kind "run" or "comparison"; each run is the
    error_signals of its rows plus "columns" and "data". ResultFolderError (one line)
    for a folder that is missing or holds no readable results. ``rows`` ({run folder name:
    (columns, rows)}) gives rows already in memory (the runs just made) instead of reading them."""
    folder = Path(folder)
    if not folder.is_dir():
        raise ResultFolderError(f"result folder {folder} does not exist{' (a file)' if folder.exists() else ''}: "
                                "allowed is a folder written by tapmp run or tapmp compare")
    kind = folder_kind(folder)
    if kind == "run":
        paths = {label(folder.name, (_read_json(folder / "run.json") or {}).get("scenario", {}).get("law")): folder}
    elif kind == "comparison":
        info = _read_json(folder / COMPARISON_JSON) or {}
        names = info.get("runs") or {p.name: None for p in sorted(folder.iterdir())
                                     if (p / "run.json").is_file()}
        paths = {label(n, law): folder / n for n, law in names.items() if folder_kind(folder / n) == "run"}
    else:
        raise ResultFolderError(f"result folder {folder} holds no results of tapmp run or tapmp compare "
                                "(no run.json, comparison.json or run folders)")
    runs = {}
    for name, path in paths.items():
        try:
            columns, data = (rows or {}).get(path.name) or read_results(path)
        except ResultFolderError:
            status = (_read_json(path / "run.json") or {}).get("status", "unknown")
            raise ResultFolderError(f"{path} holds no rows to plot (its run is {status}; run.json says why)") from None
        runs[name] = error_signals(columns, data) | {"columns": columns, "data": data}
    if not runs:
        raise ResultFolderError(f"comparison folder {folder} holds none of its runs yet")
    return kind, runs


def _title(text: str, runs: dict, width: int = 80, sep: str = " vs ") -> str:
    """``text: run vs run vs ...``, broken between runs (never inside a name) to fit the figure."""
    lines, line = [], f"{text}:"
    for i, name in enumerate(runs):
        piece = (" " if i == 0 else sep) + name
        if len(line) + len(piece) > width and line:
            lines.append(line)
            piece = piece.lstrip()
            line = ""
        line += piece
    return "\n".join(lines + [line])


def _legend_below(fig, axes) -> None:
    """One legend for the figure, below the axes (never over a trace)."""
    handles, labels = axes[0].get_legend_handles_labels()
    # at most three entries a row, so eight runs still fit the figure's width
    fig.legend(handles, labels, loc="outside lower center", ncols=max(1, min(3, len(labels))), frameon=False)


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
    fig, axes = plt.subplots(3, 1, figsize=(8, 8.6), sharex=True, layout="constrained")
    for name, sig in runs.items():
        for i in range(3):
            axes[i].plot(*decimate(sig["time"], sig[key][:, i] * scale), label=name, lw=0.8)
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


def force_figure(runs: dict):
    """Fig. 8: the force command F_i [N] the controller sends to each motor, every run."""
    fig, axes = plt.subplots(3, 1, figsize=(8, 8.6), sharex=True, layout="constrained")
    for name, run in runs.items():
        cols = force_columns(run["columns"])
        for i in range(3):
            axes[i].plot(*decimate(run["data"][:, 0], run["data"][:, cols[i]]), label=name, lw=0.8)
    for i in range(3):
        axes[i].set_ylabel(f"F{i + 1} [N]")
        axes[i].grid(True, alpha=0.3)
    axes[-1].set_xlabel("time [s]")
    _legend_below(fig, axes)
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


_RUNS = {}  # the runs a forked figure worker draws (inherited from the parent, never pickled)


def _draw(stem: str, path: str) -> str:
    """Draw and write one figure of _RUNS (in this process or a forked worker)."""
    fig = _makers()[stem](_RUNS)
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path


def plot(folder: Path, rows: dict | None = None, jobs: int = 1) -> list[Path]:
    """Write the figures of a run folder (run_fig4_trajectory.png ... run_fig8_force_commands.png)
    or of a comparison folder (fig4_trajectory.png ... fig8_force_commands.png) into ``folder``;
    return their paths. ``rows``: see load_folder. ``jobs`` > 1 draws the figures in that many
    forked processes (the same files)."""
    global _RUNS
    folder = Path(folder)
    kind, runs = load_folder(folder, rows)
    prefix = "run_" if kind == "run" else ""
    paths = {stem: folder / f"{prefix}{stem}.png" for stem in _makers()}
    _RUNS = runs
    try:
        if jobs > 1:
            from concurrent.futures import ProcessPoolExecutor
            from multiprocessing import get_context
            with ProcessPoolExecutor(min(jobs, len(paths)), mp_context=get_context("fork")) as pool:
                # the heaviest figures first, so the pool ends together
                list(pool.map(_draw, reversed(list(paths)), [str(paths[s]) for s in reversed(list(paths))]))
        else:
            for stem, path in paths.items():
                _draw(stem, str(path))
    finally:
        _RUNS = {}
    return list(paths.values())
