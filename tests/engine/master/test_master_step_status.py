"""The master's step takes the worst status call by call and stops at the first failing
call, like the Reference FMUs' CALL pattern: a failing fmi2SetReal / fmi3SetFloat64 stops
the step before that FMU's doStep, and a Warning followed by a Discard is reported as a
Discard (not as the Error that 1 | 2 would read as).

Through the real CoSimulation on an SSP of real FMUs: the plant's input F1 receives a
non-finite value (the controller's last output, as the master holds it, set to NaN before
the step), which the plant's SetReal refuses; the plant's doStep calls are counted by
wrapping the master's own call, which still calls the FMU."""

import math

import pytest

from tests.support.runs import PAPER
from tests.support.faults import faulty_plant_fmu, faulty_ssp
from orchestrator.engine.master import CoSimulation, CoSimulationError, RunOptions
from orchestrator.tool.roles import ROLES

ORDERINGS = {"gauss-seidel": ["plant", "controller", "trajectory"], "jacobi": None}  # the plant steps first


def scenario():
    from orchestrator.tool.scenario import load
    return load(PAPER)


def run_with_nan_force(ssp, ordering, steps_before=3):
    """Step ``steps_before`` times, then once with NaN as the controller's F1 output;
    returns (the CoSimulationError, the plant's doStep times, the step's start time)."""
    sc = scenario()
    with CoSimulation(ssp, sc.parameters(), RunOptions(start_time=0.0, step_size=sc.step, ordering=ordering,
                                                       order=ORDERINGS[ordering], roles=ROLES)) as sim:
        plant, controller = sim.units["plant"], sim.units["controller"]
        calls = []
        do_step = plant.do_step

        def counted(t, h):
            calls.append(t)
            return do_step(t, h)
        plant.do_step = counted
        for _ in range(steps_before):
            sim.step()
        assert len(calls) == steps_before
        t = sim.time
        controller.out[0] = math.nan  # what the plant's F1 receives at this step
        with pytest.raises(CoSimulationError) as info:
            sim.step()
    return info.value, calls, t


@pytest.mark.parametrize("ordering", ORDERINGS)
@pytest.mark.parametrize("family", ["fmi2", "fmi3"])
def test_a_failing_set_real_stops_the_step_before_do_step(native_built, family, ordering):
    err, calls, t = run_with_nan_force(native_built[family]["ssp"], ordering)
    assert len(calls) == 3  # no doStep of the plant at the failing step: the count stayed at 3
    assert t == pytest.approx(3e-4, abs=1e-15)
    assert err.element == "plant" and err.time == pytest.approx(3e-4, abs=1e-15)
    assert str(err).startswith("plant: doStep failed at t = 0.0003 s: [ERROR] ")
    assert str(err).endswith("F1 = nan at t = 0.0003 s is invalid: allowed is a finite number")


WARN_THEN_DISCARD = '''
    def fmi2_reject_input(self, vr, value):
        return 1  # fmi2Warning: the non-finite input is ignored (a test FMU)

    def fmi2_do_step(self, current_time, step_size):
        status = super().fmi2_do_step(current_time, step_size)
        return 2 if current_time >= 2.5e-4 else status  # fmi2Discard, nothing logged
'''


@pytest.fixture(scope="module")
def warn_then_discard_ssp(built, tmp_path_factory):
    """The real controller and trajectory with a plant that answers a non-finite input with
    fmi2Warning and every doStep from t = 0.3 ms on with fmi2Discard."""
    root = tmp_path_factory.mktemp("warn_discard")
    plant = faulty_plant_fmu(root, WARN_THEN_DISCARD, "The real plant: Warning, then Discard.")
    return faulty_ssp(root / "system.ssp", plant, built)


@pytest.mark.slow
@pytest.mark.parametrize("ordering", ORDERINGS)
def test_a_warning_followed_by_a_discard_is_reported_as_discard(warn_then_discard_ssp, ordering):
    err, calls, t = run_with_nan_force(warn_then_discard_ssp, ordering)
    assert calls[-1] == pytest.approx(3e-4, abs=1e-15) and len(calls) == 4  # SetReal warned, doStep ran
    assert err.element == "plant" and err.__cause__ is None
    assert str(err) == "plant: doStep failed at t = 0.0003 s: a call returned DISCARD, above fmi2Warning"
    assert not [m for m in err.log if m.startswith(("[ERROR]", "[FATAL]"))]
