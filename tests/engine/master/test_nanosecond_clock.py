"""The nanosecond clock (libcosim's: an int64 count of nanoseconds) refuses times it cannot hold,
in the master itself and the same in both loops, before any FMU steps: a start beyond 2^63 - 1 ns
(about 9.22e9 s) at construction, steps that would carry t_k beyond it at advance. (Before, the
Python loop stepped on with Python's unbounded integers while the compiled core's int64 wrapped
and called doStep at t = -8.4e9 s.)"""

import numpy as np
import pytest

from orchestrator.engine.clocks import Clock
from orchestrator.engine.master import CoSimulation, CoSimulationError, RunOptions
from orchestrator.tool.roles import ROLES
from orchestrator.tool.scenario import load

from tests.support.runs import PAPER


def test_the_clock_knows_its_last_representable_step():
    clock = Clock("nanoseconds", 9223372030.0, 1.0)
    assert clock.last_k == 6  # (2^63 - 1 - 9223372030e9) // 1e9: t_6 = 9223372036 s
    clock.require_steps(6)
    with pytest.raises(ValueError, match=r"stop_time = 9223372037.0 s is invalid for clock = 'nanoseconds'"):
        clock.require_steps(7)
    assert Clock("exact", 9.3e9, 1.0).last_k is None
    with pytest.raises(ValueError, match=r"start_time = 9300000000.0 s is invalid for clock = 'nanoseconds'"):
        Clock("nanoseconds", 9.3e9, 1.0)


@pytest.mark.slow
@pytest.mark.parametrize("stepper", ["python", "compiled"])
def test_steps_beyond_the_int64_clock_are_refused_before_any_step(built, stepper):
    parameters = load(PAPER).parameters()
    with pytest.raises(CoSimulationError) as start:
        CoSimulation(built["ssp"], parameters, RunOptions(start_time=9.3e9, step_size=1.0, clock="nanoseconds",
                                                          stepper=stepper, roles=ROLES))
    assert str(start.value) == ("start_time = 9300000000.0 s is invalid for clock = 'nanoseconds': allowed are times "
                                "within +-9223372037 s (an int64 count of nanoseconds), or another clock")
    with CoSimulation(built["ssp"], parameters, RunOptions(start_time=9223372036.84, step_size=1e-4,
                                                           clock="nanoseconds", stepper=stepper, roles=ROLES)) as sim:
        last = sim.clock.last_k  # t_last <= 2^63 - 1 ns < t_(last + 1)
        assert 100 < last < 200
        rows = np.zeros((last + 1, len(sim.columns)))
        with pytest.raises(CoSimulationError) as far:
            sim.advance(rows)
        assert str(far.value) == (
            f"stop_time = {sim.clock.at(last + 1)!r} s is invalid for clock = 'nanoseconds' (start_time 9223372036.84 "
            f"s + {last + 1} steps of 0.0001 s): allowed are times within +-9223372037 s (an int64 count of "
            "nanoseconds), or another clock")
        assert sim.k == 0 and sim.filled == 0 and not rows.any()
        assert sim.advance(rows[:last]) == last and sim.time > 9223372036.85  # up to the last representable step
