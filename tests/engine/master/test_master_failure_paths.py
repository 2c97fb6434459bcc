"""The master's failure paths, for both orderings, through the real
CoSimulation on an SSP with a real plant FMU that misbehaves from t = 0.5 ms on (tests/support/faults.py,
the ``faulty_ssps`` fixture):

* ``status``: doStep returns fmi2Error and logs nothing;
* ``error_log``: doStep logs an error and returns fmi2OK;
* ``info_log``: doStep logs an info line and returns fmi2OK (not a failure: the run completes).

A failure is a CoSimulationError (never TypeError: the status or the log is no exception to
chain from) naming the element, the call and the time."""

import pytest

from orchestrator.engine.master import CoSimulation, CoSimulationError, RunOptions
from orchestrator.tool.roles import ROLES
from tests.support.runs import PAPER


def run(ssp, ordering, steps=20):
    """Step the paper scenario's system ``steps`` times; returns the closed CoSimulation."""
    from orchestrator.tool.scenario import load
    sc = load(PAPER)
    with CoSimulation(ssp, sc.parameters(), RunOptions(start_time=0.0, step_size=sc.step, ordering=ordering,
                                                       roles=ROLES)) as sim:
        for _ in range(steps):
            sim.step()
    return sim


@pytest.mark.parametrize("ordering", ["gauss-seidel", "jacobi"])
def test_a_step_failing_by_status_only_is_a_cosimulation_error_naming_element_call_and_time(faulty_ssps, ordering):
    with pytest.raises(CoSimulationError) as info:
        run(faulty_ssps["status"], ordering)
    err = info.value
    assert type(err) is CoSimulationError and err.__cause__ is None
    assert err.element == "plant" and err.time == pytest.approx(5e-4, abs=1e-12)
    assert str(err) == ("plant: doStep failed at t = 0.0005 s: a call returned ERROR, above fmi2Warning")
    assert not [m for m in err.log if m.startswith(("[ERROR]", "[FATAL]"))]


@pytest.mark.parametrize("ordering", ["gauss-seidel", "jacobi"])
def test_a_step_failing_by_an_error_log_only_is_a_cosimulation_error_with_the_message(faulty_ssps, ordering):
    with pytest.raises(CoSimulationError) as info:
        run(faulty_ssps["error_log"], ordering)
    err = info.value
    assert type(err) is CoSimulationError and err.__cause__ is None
    assert err.element == "plant" and err.time == pytest.approx(5e-4, abs=1e-12)
    assert str(err) == "plant: doStep failed at t = 0.0005 s: [ERROR] plant: encoder lost at t = 0.0005 s"


@pytest.mark.parametrize("ordering", ["gauss-seidel", "jacobi"])
def test_a_step_that_logs_at_info_level_does_not_fail(faulty_ssps, ordering):
    sim = run(faulty_ssps["info_log"], ordering, steps=20)
    assert sim.k == 20 and sim.time == pytest.approx(2e-3)
    infos = [m for m in sim.log if m.startswith("[OK] plant: step at t = ")]
    assert len(infos) == 15  # t = 0.5 ms ... 1.9 ms, one per step, and the run went on


def test_the_status_only_failure_through_the_cli_is_one_line_exit_2(faulty_ssps, tmp_path):
    """The same failure through `tapmp run`: one line, exit 2, run.json says failed at 0.5 ms."""
    import json
    import os
    import subprocess
    import sys
    res = subprocess.run([sys.executable, "-m", "orchestrator", "run", PAPER, "--ssp", str(faulty_ssps["status"]),
                          "--out", str(tmp_path / "out"), "--set", "stop_time=0.002", "--set", 'ordering="jacobi"',
                          "--no-progress"], capture_output=True, text=True, timeout=120,
                         env=dict(os.environ, TMPDIR=str(tmp_path)))
    assert res.returncode == 2, res.stderr
    assert res.stderr.splitlines() == ["error: plant: doStep failed at t = 0.0005 s: a call returned ERROR, "
                                       "above fmi2Warning"]
    info = json.loads((tmp_path / "out" / "run.json").read_text())
    assert info["status"] == "failed" and info["failed_at_s"] == pytest.approx(5e-4)
