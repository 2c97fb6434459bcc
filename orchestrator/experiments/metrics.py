"""Error metrics in the units of the paper's Tables 1-6.

Tracking error of motor i: e_i = q_di - q_i with the plant's true position q_i
(the encoder reading is what the controller sees; accuracy is judged on the true
motion). Synchronization errors follow Eq. 18. Axis errors are X_d - X, Z_d - Z
in um and B_d - B in urad. MAE = mean |e|; STD = population standard deviation.
"""

import numpy as np

_GROUPS = ("tracking", "sync", "axis")


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


class ErrorStatistics:
    """MAE and population STD of the error signals, accumulated block by block.

    A run streams its rows through :meth:`add` in blocks of any size, so memory stays
    bounded however long the run; per-block means and sums of squared deviations are
    combined with Chan et al.'s pairwise update, which keeps the STD accurate (no
    E[e^2] - E[e]^2 cancellation).
    """

    def __init__(self, columns: list[str]):
        self.columns = list(columns)
        self.n = 0
        self.abs_sum = {g: np.zeros(3) for g in _GROUPS}
        self.mean = {g: np.zeros(3) for g in _GROUPS}
        self.m2 = {g: np.zeros(3) for g in _GROUPS}

    def add(self, rows) -> None:
        """Accumulate a block of result rows (a 2-D array or a list of rows)."""
        data = np.asarray(rows, dtype=float)
        if data.size == 0:
            return
        signals = error_signals(self.columns, data.reshape(-1, len(self.columns)))
        nb = signals["time"].shape[0]
        n = self.n + nb
        for g in _GROUPS:
            x = signals[g]
            mb = x.mean(0)
            delta = mb - self.mean[g]
            self.abs_sum[g] += np.abs(x).sum(0)
            self.m2[g] += ((x - mb) ** 2).sum(0) + delta ** 2 * self.n * nb / n
            self.mean[g] += delta * nb / n
        self.n = n

    def result(self) -> dict:
        """metrics.json content: lists for (q1, q2, q3) and (X um, Z um, B urad)."""
        um = 1e6
        mae = {g: (self.abs_sum[g] / self.n * um).tolist() for g in _GROUPS}
        std = {g: (np.sqrt(self.m2[g] / self.n) * um).tolist() for g in _GROUPS}
        return {
            "tracking_mae_um": mae["tracking"], "tracking_std_um": std["tracking"],
            "sync_mae_um": mae["sync"], "sync_std_um": std["sync"],
            "axis_mae": mae["axis"], "axis_std": std["axis"],
            "units": {"tracking": "um", "sync": "um", "axis": ["um", "um", "urad"]},
            "samples": int(self.n),
        }


def compute(columns: list[str], data: np.ndarray) -> dict:
    """metrics.json content of a whole results table (see ErrorStatistics.result)."""
    stats = ErrorStatistics(columns)
    stats.add(data)
    return stats.result()
