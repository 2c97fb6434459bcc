"""Paced runs (orchestrator.engine.pacing) on the native FMUs: a paced run takes its wall time and gives
the unpaced run's rows bit for bit; delays injected at chosen steps (the test hook $TAPMP_REALTIME_INJECT)
are counted and placed exactly, and the statistics agree with the per-step trace; the overrun policies
skip and abort; event mode and the clocked SSP paced; a run that steps in Python is refused."""

import math
import time
from pathlib import Path

import numpy as np
import pytest

from orchestrator.engine.master import CoSimulation, CoSimulationError, RunOptions
from orchestrator.engine.pacing import INJECT_ENV, Pacing, RealTimeError, bin_range_ns, run_paced
from orchestrator.tool.roles import ROLES
from orchestrator.tool.scenario import load

pytestmark = pytest.mark.slow  # builds the native FMUs and keeps runs to the wall clock

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "scenarios" / "paper_simulation.toml"
H = 1e-4


@pytest.fixture(scope="module")
def native_built(tmp_path_factory):
    """The native FMI 2.0 and 3.0 FMUs and SSPs for this machine only (the session's native_built builds
    every platform)."""
    from orchestrator.builder.build_native import build_native
    return build_native(tmp_path_factory.mktemp("native"), families=("fmi2", "fmi3"), log=lambda *_: None,
                        windows=False)


def options(**kw):
    return RunOptions(start_time=0.0, step_size=H, roles=ROLES, **kw)


def parameters():
    return load(PAPER, ["stop_time=0.2"]).parameters()


def unpaced(ssp, n, **kw):
    with CoSimulation(ssp, parameters(), options(**kw)) as sim:
        rows = np.empty((n, len(sim.columns)))
        sim.advance(rows)
        return rows


def paced(ssp, n, pacing, stop_after=None, **kw):
    """(rows, statistics, wall time [s] of run_paced, error or None, sim.k after)."""
    got, calls = [], [0]

    def stopped():
        calls[0] += 1
        return stop_after is not None and calls[0] > stop_after
    with CoSimulation(ssp, parameters(), options(**kw)) as sim:
        start, error, stats = time.monotonic(), None, None
        try:
            stats = run_paced(sim, n, pacing, lambda rows: got.append(rows.copy()), stopped)
        except CoSimulationError as err:
            error = err
        wall = time.monotonic() - start
        return np.concatenate(got) if got else np.empty((0, 1)), stats, wall, error, sim.k


def test_a_paced_run_takes_its_wall_time_and_gives_the_unpaced_rows(native_built):
    ssp = native_built["fmi2"]["ssp"]
    rows, stats, wall, error, k = paced(ssp, 2000, Pacing(1.0))  # 0.2 s of simulated time at the wall clock
    assert error is None and k == 2000
    assert rows.tobytes() == unpaced(ssp, 2000).tobytes()
    # it cannot end before its last deadline, 0.2 s after it started; the upper bound allows a loaded machine
    assert 0.2 <= wall < 0.2 + 3.0
    assert 0.2 <= stats["wall_time_s"] <= wall
    assert stats["achieved_factor"] == pytest.approx(0.2 / stats["wall_time_s"])
    assert stats["achieved_factor"] <= 1.0 + 1e-12
    assert stats["steps"] == 2000 and stats["factor"] == 1.0 and stats["overrun_policy"] == "continue"
    assert stats["period_s"] == pytest.approx(1e-4)
    assert stats["measures"]["mlockall"]["applied"] in (True, False) and stats["measures"]["mlockall"]["detail"]
    assert not stats["measures"]["sched_fifo"]["applied"]  # only with an rt_priority
    assert sum(b[2] for b in stats["histogram"]["lateness"]) == 2000


def test_injected_delays_are_counted_and_placed_and_the_statistics_match_the_trace(native_built, monkeypatch):
    # period 2 ms (factor 0.05); step 50 takes 5 ms longer: 3 ms late, step 51 (started late) 1 ms late;
    # step 120 takes 3 ms longer: 1 ms late
    monkeypatch.setenv(INJECT_ENV, "50:0.005,120:0.003")
    ssp = native_built["fmi2"]["ssp"]
    rows, stats, _, error, _ = paced(ssp, 200, Pacing(0.05, trace=True))
    assert error is None
    late, run = stats["trace"]["lateness_ns"], stats["trace"]["execution_ns"]
    assert len(late) == len(run) == 200
    over = [i + 1 for i in np.flatnonzero(late > 0)]  # steps by the communication point they reach
    assert {50, 51, 120} <= set(over)
    assert late[49] >= 3_000_000 and late[50] >= 1_000_000 and late[119] >= 1_000_000  # made late, at least
    assert run[49] >= 5_000_000 and run[119] >= 3_000_000
    # the statistics are the trace's: counted, placed, the longest run, the extremes exactly
    assert stats["overruns"] == len(over)
    runs, current = 0, 0
    for x in late:
        current = current + 1 if x > 0 else 0
        runs = max(runs, current)
    assert stats["longest_overrun_run"] == runs >= 2
    assert [o["step"] for o in stats["first_overruns"]] == over[:16]
    assert [o["lateness_s"] for o in stats["first_overruns"]] == [late[s - 1] * 1e-9 for s in over[:16]]
    assert stats["lateness_s"]["max"] == late.max() * 1e-9 and stats["lateness_s"]["min"] == late.min() * 1e-9
    assert stats["execution_s"]["max"] == run.max() * 1e-9
    for key, p in (("p50", 50), ("p99", 99), ("p999", 99.9)):
        for name, values in (("lateness_s", late), ("execution_s", run)):
            exact = int(np.percentile(values, p, method="inverted_cdf"))  # nearest rank
            got = round(stats[name][key] * 1e9)
            # the highest value of the exact quantile's bin: at most one bin width (1/16) above it
            assert exact <= got <= exact + max(1, abs(exact) // 16), (name, key, exact, got)
    # the worst lateness per window is the trace's
    w = stats["lateness_window"]["steps"]
    worst = [late[i:i + w].max() * 1e-9 for i in range(0, 200, w)]
    assert stats["lateness_window"]["worst_s"] == worst
    assert rows.tobytes() == unpaced(ssp, 200).tobytes()


def test_the_histogram_bins_are_log_linear_with_a_sixteenth_resolution():
    assert [bin_range_ns(b) for b in (0, 15, 16, 31, 32)] == [(0, 1), (15, 16), (16, 17), (31, 32), (32, 34)]
    for b in range(16, 1000):
        lo, hi = bin_range_ns(b)
        assert (hi - lo) * 16 <= lo and bin_range_ns(b + 1)[0] == hi


def test_skip_drops_the_missed_slots_and_keeps_the_rows(native_built, monkeypatch):
    monkeypatch.setenv(INJECT_ENV, "20:0.0035")  # period 1 ms: step 20 ends >= 2.5 ms late
    ssp = native_built["fmi2"]["ssp"]
    rows, stats, wall, error, _ = paced(ssp, 100, Pacing(0.1, "skip", trace=True))
    assert error is None and stats["overrun_policy"] == "skip"
    late = stats["trace"]["lateness_ns"]
    assert late[19] > 2_500_000
    assert late[20] < 0 or stats["overruns"] > 1  # released at the next free slot, the next step is on time
    assert stats["dropped_slots"] >= 3
    # the run takes its 100 slots plus the dropped ones: it cannot end earlier
    assert wall >= (100 + stats["dropped_slots"]) * 1e-3
    assert rows.tobytes() == unpaced(ssp, 100).tobytes()


def test_abort_stops_at_the_first_overrun_naming_the_step(native_built, monkeypatch):
    monkeypatch.setenv(INJECT_ENV, "20:0.0035")
    ssp = native_built["fmi2"]["ssp"]
    rows, _, _, error, k = paced(ssp, 100, Pacing(0.1, "abort"))
    assert isinstance(error, RealTimeError)
    first = error.real_time["first_overruns"][0]
    if first["step"] == 20:  # else the machine made an earlier step late on its own
        assert str(error).startswith("real time: step 20 (to t = 0.002 s) finished ")
        assert str(error).endswith(" us after its deadline (overrun policy abort)")
        assert k == 20 and len(rows) == 20
        assert rows.tobytes() == unpaced(ssp, 20).tobytes()
    assert error.real_time["overruns"] == 1 and error.real_time["steps"] == k


def test_a_stop_ends_a_paced_run_between_two_steps(native_built):
    ssp = native_built["fmi2"]["ssp"]
    rows, stats, _, error, k = paced(ssp, 20000, Pacing(1.0), stop_after=3)  # 2 s, stopped at once
    assert error is None and 0 < k < 20000 and len(rows) == k == stats["steps"]
    assert rows.tobytes() == unpaced(ssp, k).tobytes()


@pytest.mark.parametrize("which", ["ssp", "clocked_ssp"])
def test_event_mode_and_the_clocked_system_run_paced(native_built, which):
    ssp = native_built["fmi3"][which]
    rows, stats, wall, error, _ = paced(ssp, 200, Pacing(10.0), event_mode=True)
    assert error is None and stats["steps"] == 200 and wall >= 0.002
    assert rows.tobytes() == unpaced(ssp, 200, event_mode=True).tobytes()


def test_a_run_in_the_python_loop_and_a_bad_factor_are_refused(native_built):
    ssp = native_built["fmi2"]["ssp"]
    with CoSimulation(ssp, parameters(), options(stepper="python")) as sim:
        with pytest.raises(CoSimulationError, match=r"^real time needs the compiled stepping core, and this run "
                           r"steps in Python \(TAPMP_STEPPER or stepper = 'python'\)$"):
            run_paced(sim, 10, Pacing(), lambda rows: None, lambda: False)
        for bad in (0, -1.0, math.inf, math.nan, "1"):
            with pytest.raises(CoSimulationError, match=r"^real-time factor = .* is invalid: allowed is a finite "
                               r"number > 0"):
                run_paced(sim, 10, Pacing(bad), lambda rows: None, lambda: False)
        with pytest.raises(CoSimulationError, match=r"^overrun = 'later' is invalid: allowed are continue, skip, "
                           r"abort$"):
            run_paced(sim, 10, Pacing(overrun="later"), lambda rows: None, lambda: False)
        assert sim.k == 0
