"""The master's per-step output check comes from its caller: any column, any limit, its own
message, checked the same by the Python loop and the compiled core."""

import numpy as np
import pytest

from orchestrator.engine.master import CoSimulation, DivergenceError, OutputCheck, RunOptions
from orchestrator.tool.roles import ROLES
from orchestrator.tool.envelope import Envelope
from tests.support.runs import paper_scenario


class ReferenceBound(OutputCheck):
    """|trajectory.X_d| <= 0.1 mm: the reference (2.5 um per step) leaves it after 40 steps."""

    bounds = (("trajectory.X_d", 1e-4),)

    def breach(self, column, value, limit, t):
        return f"test bound: {column} = {value!r} > {limit!r} at t = {t!r}"


@pytest.mark.parametrize("stepper", ["python", "compiled"])
def test_a_caller_supplied_bound_on_any_column_stops_the_run_with_its_message(built, stepper):
    sc = paper_scenario(0.05)
    with CoSimulation(built["ssp"], sc.parameters(), RunOptions(start_time=0.0, step_size=sc.step,
                                                                check=ReferenceBound(), stepper=stepper,
                                                                roles=ROLES)) as sim:
        rows = np.full((sc.n_steps, len(sim.columns)), np.nan)
        with pytest.raises(DivergenceError) as info:
            sim.advance(rows)
        column = sim.columns.index("trajectory.X_d")
        stored = rows[:sim.filled]
    err = info.value
    assert str(err) == f"test bound: trajectory.X_d = {err.value!r} > 0.0001 at t = {err.time!r}"
    assert (err.signal, err.element) == ("trajectory.X_d", "trajectory") and abs(err.value) > 1e-4
    assert err.time == pytest.approx((len(stored) + 1) * sc.step)  # the rows before the breach are stored
    assert len(stored) >= 30 and np.all(np.abs(stored[:, column]) <= 1e-4)


def test_without_a_check_only_non_finite_outputs_stop_a_run(built):
    sc = paper_scenario(0.01, "limits.motor_travel=0.000001")  # the scenario's limits are not the master's
    with CoSimulation(built["ssp"], sc.parameters(), RunOptions(start_time=0.0, step_size=sc.step, roles=ROLES)) as sim:
        rows = np.empty((sc.n_steps, len(sim.columns)))
        assert sim.advance(rows) == sc.n_steps


def test_the_platform_envelope_bounds_the_limits_that_are_on_in_their_order():
    env = Envelope({"motor_travel": 0.05, "platform_angle": 0.0})
    assert env.bounds == (("plant.q1_true", 0.05), ("plant.q2_true", 0.05), ("plant.q3_true", 0.05))
    assert env.breach("plant.q2_true", 0.06, 0.05, 0.25).startswith(
        "plant.q2_true = 0.06 m at t = 0.25 s is outside the envelope |plant.q2_true| <= 0.05 m "
        "(limits.motor_travel): the closed loop is diverging; hint: gains unstable at this step size?")
    with pytest.raises(ValueError, match=r"limits x unknown: allowed are motor_travel, platform_angle"):
        Envelope({"x": 1.0})
