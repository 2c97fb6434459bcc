"""Error metrics in the units of the paper's Tables 1-6.

Tracking error of motor i: e_i = q_di - q_i with the plant's true position q_i
(the encoder reading is what the controller sees; accuracy is judged on the true
motion). Synchronization errors follow Eq. 18. Axis errors are X_d - X, Z_d - Z
in um and B_d - B in urad. MAE = mean |e|; STD = population standard deviation; the tracking
error's signed mean per motor (tracking_mean_um) is its steady offset.
Saturation of motor i: the share of samples whose force command |F_i| (the controller's
output) is at the force limit (the plant's force_limit; the controller's if the plant's is 0).
Effort: the RMS of each motor's force command above EFFORT_HZ (after a 4th-order Butterworth
high-pass, started at rest on the first command), the part of the force that follows
quantization, noise and cogging rather than the reference, whose content is below 1 Hz.
Response to a force step (plant.disturbance_force_i from plant.disturbance_time on): the
change of the mean tracking error from the window before the step to the last window of the
run (each RESPONSE_WINDOW long, or what the run has), per motor and for the common mode
(the mean over the motors), and the peak change after the step.
A point-to-point run (trajectory profile 1-3) also gets the move metrics (MoveMetrics):
rise time, overshoot, settling times into bands, peak error while moving and the error at
constant velocity, per axis and motor.
"""

import numpy as np

from tapmp.interface import CONTROLLER_VARS, PLANT_VARS

_GROUPS = ("tracking", "sync", "axis")
_FORCES = tuple(f"controller.F{i}" for i in (1, 2, 3))
AT_LIMIT = 1e-9  # |F| >= (1 - AT_LIMIT) force_limit counts as at the limit (a clipped value, to rounding)
RESPONSE_WINDOW = 0.1  # [s] the windows before a force step and at the end of the run
EFFORT_HZ = 100.0  # [Hz] the force RMS above this frequency is the effort metric (module doc)
# The metrics.json keys of each error quantity: (STD, MAE), each a list over the columns.
METRIC_KEYS = {"tracking": ("tracking_std_um", "tracking_mae_um"), "sync": ("sync_std_um", "sync_mae_um"),
               "axis": ("axis_std", "axis_mae")}
# The columns and units of each quantity, as the paper's tables lay them out (um, urad for B).
QUANTITIES = {"tracking": (("q1", "q2", "q3"), ("um", "um", "um")), "sync": (("q1", "q2", "q3"), ("um", "um", "um")),
              "axis": (("X", "Z", "B"), ("um", "um", "urad"))}


def reduction(base: float, new: float) -> float:
    """Reduction of ``new`` relative to ``base`` in percent, 100 (base - new) / base (NaN if
    ``base`` is 0): the formula of the paper's "Reduction (%)" rows with base APD-DC."""
    return 100.0 * (base - new) / base if base else float("nan")


def reductions(base: dict, new: dict) -> dict[str, list[float]]:
    """{metrics.json key: [reduction per motor or axis, %]} of the metrics ``new`` against
    ``base`` (two metrics.json dicts) for every key of METRIC_KEYS."""
    return {k: [reduction(b, n) for b, n in zip(base[k], new[k])] for pair in METRIC_KEYS.values() for k in pair}


class _HighPassRms:
    """RMS [N] of three force channels above EFFORT_HZ, streamed block by block (highpass.HighPassRms;
    the step from the first two time stamps)."""

    def __init__(self):
        self.filter = self.x0 = None
        self.pending = None

    def add(self, time: np.ndarray, forces: np.ndarray) -> None:
        if self.pending is not None:
            time, forces = np.concatenate([self.pending[0], time]), np.vstack([self.pending[1], forces])
            self.pending = None
        if self.filter is None:
            if len(time) < 2:
                self.pending = (time, forces)
                return
            step = float(time[1] - time[0])
            if not 0.5 / step > EFFORT_HZ:
                self.filter = False  # the sample rate cannot resolve the band
                return
            from .highpass import HighPassRms, butter_highpass_sos
            self.filter = HighPassRms(butter_highpass_sos(4, EFFORT_HZ, 1.0 / step), forces.shape[1])
            # Started at rest on the first sample: the filter sees the forces less their first value,
            # from a zero state. For a high-pass (zero gain at 0 Hz) that is the steady state on the
            # first sample.
            self.x0 = np.array(forces[0], dtype=float)
        if self.filter is False:
            return
        self.filter.add(forces - self.x0)

    def result(self):
        return self.filter.result() if self.filter else None


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

    def __init__(self, columns: list[str], force_limit: float = 0.0, step: tuple[float, float] | None = None,
                 move: "MoveSpec | None" = None):
        self.columns = list(columns)
        # step: (disturbance_time, stop_time) [s] of a force step (force_step), None if there is none
        self.response = _StepResponse(*step) if step is not None else None
        # a point-to-point run (move = its MoveSpec) also gets the move metrics under "move"
        self.move = MoveMetrics(self.columns, move) if move is not None else None
        self.force_limit = float(force_limit)  # [N]; 0: no saturation is counted
        self.saturated = np.zeros(3, dtype=np.int64)  # samples with |F_i| at the limit
        self._forces = [self.columns.index(c) for c in _FORCES] if set(_FORCES) <= set(self.columns) else None
        self.effort = _HighPassRms()
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
        if self.move is not None:
            self.move.add(data)
        if self.missing:
            self.n += data.shape[0]
            return
        signals = error_signals(self.columns, data)
        if self.response is not None:
            self.response.add(signals["time"], signals["tracking"])
        if self.force_limit > 0.0 and self._forces is not None:
            at_limit = np.abs(data[:, self._forces]) >= self.force_limit * (1.0 - AT_LIMIT)
            self.saturated += at_limit.sum(0)
        if self._forces is not None:
            self.effort.add(signals["time"], data[:, self._forces])
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
        move = {"move": self.move.result()} if self.move is not None else {}
        mae = {g: (self.abs_sum[g] / self.n * um).tolist() for g in _GROUPS}
        std = {g: (np.sqrt(self.m2[g] / self.n) * um).tolist() for g in _GROUPS}
        out = {
            "tracking_mae_um": mae["tracking"], "tracking_std_um": std["tracking"],
            "tracking_mean_um": (self.mean["tracking"] * um).tolist(),  # signed: the steady offset
            "sync_mae_um": mae["sync"], "sync_std_um": std["sync"],
            "axis_mae": mae["axis"], "axis_std": std["axis"],
            "units": {"tracking": "um", "sync": "um", "axis": ["um", "um", "urad"]},
            "samples": int(self.n),
            "saturation_fraction": (self.saturated / max(self.n, 1)).tolist(),
            "force_limit_n": self.force_limit,
            "force_rms_above_hz": EFFORT_HZ, "force_hf_rms_n": self.effort.result(),
            **move,
        }
        if self.response is not None:
            out["force_step"] = self.response.result()
        return out


def compute(columns: list[str], data: np.ndarray, force_limit: float = 0.0, move: "MoveSpec | None" = None) -> dict:
    """metrics.json content of a whole results table (see ErrorStatistics.result)."""
    stats = ErrorStatistics(columns, force_limit, move=move)
    stats.add(data)
    return stats.result()


# --- point-to-point moves -------------------------------------------------------------------

SETTLING_BANDS = (1e-6, 1e-7)  # default settling bands [m for X, Z and the motors; rad for B]
CHANNELS = ("X", "Z", "B", "q1", "q2", "q3")
_ACTUAL = ("plant.X", "plant.Z", "plant.B", "plant.q1_true", "plant.q2_true", "plant.q3_true")
_REFERENCE = ("trajectory.X_d", "trajectory.Z_d", "trajectory.B_d",
              "trajectory.q1_d", "trajectory.q2_d", "trajectory.q3_d")
PROFILE_NAMES = {1: "step", 2: "ramp", 3: "s-curve"}


class MoveSpec:
    """What the move metrics need to know of a point-to-point run: per channel (X, Z, B, q1, q2,
    q3) the start and end value [m, rad], the move's start t0 and end t1 [s], the constant-velocity
    window per channel ((start, end) [s] or None) and the settling bands."""

    def __init__(self, tp, L_1: float, bands=SETTLING_BANDS):
        from tapmp.kinematics import inverse
        from tapmp.trajectory import move_duration, move_plan
        self.profile = tp.profile
        self.t0 = tp.t_move
        self.t1 = tp.t_move + move_duration(tp)
        a = (tp.X_a, tp.Z_a, tp.B_a)
        b = (tp.X_b, tp.Z_b, tp.B_b)
        self.start = (*a, *inverse(*a, L_1))
        self.end = (*b, *inverse(*b, L_1))
        self.bands = tuple(float(x) for x in bands)
        windows = []
        if tp.profile in (2, 3):
            for p in move_plan(tp):
                windows.append(None if p.D == 0.0 or p.Tv <= 0.0 else
                               (tp.t_move + (p.Ta if tp.profile == 3 else 0.0),
                                tp.t_move + (p.Ta if tp.profile == 3 else 0.0) + p.Tv))
        else:
            windows = [None, None, None]
        moving = [w for w, p in zip(windows, move_plan(tp)) if p.D != 0.0] if tp.profile in (2, 3) else []
        # a motor moves at constant velocity while every moving axis does
        if moving and all(w is not None for w in moving):
            lo, hi = max(w[0] for w in moving), min(w[1] for w in moving)
            joint = (lo, hi) if hi > lo else None
        else:
            joint = None
        self.cruise = (*windows, joint, joint, joint)


def move_spec(parameters: dict, bands=SETTLING_BANDS):
    """The MoveSpec of a run from its FMU parameters by element ({"trajectory": {...}}), or None
    if its trajectory is not a point-to-point move (profile 0)."""
    from tapmp.params import PAPER_MODEL
    from tapmp.trajectory import TrajectoryParams
    tr = parameters.get("trajectory", {})
    tp = TrajectoryParams(*(tr.get(n, d) for n, d in zip(TrajectoryParams._fields, TrajectoryParams())))
    if not tp.profile:
        return None
    return MoveSpec(tp, tr.get("L_1", PAPER_MODEL.L_1), bands)


class MoveMetrics:
    """Rise time, overshoot, settling times, peak error while moving and error at constant
    velocity of a point-to-point run, per channel (X, Z, B, q1, q2, q3), streamed block by block.

    For a channel with start value a and end value b (d = b - a, s = sign d):
    * rise time [s]: from the first time the true value y passes a + 0.1 d to the first time it
      passes a + 0.9 d (linear interpolation between samples); None for d = 0;
    * overshoot: the largest s (y - b) after the move started, >= 0, in um (urad for B) and in
      % of |d|;
    * settling time into each band [s]: from the end of the reference move to the first sample
      from which on |y - b| <= band for the rest of the run (0 if it never leaves the band after
      the reference ends, None if it is outside at the last sample);
    * peak error while moving: max |r - y| (r the reference) from the start to the end of the
      reference move [um, urad];
    * error at constant velocity: max |r - y| and the mean of r - y while the reference moves at
      constant velocity (for a motor: while every moving axis does) [um, urad]; None without such
      a phase (a step, or an S-curve that never reaches v_max).
    """

    def __init__(self, columns: list[str], spec: MoveSpec):
        self.spec = spec
        self.missing = [c for c in ("time", *_ACTUAL, *_REFERENCE) if c not in columns]
        col = {name: i for i, name in enumerate(columns)}
        self._cols = None if self.missing else (col["time"], [col[c] for c in _ACTUAL], [col[c] for c in _REFERENCE])
        self.width = len(columns)
        n = len(CHANNELS)
        self.prev = None  # (t, y) of the last sample
        self.t10 = [None] * n
        self.t90 = [None] * n
        self.overshoot = np.zeros(n)
        self.settled_from = [[None] * len(spec.bands) for _ in range(n)]  # first sample time after a violation
        self.violation = [[False] * len(spec.bands) for _ in range(n)]   # the last sample was outside
        self.peak_moving = np.zeros(n)
        self.cruise_max = np.zeros(n)
        self.cruise_sum = np.zeros(n)
        self.cruise_n = np.zeros(n, dtype=np.int64)
        self.last_t = None

    def add(self, rows) -> None:
        """Accumulate a block of result rows (a 2-D array with the run's columns)."""
        if self._cols is None:
            return
        data = np.asarray(rows, dtype=float).reshape(-1, self.width)
        if data.size == 0:
            return
        ti, ai, ri = self._cols
        t = data[:, ti]
        y = data[:, ai]
        r = data[:, ri]
        sp = self.spec
        a, b = np.array(sp.start), np.array(sp.end)
        d = b - a
        after = t >= sp.t0
        moving = after & (t <= sp.t1)
        err = np.abs(r - y)
        for c in range(len(CHANNELS)):
            yc = y[:, c]
            if d[c] != 0.0:
                frac = (yc - a[c]) / d[c]
                for level, store in ((0.1, self.t10), (0.9, self.t90)):
                    if store[c] is None:
                        store[c] = self._crossing(t, frac, level, c)
                s = 1.0 if d[c] > 0 else -1.0
                if after.any():
                    self.overshoot[c] = max(self.overshoot[c], float(np.max(s * (yc[after] - b[c]))))
            if moving.any():
                self.peak_moving[c] = max(self.peak_moving[c], float(err[moving, c].max()))
            w = sp.cruise[c]
            if w is not None:
                inside = (t >= w[0]) & (t <= w[1])
                if inside.any():
                    self.cruise_max[c] = max(self.cruise_max[c], float(err[inside, c].max()))
                    self.cruise_sum[c] += float((r[inside, c] - yc[inside]).sum())
                    self.cruise_n[c] += int(inside.sum())
            dev = np.abs(yc - b[c])
            for k, band in enumerate(sp.bands):
                out = np.nonzero(after & (dev > band))[0]
                if len(out):
                    last = out[-1]
                    if last + 1 < len(t):
                        self.settled_from[c][k] = float(t[last + 1])
                        self.violation[c][k] = False
                    else:
                        self.violation[c][k] = True
                elif after.any() and self.violation[c][k]:  # outside at the end of the previous block
                    self.settled_from[c][k] = float(t[np.nonzero(after)[0][0]])
                    self.violation[c][k] = False
        self.prev = (float(t[-1]), y[-1].copy())
        self.last_t = float(t[-1])

    def _crossing(self, t, frac, level, c):
        """Time [s] at which frac first reaches level in this block (interpolated), else None."""
        idx = np.nonzero(frac >= level)[0]
        if not len(idx):
            return None
        k = idx[0]
        if k == 0:
            if self.prev is None:
                return float(t[0])
            t0, f0 = self.prev[0], (self.prev[1][c] - self.spec.start[c]) / (self.spec.end[c] - self.spec.start[c])
        else:
            t0, f0 = float(t[k - 1]), float(frac[k - 1])
        t1, f1 = float(t[k]), float(frac[k])
        return t0 + (level - f0) / (f1 - f0) * (t1 - t0) if f1 != f0 else t1

    def result(self) -> dict:
        """The "move" entry of metrics.json."""
        sp = self.spec
        if self.missing:
            return {"not_computed": "the system has no column " + ", ".join(self.missing)}
        d = np.array(sp.end) - np.array(sp.start)
        channels = {}
        for c, name in enumerate(CHANNELS):
            rise = (self.t90[c] - self.t10[c]) if self.t10[c] is not None and self.t90[c] is not None else None
            settling = {}
            for k, band in enumerate(sp.bands):
                if self.violation[c][k]:
                    settling[f"{band:g}"] = None
                else:
                    start = self.settled_from[c][k]
                    settling[f"{band:g}"] = 0.0 if start is None else max(start - sp.t1, 0.0)
            channels[name] = {
                "distance": float(d[c]),
                "rise_time_s": rise,
                "overshoot": float(self.overshoot[c]) * 1e6,
                "overshoot_percent": 100.0 * float(self.overshoot[c]) / abs(d[c]) if d[c] else None,
                "settling_time_s": settling,
                "peak_error_moving": float(self.peak_moving[c]) * 1e6,
                "cruise_error_max": float(self.cruise_max[c]) * 1e6 if self.cruise_n[c] else None,
                "cruise_error_mean": float(self.cruise_sum[c] / self.cruise_n[c]) * 1e6 if self.cruise_n[c] else None,
            }
        return {"profile": PROFILE_NAMES.get(sp.profile, str(sp.profile)), "t_move_s": sp.t0, "t_end_s": sp.t1,
                "bands": list(sp.bands), "channels": channels,
                "units": {"distance": "m (B: rad)", "overshoot": "um (B: urad)",
                          "peak_error_moving": "um (B: urad)", "cruise_error_max": "um (B: urad)",
                          "cruise_error_mean": "um (B: urad)", "bands": "m (B: rad)",
                          "settling_time_s": "s after the end of the reference move"}}


# --- limit cycles (hunting) while holding still ------------------------------------------------

def limit_cycle(time: np.ndarray, x: np.ndarray) -> dict:
    """The limit cycle of each column of ``x`` (samples at ``time`` [s], e.g. one window of a hold).

    The straight line fitted to a column is taken out first (a slow drift toward rest is no cycle).
    Of what remains: ``amplitude``, half its peak-to-peak, in x's unit; ``period_s``, the mean time
    between its rises from below mid - amplitude/2 to above mid + amplitude/2 (mid the centre of its
    range: a Schmitt trigger, so that a chatter smaller than half the cycle counts no cycle), None
    with fewer than two such rises; ``cycles``, the number of rises; ``mean``, the column's mean (its steady
    offset)."""
    t = np.asarray(time, dtype=float)
    x = np.asarray(x, dtype=float).reshape(len(t), -1)
    out = {"amplitude": [], "period_s": [], "cycles": [], "mean": []}
    for col in x.T:
        r = col - np.polyval(np.polyfit(t, col, 1), t) if len(t) > 1 else col - col.mean()
        hi, lo = float(r.max()), float(r.min())
        amplitude, mid = (hi - lo) / 2.0, (hi + lo) / 2.0
        state, rises = 0, []  # state: -1 below the low level, 1 above the high one
        for tk, v in zip(t, r):
            if v <= mid - amplitude / 2.0:
                state = -1
            elif v >= mid + amplitude / 2.0:
                if state == -1:
                    rises.append(float(tk))
                state = 1
        out["amplitude"].append(amplitude)
        out["period_s"].append(float(np.mean(np.diff(rises))) if len(rises) > 1 and amplitude > 0.0 else None)
        out["cycles"].append(len(rises) if amplitude > 0.0 else 0)
        out["mean"].append(float(col.mean()))
    return out


def hold_cycles(columns: list[str], data: np.ndarray, t_from: float) -> dict:
    """Hunting in a results table from t_from [s] on (e.g. the last half of a hold): the limit cycle
    (limit_cycle) of each motor's true tracking error q_d - q_true [um] and force command F [N]."""
    col = {name: i for i, name in enumerate(columns)}
    rows = data[data[:, col["time"]] >= t_from]
    e = np.stack([rows[:, col[f"trajectory.q{i}_d"]] - rows[:, col[f"plant.q{i}_true"]] for i in (1, 2, 3)], axis=1)
    F = rows[:, [col[c] for c in _FORCES]]
    t = rows[:, col["time"]]
    return {"t_from_s": float(t_from), "tracking_um": limit_cycle(t, e * 1e6), "force_n": limit_cycle(t, F)}
