"""Error metrics in the units of the paper's Tables 1-6.

Tracking error of motor i: e_i = q_di - q_i with the plant's true position q_i
(the encoder reading is what the controller sees; accuracy is judged on the true
motion). Synchronization errors follow Eq. 18. Axis errors are X_d - X, Z_d - Z
in um and B_d - B in urad. MAE = mean |e|; STD = population standard deviation.
Saturation of motor i: the share of samples whose force command |F_i| (the controller's
output) is at the force limit (the plant's force_limit; the controller's if the plant's is 0).
Response to a force step (plant.disturbance_force_i from plant.disturbance_time on): the
change of the mean tracking error from the window before the step to the last window of the
run (each RESPONSE_WINDOW long, or what the run has), per motor and for the common mode
(the mean over the motors), and the peak change after the step.
"""

import numpy as np

from tapmp.interface import CONTROLLER_VARS, PLANT_VARS

_GROUPS = ("tracking", "sync", "axis")
_FORCES = tuple(f"controller.F{i}" for i in (1, 2, 3))
AT_LIMIT = 1e-9  # |F| >= (1 - AT_LIMIT) force_limit counts as at the limit (a clipped value, to rounding)
RESPONSE_WINDOW = 0.1  # [s] the windows before a force step and at the end of the run


def saturation_limit(parameters: dict) -> float:
    """The force limit [N] saturation is measured against, from the FMU parameters by element
    ({"plant": {...}, "controller": {...}}): the plant's force_limit (its FMU default if not
    set), else the controller's; 0 if both are 0 (no saturation)."""
    limits = []
    for element, variables in (("plant", PLANT_VARS), ("controller", CONTROLLER_VARS)):
        default = next(v.start for v in variables if v.name == "force_limit")
        limits.append(float(parameters.get(element, {}).get("force_limit", default)))
    return limits[0] if limits[0] > 0.0 else limits[1]


def force_step(parameters: dict, start_time: float, stop_time: float) -> tuple[float, float] | None:
    """(disturbance_time, stop_time) [s] of the plant's force step from the FMU parameters by
    element, or None if no disturbance force is set."""
    plant = parameters.get("plant", {})
    if not any(float(plant.get(f"disturbance_force{i}", 0.0)) for i in (1, 2, 3)):
        return None
    return float(plant.get("disturbance_time", 0.0)), float(stop_time)


class _StepResponse:
    """Mean tracking error before a force step and in the run's last window, and the peak
    change after the step, accumulated over time-ordered blocks (see the module doc)."""

    def __init__(self, t_step: float, t_end: float):
        self.t_step, self.t_end = t_step, t_end
        self.sums = {"before": np.zeros(3), "end": np.zeros(3)}
        self.counts = {"before": 0, "end": 0}
        self.peak = np.zeros(3)

    def add(self, t: np.ndarray, e: np.ndarray) -> None:
        before = (t >= self.t_step - RESPONSE_WINDOW) & (t < self.t_step)
        end = t >= self.t_end - RESPONSE_WINDOW
        for name, mask in (("before", before), ("end", end)):
            self.sums[name] += e[mask].sum(0)
            self.counts[name] += int(mask.sum())
        after = t >= self.t_step
        if after.any():
            ref = self._before()
            self.peak = np.maximum(self.peak, np.abs(e[after] - ref).max(0))

    def _before(self) -> np.ndarray:
        # a step at the start of the run has no window before it: the change is from zero error
        return self.sums["before"] / self.counts["before"] if self.counts["before"] else np.zeros(3)

    def result(self) -> dict:
        um = 1e6
        end = self.sums["end"] / max(self.counts["end"], 1)
        change = (end - self._before()) * um
        return {"disturbance_time_s": self.t_step, "window_s": RESPONSE_WINDOW,
                "error_change_um": change.tolist(), "common_mode_change_um": float(change.mean()),
                "peak_error_change_um": (self.peak * um).tolist()}


REQUIRED = ("time", *(f"trajectory.q{i}_d" for i in (1, 2, 3)), *(f"plant.q{i}_true" for i in (1, 2, 3)),
            "trajectory.X_d", "trajectory.Z_d", "trajectory.B_d", "plant.X", "plant.Z", "plant.B")


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

    def __init__(self, columns: list[str], force_limit: float = 0.0, step: tuple[float, float] | None = None):
        self.columns = list(columns)
        # step: (disturbance_time, stop_time) [s] of a force step (force_step), None if there is none
        self.response = _StepResponse(*step) if step is not None else None
        self.force_limit = float(force_limit)  # [N]; 0: no saturation is counted
        self.saturated = np.zeros(3, dtype=np.int64)  # samples with |F_i| at the limit
        self._forces = [self.columns.index(c) for c in _FORCES] if set(_FORCES) <= set(self.columns) else None
        # A system without the TAPMP plant and trajectory (e.g. the user's own plant FMU) runs,
        # but its errors cannot be computed: metrics.json says which columns are missing.
        self.missing = [c for c in REQUIRED if c not in self.columns]
        self.n = 0
        self.abs_sum = {g: np.zeros(3) for g in _GROUPS}
        self.mean = {g: np.zeros(3) for g in _GROUPS}
        self.m2 = {g: np.zeros(3) for g in _GROUPS}

    def add(self, rows) -> None:
        """Accumulate a block of result rows (a 2-D array or a list of rows)."""
        data = np.asarray(rows, dtype=float)
        if data.size == 0:
            return
        data = data.reshape(-1, len(self.columns))
        if self.missing:
            self.n += data.shape[0]
            return
        signals = error_signals(self.columns, data)
        if self.response is not None:
            self.response.add(signals["time"], signals["tracking"])
        if self.force_limit > 0.0 and self._forces is not None:
            at_limit = np.abs(data[:, self._forces]) >= self.force_limit * (1.0 - AT_LIMIT)
            self.saturated += at_limit.sum(0)
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
        """metrics.json content: lists for (q1, q2, q3) and (X um, Z um, B urad); saturation_fraction
    per motor (0 to 1) against force_limit_n [N]."""
        if self.missing:
            return {"samples": int(self.n), "not_computed": (
                "the system has no column " + ", ".join(self.missing) + ": tracking, synchronization and axis "
                "errors need the TAPMP plant and trajectory elements (recorded as plant.* and trajectory.*)")}
        um = 1e6
        mae = {g: (self.abs_sum[g] / self.n * um).tolist() for g in _GROUPS}
        std = {g: (np.sqrt(self.m2[g] / self.n) * um).tolist() for g in _GROUPS}
        out = {
            "tracking_mae_um": mae["tracking"], "tracking_std_um": std["tracking"],
            "sync_mae_um": mae["sync"], "sync_std_um": std["sync"],
            "axis_mae": mae["axis"], "axis_std": std["axis"],
            "units": {"tracking": "um", "sync": "um", "axis": ["um", "um", "urad"]},
            "samples": int(self.n),
            "saturation_fraction": (self.saturated / max(self.n, 1)).tolist(),
            "force_limit_n": self.force_limit,
        }
        if self.response is not None:
            out["force_step"] = self.response.result()
        return out


def compute(columns: list[str], data: np.ndarray, force_limit: float = 0.0) -> dict:
    """metrics.json content of a whole results table (see ErrorStatistics.result)."""
    stats = ErrorStatistics(columns, force_limit)
    stats.add(data)
    return stats.result()
