"""Communication clocks: how a fixed-step master turns step k into the doStep arguments.

Each returns, for macro step k, the communication point t_k [s] and the step size
h_k = t_{k+1} - t_k [s] that doStep(t_k, h_k) receives. On paper they are all
t0 + k h; in floating point they differ in the last bits, and a controller that
differentiates a quantized position amplifies that to ~1e-12 m within 0.2 s. Choosing
the clock of another master makes the orchestrator reproduce it bit for bit:

* ``exact`` (default): t_k = t0 + k h, h_k = h. Never accumulated.
* ``accumulated``: t_{k+1} = t_k + h, h_k = h, as FMPy's ``simulate_ssp`` and Ecos's
  fixed-step algorithm do (``time += step_size``).
* ``nanoseconds``: libcosim's clock: time is an int64 count of nanoseconds,
  t_k = (T0 + k H) / 1e9 with T0 = trunc(t0 1e9), H = trunc(h 1e9), and
  h_k = t_{k+1} - t_k (libcosim's ``to_double_duration``).
"""

import math

CLOCKS = ("exact", "accumulated", "nanoseconds")


class Clock:
    """t_k and h_k of one clock; ``kind`` is one of :data:`CLOCKS`."""

    def __init__(self, kind: str, t0: float, h: float):
        if kind not in CLOCKS:
            raise ValueError(f"clock = {kind!r} is invalid: allowed are {', '.join(CLOCKS)}")
        self.kind, self.t0, self.h = kind, float(t0), float(h)
        if kind == "nanoseconds":
            self._t0_ns, self._h_ns = math.trunc(self.t0 * 1e9), math.trunc(self.h * 1e9)
            if self._h_ns < 1:
                raise ValueError(f"step = {h!r} s is invalid for clock = 'nanoseconds': "
                                 "allowed is a step of at least 1e-9 s")
        self._acc_k, self._acc_t = 0, self.t0  # accumulated: last computed (k, t_k)

    def at(self, k: int) -> float:
        """Communication point t_k [s]."""
        if self.kind == "exact":
            return self.t0 + k * self.h
        if self.kind == "nanoseconds":
            return (self._t0_ns + k * self._h_ns) / 1e9
        if k < self._acc_k:  # replay from the start: sums are only defined forwards
            self._acc_k, self._acc_t = 0, self.t0
        while self._acc_k < k:
            self._acc_t += self.h
            self._acc_k += 1
        return self._acc_t

    def step(self, k: int) -> float:
        """Step size h_k [s] passed with doStep at t_k."""
        if self.kind == "nanoseconds":
            return self.at(k + 1) - self.at(k)
        return self.h
