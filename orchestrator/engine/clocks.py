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
  h_k = t_{k+1} - t_k (libcosim's ``to_double_duration``). An int64 holds times up to
  (2^63 - 1) ns, about 9.22e9 s (292 years): a start or a step beyond it is refused
  (:func:`nanoseconds_problem`), never wrapped around.
"""

import math

CLOCKS = ("exact", "accumulated", "nanoseconds")
INT64_MAX = 2**63 - 1  # the nanosecond clock's counter, as in libcosim and the compiled core (stepper.c)


def nanoseconds_problem(t0: float, h: float, n_steps: int | None = None) -> str | None:
    """Why the nanosecond clock cannot represent a run from ``t0`` [s] in steps of ``h`` [s]
    (``n_steps`` of them if given, else only the start), as "KEY = VALUE is invalid ..." text;
    None if every t_k is an int64 count of nanoseconds (|T0 + k H| <= 2^63 - 1)."""
    limit = f"allowed are times within +-{INT64_MAX / 1e9:.10g} s (an int64 count of nanoseconds), or another clock"
    if not (math.isfinite(t0) and abs(t0 * 1e9) < 2.0**63):
        return f"start_time = {t0!r} s is invalid for clock = 'nanoseconds': {limit}"
    t0_ns, h_ns = math.trunc(t0 * 1e9), math.trunc(h * 1e9) if math.isfinite(h) else 2**63
    if h_ns < 1:
        return f"step = {h!r} s is invalid for clock = 'nanoseconds': allowed is a step of at least 1e-9 s"
    if n_steps is not None and t0_ns + n_steps * h_ns > INT64_MAX:
        end = (t0_ns + n_steps * h_ns) / 1e9
        return (f"stop_time = {end!r} s is invalid for clock = 'nanoseconds' (start_time {t0!r} s + {n_steps} steps "
                f"of {h!r} s): {limit}")
    return None


class Clock:
    """t_k and h_k of one clock; ``kind`` is one of :data:`CLOCKS`."""

    def __init__(self, kind: str, t0: float, h: float):
        if kind not in CLOCKS:
            raise ValueError(f"clock = {kind!r} is invalid: allowed are {', '.join(CLOCKS)}")
        self.kind, self.t0, self.h = kind, float(t0), float(h)
        self.last_k = None  # the last step whose t_k the clock can represent; None: no limit
        if kind == "nanoseconds":
            problem = nanoseconds_problem(self.t0, self.h)
            if problem:
                raise ValueError(problem)
            self._t0_ns, self._h_ns = math.trunc(self.t0 * 1e9), math.trunc(self.h * 1e9)
            self.last_k = (INT64_MAX - self._t0_ns) // self._h_ns
        self._acc_k, self._acc_t = 0, self.t0  # accumulated: last computed (k, t_k)

    def require_steps(self, k_end: int) -> None:
        """ValueError (the text of nanoseconds_problem) unless t_k is representable up to step ``k_end``."""
        if self.last_k is not None and k_end > self.last_k:
            raise ValueError(nanoseconds_problem(self.t0, self.h, k_end))

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
