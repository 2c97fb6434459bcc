"""Paced (real-time) runs: the compiled stepping core keeps every macro step to the wall clock.

Schedule (stepper.c): the run starts at wall time W0 (CLOCK_MONOTONIC); the step that reaches
communication point j (counted from the run's first paced point) has its deadline
W0 + j h / factor, an absolute grid that cannot drift. A step starts at its release (the previous
step's deadline, or at once if that has passed), runs, and its lateness is its completion minus its
deadline (negative: early); an overrun is a lateness > 0. The overrun policies: ``continue`` keeps
the grid (late steps run back to back until caught up), ``skip`` releases the step after an overrun
at the next grid slot still in the future (the missed slots are dropped: the rows are the same, the
run takes longer), ``abort`` stops the run at the first overrun.

The whole run is one call into C on a thread of its own, without the GIL: the rows go into a ring
of blocks that the calling thread reads (recording, metrics, progress), so no Python runs between
two steps. Statistics are kept in C (log-linear histograms of lateness and execution time, exact
extremes, overrun counts, the worst lateness per window of steps); per-step arrays only if asked.

Real-time measures (:func:`run_paced` applies them and undoes them at the end): mlockall, the
stepping thread pinned to one CPU, and SCHED_FIFO at a priority only if one is asked for (a
thread that spins at real-time priority can take a CPU from everything else). Each is reported
applied or not, with the reason.

Test hook, no user option: ``$TAPMP_REALTIME_INJECT`` = "STEP:SECONDS,..." makes the step that
reaches communication point STEP busy-wait SECONDS longer (tests/engine/test_pacing.py).
"""

import ctypes
import math
import os
import threading
import time
from ctypes import Structure, c_double, c_int32, c_int64, c_void_p
from dataclasses import dataclass

import numpy as np

from .errors import CoSimulationError
from . import stepper as stepper_core

OVERRUN_POLICIES = ("continue", "skip", "abort")
# Sleep until this long before a release, then spin (stepper.c wait_until). Measured on the 2-core VM
# of docs/performance.md ("Real time"): at SCHED_FIFO clock_nanosleep woke 37 us late at the median,
# 47 us at p90. Below the 100 us servo period on purpose: a thread that spins its whole period at
# SCHED_FIFO runs into the kernel's real-time throttling (50 ms taken away every second).
SPIN_MARGIN_S = 60e-6
HIST_BINS, FIRST_OVERRUNS = 1024, 16
RING_SLOTS, SLOT_STEPS = 64, 250  # ring of 16,000 steps: 1.6 s of a 0.1 ms run at factor 1
MAX_WINDOWS = 2000                # points of the lateness-over-time series
INJECT_ENV = "TAPMP_REALTIME_INJECT"


class RealTimeError(CoSimulationError):
    """A paced run that missed a deadline under the overrun policy abort."""

    def __init__(self, message: str, time: float, log: list[str]):
        super().__init__(message, None, time, log)


@dataclass(frozen=True)
class Pacing:
    """How a run is paced: ``factor`` simulated seconds per wall second (1: the wall clock, 0.5: half
    speed, 10: ten times faster), the ``overrun`` policy, the ``spin_margin`` [s] before a release
    that the core spins instead of sleeping, ``trace``: keep per-step arrays, ``rt_priority``: the
    SCHED_FIFO priority (1-99) of the stepping thread, None: not real-time scheduled."""

    factor: float = 1.0
    overrun: str = "continue"
    spin_margin: float = SPIN_MARGIN_S
    trace: bool = False
    rt_priority: int | None = None

    def checked(self) -> "Pacing":
        """Itself, or CoSimulationError naming the value that is invalid and what is allowed."""
        f = self.factor
        if isinstance(f, bool) or not isinstance(f, (int, float)) or not math.isfinite(f) or f <= 0:
            raise CoSimulationError(f"real-time factor = {f!r} is invalid: allowed is a finite number > 0 "
                                    "(1: the wall clock, 0.5: half speed, 10: ten times faster)")
        if self.overrun not in OVERRUN_POLICIES:
            raise CoSimulationError(f"overrun = {self.overrun!r} is invalid: allowed are {', '.join(OVERRUN_POLICIES)}")
        m = self.spin_margin
        if isinstance(m, bool) or not isinstance(m, (int, float)) or not 0 <= m <= 0.1:
            raise CoSimulationError(f"spin margin = {m!r} s is invalid: allowed is a number in [0, 0.1] s")
        p = self.rt_priority
        if p is not None and (isinstance(p, bool) or not isinstance(p, int) or not 1 <= p <= 99):
            raise CoSimulationError(f"rt-priority = {p!r} is invalid: allowed is an integer in [1, 99]")
        return self


class _Hist(Structure):
    _fields_ = [("n", c_int64), ("min", c_int64), ("max", c_int64),
                ("neg", c_int64 * HIST_BINS), ("pos", c_int64 * HIST_BINS)]


class Pace(Structure):
    """stepper.c's tapmp_pace: the schedule of a paced run and its statistics."""
    _fields_ = [("policy", c_int32), ("started", c_int32), ("period_ns", c_double), ("spin_ns", c_int64),
                ("t0_wall", c_int64), ("k0", c_int64), ("dropped", c_int64), ("release", c_int64),
                ("end", c_int64), ("due", c_int64), ("finish", c_int64), ("steps", c_int64), ("overruns", c_int64),
                ("longest_run", c_int64), ("current_run", c_int64), ("n_first", c_int64),
                ("first_k", c_int64 * FIRST_OVERRUNS), ("first_late", c_int64 * FIRST_OVERRUNS),
                ("ring_waits", c_int64), ("late", _Hist), ("exec", _Hist),
                ("window", c_int64), ("n_windows", c_int64), ("worst", c_void_p),
                ("trace_n", c_int64), ("trace_late", c_void_p), ("trace_exec", c_void_p),
                ("n_inject", c_int32), ("inject_k", c_void_p), ("inject_ns", c_void_p), ("stop", c_void_p)]


def injected(text: str | None = None) -> list[tuple[int, float]]:
    """The test hook's table [(communication point, extra seconds)] from ``text`` (default
    $TAPMP_REALTIME_INJECT), "STEP:SECONDS,..."; CoSimulationError if it cannot be read."""
    text = os.environ.get(INJECT_ENV, "") if text is None else text
    table = []
    for item in filter(None, (x.strip() for x in text.split(","))):
        try:
            k, sec = item.split(":")
            table.append((int(k), float(sec)))
        except ValueError:
            raise CoSimulationError(f"{INJECT_ENV} = {text!r} is invalid: allowed is STEP:SECONDS,... "
                                    "(a test hook)") from None
    return table


# --- histogram reading -------------------------------------------------------------------
def bin_range_ns(b: int) -> tuple[int, int]:
    """The magnitudes [lo, hi) [ns] of histogram bin ``b`` (stepper.c hist_bin)."""
    if b < 16:
        return b, b + 1
    e, sub = (b - 16) // 16 + 4, (b - 16) % 16
    return (16 + sub) << (e - 4), (17 + sub) << (e - 4)


def _ordered_bins(h: _Hist):
    """(count, lowest value, highest value) [ns] of the non-empty bins, in increasing value."""
    for b in range(HIST_BINS - 1, -1, -1):
        if h.neg[b]:
            lo, hi = bin_range_ns(b)
            yield h.neg[b], -(hi - 1), -lo
    for b in range(HIST_BINS):
        if h.pos[b]:
            lo, hi = bin_range_ns(b)
            yield h.pos[b], lo, hi - 1


def percentile_ns(h: _Hist, p: float) -> int:
    """The nearest-rank ``p``-quantile (0 < p <= 1) [ns] read from the histogram: the highest value of
    the bin holding rank ceil(p n), clamped to the exact extremes; so at most one bin width (< 1/16
    of the value, 1 ns below 16 ns) above the exact quantile."""
    rank, seen = max(1, math.ceil(p * h.n)), 0
    for count, _, top in _ordered_bins(h):
        seen += count
        if seen >= rank:
            return min(max(top, h.min), h.max)
    return h.max


def _summary(h: _Hist) -> dict:
    s = 1e-9
    if not h.n:
        return {"p50": None, "p99": None, "p999": None, "max": None, "min": None}
    return {"p50": percentile_ns(h, 0.5) * s, "p99": percentile_ns(h, 0.99) * s,
            "p999": percentile_ns(h, 0.999) * s, "max": h.max * s, "min": h.min * s}


def _bins(h: _Hist) -> list:
    return [[lo * 1e-9, hi * 1e-9, n] for n, lo, hi in _ordered_bins(h)]


# --- real-time measures --------------------------------------------------------------------
def _libc():
    return ctypes.CDLL(None, use_errno=True)


def _lock_memory() -> dict:
    try:
        libc = _libc()
        if libc.mlockall(3) == 0:  # MCL_CURRENT | MCL_FUTURE: no page fault inside a step
            return {"applied": True, "detail": "mlockall(MCL_CURRENT | MCL_FUTURE)"}
        return {"applied": False, "detail": f"mlockall refused: {os.strerror(ctypes.get_errno())}"}
    except (OSError, AttributeError) as err:
        return {"applied": False, "detail": f"mlockall unavailable: {err}"}


def _unlock_memory(measure: dict | None) -> None:
    if measure and measure["applied"]:
        _libc().munlockall()


def _reader_affinity(measures: dict) -> tuple:
    """On the recording (calling) thread: keep it off the CPU the stepping thread will have, the
    last one it may run on, so that the two never share a CPU; returns (that CPU or None, what undoes it)."""
    try:
        cpus = sorted(os.sched_getaffinity(0))
    except (OSError, AttributeError) as err:
        measures["cpu_affinity"] = {"applied": False, "detail": f"sched_getaffinity unavailable: {err}"}
        return None, ()
    if len(cpus) < 2:
        measures["cpu_affinity"] = {"applied": False, "detail": f"one CPU allowed ({cpus}): nothing to pin"}
        return None, ()
    try:
        os.sched_setaffinity(0, set(cpus[:-1]))  # pid 0: this thread only
    except OSError as err:
        measures["cpu_affinity"] = {"applied": False, "detail": f"sched_setaffinity refused: {err}"}
        return None, ()
    return cpus[-1], (lambda: os.sched_setaffinity(0, set(cpus)),)


def _thread_measures(pacing: Pacing, cpu, measures: dict) -> tuple:
    """In the stepping thread: pin it to ``cpu`` (None: not pinned) and SCHED_FIFO if asked; returns
    what undoes them."""
    undo = []
    if cpu is not None:
        try:
            cpus = os.sched_getaffinity(0)
            os.sched_setaffinity(0, {cpu})
            undo.append(lambda: os.sched_setaffinity(0, cpus))
            measures["cpu_affinity"] = {"applied": True, "detail": f"stepping thread on CPU {cpu}, the "
                                        "recording thread on the others"}
        except OSError as err:
            measures["cpu_affinity"] = {"applied": False, "detail": f"sched_setaffinity refused: {err}"}
    if pacing.rt_priority is None:
        measures["sched_fifo"] = {"applied": False, "detail": "not asked for (--rt-priority N): a thread "
                                  "spinning at real-time priority can starve the machine's other work"}
    else:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(pacing.rt_priority))
            undo.append(lambda: os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0)))
            measures["sched_fifo"] = {"applied": True, "detail": f"SCHED_FIFO priority {pacing.rt_priority} "
                                      "(stepping thread)"}
        except (OSError, AttributeError) as err:
            measures["sched_fifo"] = {"applied": False, "detail": f"sched_setscheduler refused: {err}"}
    return tuple(undo)


# --- the paced run ---------------------------------------------------------------------------
def run_paced(sim, n: int, pacing: Pacing, consume, stopped) -> dict:
    """Step the open co-simulation ``sim`` (master.CoSimulation) ``n`` times paced by ``pacing``;
    every row (an array of rows, in order) is handed to ``consume`` on the calling thread, which
    also polls ``stopped()`` (True: end before the next step). Returns the statistics
    (:func:`statistics`); raises what the co-simulation raises for a failed step (the rows before
    it consumed), RealTimeError at the first overrun with policy abort. A stop returns normally
    with fewer steps (sim.k says how many)."""
    pacing = pacing.checked()
    core = sim.compiled_core("real time")
    h = sim.clock.step(sim.k)
    pace = Pace(policy=OVERRUN_POLICIES.index(pacing.overrun), period_ns=h / pacing.factor * 1e9,
                spin_ns=round(pacing.spin_margin * 1e9))
    window = max(1, math.ceil(n / MAX_WINDOWS))
    worst = np.full(math.ceil(n / window) if n else 1, np.iinfo(np.int64).min, dtype=np.int64)
    trace = np.zeros((2, n if pacing.trace else 1), dtype=np.int64)
    table = injected()
    inject_k = np.array([k for k, _ in table] or [0], dtype=np.int64)
    inject_ns = np.array([round(s * 1e9) for _, s in table] or [0], dtype=np.int64)
    stop = c_int32(0)
    pace.window, pace.n_windows, pace.worst = window, len(worst), worst.ctypes.data
    if pacing.trace:
        pace.trace_n, pace.trace_late, pace.trace_exec = n, trace[0].ctypes.data, trace[1].ctypes.data
    pace.n_inject, pace.inject_k, pace.inject_ns = len(table), inject_k.ctypes.data, inject_ns.ctypes.data
    pace.stop = ctypes.addressof(stop)
    ring = np.empty((RING_SLOTS, SLOT_STEPS, len(sim.columns)))
    produced, consumed = c_int64(0), c_int64(0)
    measures = {}
    cpu, undo_reader = None, ()
    outcome = {}

    def stepping():
        undo = _thread_measures(pacing, cpu, measures)
        try:
            outcome["state"] = core.advance_paced(sim.k, n, pace, ring, SLOT_STEPS, produced, consumed)
        except BaseException as err:  # handed to the calling thread
            outcome["error"] = err
        finally:
            for step in reversed(undo):
                step()

    thread = threading.Thread(target=stepping, name="tapmp-paced-stepping", daemon=True)
    taken = 0
    try:
        measures["mlockall"] = _lock_memory()
        cpu, undo_reader = _reader_affinity(measures)  # before the thread starts: it reads cpu
        thread.start()
        while thread.is_alive():
            if stopped():
                stop.value = 1
            taken = _take(ring, produced, consumed, taken, n, consume)
            time.sleep(0.002)  # the reader's poll: the ring holds 1.6 s at factor 1
        thread.join()
        taken = _take(ring, produced, consumed, taken, n, consume)
    finally:
        stop.value = 1
        if thread.ident is not None:  # started
            thread.join()
        _unlock_memory(measures.get("mlockall"))
        for step in undo_reader:
            step()
    if "error" in outcome:
        raise outcome["error"]
    s = outcome["state"]
    if s.outcome != stepper_core.DONE and s.rows:  # the unfinished block's rows
        consume(ring[taken % RING_SLOTS, :s.rows])
    sim.k = s.k
    stats = statistics(pace, pacing, h, pace.finish, measures, worst, trace if pacing.trace else None)
    try:
        if s.outcome == stepper_core.OVERRUN:
            step = int(pace.first_k[0])
            raise RealTimeError(f"real time: step {step} (to t = {sim.clock.at(step):.6g} s) finished "
                                f"{pace.first_late[0] * 1e-3:.1f} us after its deadline (overrun policy abort)",
                                sim.clock.at(step), list(sim.log))
        if s.outcome not in (stepper_core.DONE, stepper_core.STOPPED):
            sim.raise_outcome(s)
    except CoSimulationError as err:
        err.real_time = stats  # a failed paced run records its statistics too
        raise
    return stats


def _take(ring, produced, consumed, taken: int, n: int, consume) -> int:
    """Hand the whole blocks of the ring not taken yet to ``consume``; returns the blocks taken."""
    while taken < produced.value:
        rows = min(SLOT_STEPS, n - taken * SLOT_STEPS)
        consume(ring[taken % RING_SLOTS, :rows])
        taken += 1
        consumed.value = taken  # the slot may be written again
    return taken


def statistics(pace: Pace, pacing: Pacing, h: float, end_ns: int, measures: dict, worst, trace=None) -> dict:
    """The run.json record "real_time" of a paced run (times in seconds)."""
    steps = pace.steps
    wall = (end_ns - pace.t0_wall) * 1e-9 if pace.started else 0.0
    used = worst[:math.ceil(steps / pace.window)] if steps else worst[:0]
    out = {"factor": pacing.factor, "overrun_policy": pacing.overrun, "steps": steps, "period_s": h / pacing.factor,
           "spin_margin_s": pacing.spin_margin,
           "lateness_s": _summary(pace.late), "execution_s": _summary(pace.exec),
           "overruns": pace.overruns, "longest_overrun_run": pace.longest_run,
           "first_overruns": [{"step": int(pace.first_k[i]), "lateness_s": pace.first_late[i] * 1e-9}
                              for i in range(pace.n_first)],
           "dropped_slots": pace.dropped, "ring_waits": pace.ring_waits, "wall_time_s": wall,
           "achieved_factor": steps * h / wall if wall > 0 else None,
           "measures": measures,
           "histogram": {"resolution": "log-linear: 1 ns bins below 16 ns, then 16 bins per power of two "
                         "(width <= 1/16 of the value); [lowest s, highest s, count] of each non-empty bin; "
                         "percentiles are the highest value of their bin",
                         "lateness": _bins(pace.late), "execution": _bins(pace.exec)},
           "lateness_window": {"steps": pace.window, "worst_s": [float(v) * 1e-9 for v in used]}}
    if trace is not None:
        out["trace"] = {"lateness_ns": trace[0, :steps], "execution_ns": trace[1, :steps]}
    return out
