"""Error metrics in the units of the paper's Tables 1-6.

Tracking error of motor i: e_i = q_di - q_i with the plant's true position q_i
(the encoder reading is what the controller sees; accuracy is judged on the true
motion). Synchronization errors follow Eq. 18. Axis errors are X_d - X, Z_d - Z
in um and B_d - B in urad. MAE = mean |e|; STD = population standard deviation.
"""

import numpy as np


def error_signals(columns: list[str], data: np.ndarray) -> dict[str, np.ndarray]:
    """Tracking, synchronization and axis errors [m, m, (m, m, rad)] from a results table."""
    col = {name: i for i, name in enumerate(columns)}

    def c(name):
        return data[:, col[name]]

    e = np.stack([c(f"trajectory.q{i}_d") - c(f"plant.q{i}_true") for i in (1, 2, 3)], axis=1)
    es = np.stack([e[:, 0] - e[:, 1], e[:, 1] - e[:, 2], e[:, 2] - e[:, 0]], axis=1)
    axis = np.stack([c("trajectory.X_d") - c("plant.X"), c("trajectory.Z_d") - c("plant.Z"),
                     c("trajectory.B_d") - c("plant.B")], axis=1)
    return {"time": c("time"), "tracking": e, "sync": es, "axis": axis}


def compute(columns: list[str], data: np.ndarray) -> dict:
    """metrics.json content: lists for (q1, q2, q3) and (X um, Z um, B urad)."""
    s = error_signals(columns, data)
    um = 1e6
    return {
        "tracking_mae_um": (np.abs(s["tracking"]).mean(0) * um).tolist(),
        "tracking_std_um": (s["tracking"].std(0) * um).tolist(),
        "sync_mae_um": (np.abs(s["sync"]).mean(0) * um).tolist(),
        "sync_std_um": (s["sync"].std(0) * um).tolist(),
        "axis_mae": (np.abs(s["axis"]).mean(0) * um).tolist(),
        "axis_std": (s["axis"].std(0) * um).tolist(),
        "units": {"tracking": "um", "sync": "um", "axis": ["um", "um", "urad"]},
        "samples": int(data.shape[0]),
    }
