"""TAPMP.ssp in FMPy's own SSP simulation, ``fmpy.ssp.simulate_ssp`` (fmpy 0.3.32).

Its loop is Jacobi-type like libcosim's and Ecos's, but with two conventions of its own:
* every FMU is initialized on its own (parameters, enter and exit Initialization Mode)
  and every connection starts at 0.0, so the first step runs on zero inputs: the
  controller on q_d = q = 0 and the plant on F = 0;
* time accumulates (``time += step_size``), the loop runs ``while time < stop_time``
  (so 0.2 s at 0.1 ms is 2,001 steps, the sum of 2,000 steps being just below 0.2) and
  each row holds the values after the step, labelled with the time the step started.
The orchestrator with connection_start = "zero" and clock = "accumulated" reproduces it
bit for bit; with its defaults the zero start moves the motors by up to ~0.1 um.
"""

from tests.interop import compatibility
import numpy as np
import pytest
from tests.support.runs import COMMANDS, MOTOR_POSITIONS, orchestrator_rows, paper_scenario
from fmpy.ssp.simulation import simulate_ssp
from fmpy.ssp.ssd import Parameter, ParameterSet

NAMES = MOTOR_POSITIONS + COMMANDS


def run_fmpy_ssp(ssp, scenario):
    """simulate_ssp over the scenario with its parameters as an SSP parameter set."""
    params = ParameterSet(name="scenario", parameters=[
        Parameter(name=f"{element}.{name}", value=value)
        for element, table in scenario.parameters().items() for name, value in table.items()])
    return simulate_ssp(str(ssp), start_time=scenario.start_time, stop_time=scenario.stop_time,
                        step_size=scenario.step, parameter_set=params)


@pytest.fixture(scope="module")
def fmpy_run(built):
    scenario = paper_scenario()
    result = run_fmpy_ssp(built["ssp"], scenario)
    return scenario, result, np.array([result[n] for n in NAMES]).T


def test_fmpy_ssp_runs_one_step_more_with_accumulated_time_labels(fmpy_run):
    scenario, result, _ = fmpy_run
    assert len(result) == scenario.n_steps + 1 == 2001
    labels = np.cumsum([0.0] + [scenario.step] * scenario.n_steps)
    assert np.array_equal(result["time"], labels)
    assert result["time"][-1] < 0.2


def test_fmpy_ssp_is_bit_identical_with_the_orchestrator_on_its_conventions(built, fmpy_run, request):
    scenario, _, fm = fmpy_run
    sc = scenario.with_changes(stop_time=scenario.stop_time + scenario.step)  # 2,001 steps
    ours = orchestrator_rows(built["ssp"], sc, NAMES, "jacobi", clock="accumulated",
                             connection_start="zero")
    assert np.all(ours[0] == 0.0)  # no output is read before the first step
    assert np.array_equal(fm, ours[1:]), dict(zip(NAMES, np.abs(fm - ours[1:]).max(axis=0)))
    assert np.abs(fm[-1, :3]).min() > 1e-3  # the platform has moved (mm), so this compares something
    compatibility.record(
        request, tool="FMPy", version=compatibility.python_version("fmpy"), fmi="2.0", interface="SSP 1.0, CS",
        command=".venv/bin/python tests/interop/rows/fmpy_simulate_ssp.py build/TAPMP.ssp --stop-time 0.2 "
                "--scenario scenarios/paper_simulation.toml",
        difference=compatibility.difference(compatibility.largest(fm, ours[1:]), "",
                                            "tapmp run, ordering=jacobi, clock=accumulated, connection_start=zero"))


def test_fmpy_ssp_zero_start_is_the_difference_to_the_orchestrator(built, fmpy_run):
    """With the orchestrator's defaults (outputs propagated in Initialization Mode) the first
    plant step gets the controller's initial command instead of 0 N (~15 N on motors 1 and 3,
    ~0 N on motor 2), which moves motors 1 and 3 by ~10 nm in 0.1 ms and, through the
    encoder quantization, all three by up to ~0.1 um later."""
    scenario, _, fm = fmpy_run
    ours = orchestrator_rows(built["ssp"], scenario, NAMES, "jacobi")
    F0 = ours[0, 6:]                                   # N: the initial command FMPy does not use
    assert abs(F0[0]) > 10.0 and abs(F0[2]) > 10.0 and abs(F0[1]) < 1e-9  # motor 2 starts at ~0 N
    first = np.abs(fm[0, :3] - ours[1, :3])            # fmpy row 0 = values at t_1
    assert np.all((first[[0, 2]] > 1e-9) & (first[[0, 2]] < 1e-7)) and first[1] < 1e-11, first
    diff = np.abs(fm[:-1, :3] - ours[1:, :3]).max(axis=0)
    assert np.all((diff > 1e-8) & (diff < 2e-7)), diff  # m; measured 9.9e-8 ... 1.2e-7
    # the accumulated clock alone is not the difference: it gives the same picture
    acc = orchestrator_rows(built["ssp"], scenario, NAMES, "jacobi", clock="accumulated")
    assert np.abs(fm[:-1, :3] - acc[1:, :3]).max() > 1e-8
