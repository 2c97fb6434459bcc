"""Figures of a run or a comparison (matplotlib, PNG), after the paper's Fig. 4-7."""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from .metrics import error_signals  # noqa: E402
from .results import read_results  # noqa: E402

_LABELS = {"sc-dc": "SC-DC (proposed)", "apd-dc": "APD-DC", "apd-dc-matched": "APD-DC matched"}


def _runs(folder: Path) -> dict[str, Path]:
    """Run folders under a comparison folder, or the folder itself for a single run."""
    folder = Path(folder)
    if (folder / "results.csv").is_file():
        return {folder.name: folder}
    runs = {p.name: p for p in sorted(folder.iterdir()) if (p / "results.csv").is_file()}
    if not runs:
        raise FileNotFoundError(f"{folder} holds no results.csv (neither itself nor a sub-folder)")
    return runs


def plot(folder: Path) -> list[Path]:
    """Write fig4_trajectory.png ... fig7_axis_errors.png into ``folder``; return their paths."""
    folder = Path(folder)
    runs = {name: error_signals(*read_results(p)) | {"data": read_results(p)} for name, p in _runs(folder).items()}
    written = []
    cols, data = next(iter(runs.values()))["data"]
    c = {n: i for i, n in enumerate(cols)}
    t = data[:, 0]
    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    ax[0].plot(data[:, c["trajectory.X_d"]] * 1e3, data[:, c["trajectory.Z_d"]] * 1e3)
    ax[0].set(xlabel="X [mm]", ylabel="Z [mm]", title="(a) X- and Z-axis", aspect="equal")
    ax[1].plot(t, data[:, c["trajectory.B_d"]] * 180 / 3.141592653589793)
    ax[1].set(xlabel="time [s]", ylabel="B [deg]", title="(b) B-axis")
    fig.suptitle("Desired trajectory in task space (cf. paper Fig. 4)")
    written.append(_save(fig, folder / "fig4_trajectory.png"))
    for key, name, title, ylabels, scale in (
            ("tracking", "fig5_tracking_errors.png", "Tracking error of each motor (cf. Fig. 5)",
             ("e1 [um]", "e2 [um]", "e3 [um]"), (1e6,) * 3),
            ("sync", "fig6_sync_errors.png", "Synchronization error of each motor (cf. Fig. 6)",
             ("es1 [um]", "es2 [um]", "es3 [um]"), (1e6,) * 3),
            ("axis", "fig7_axis_errors.png", "Tracking error of each drive axis (cf. Fig. 7)",
             ("X [um]", "Z [um]", "B [urad]"), (1e6,) * 3)):
        fig, axes = plt.subplots(3, 1, figsize=(8, 8), sharex=True)
        for run, sig in runs.items():
            for i in range(3):
                axes[i].plot(sig["time"], sig[key][:, i] * scale[i], label=_LABELS.get(run, run), lw=0.8)
        for i in range(3):
            axes[i].set_ylabel(ylabels[i])
            axes[i].grid(True, alpha=0.3)
        axes[0].legend(loc="upper right")
        axes[-1].set_xlabel("time [s]")
        fig.suptitle(title)
        written.append(_save(fig, folder / name))
    return written


def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
