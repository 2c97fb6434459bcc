"""The master algorithm: FMI plumbing adds nothing, SC-DC beats APD-DC, failures keep results."""

import json
import tempfile
from pathlib import Path

import numpy as np
import pytest

from orchestrator.engine.master import CoSimulation, CoSimulationError, DivergenceError, RunOptions
from orchestrator.tool.roles import ROLES
from orchestrator.tool.results import run_scenario
from orchestrator.tool.scenario import load
from tapmp.closed_loop import simulate
from tests.support.faults import faulty_plant_fmu, faulty_ssp

ROOT = Path(__file__).resolve().parents[3]
PAPER = ROOT / "scenarios" / "paper_simulation.toml"


def plain_loop(scenario):
    """The same closed loop from the model functions alone (no FMI)."""
    plant, ctrl, traj = scenario.plain_models()
    rows = []
    simulate(plant, ctrl, traj, scenario.start_time, scenario.n_steps, scenario.step,
             scenario.ordering, lambda t, ref, F, q, qt: rows.append((t, *F, *q, *qt)))
    return np.array(rows)


@pytest.mark.parametrize("ordering", ["gauss-seidel", "jacobi"])
def test_fmu_closed_loop_equals_the_plain_python_loop(built, ordering):
    scenario = load(PAPER, [f'ordering="{ordering}"', "stop_time=0.1"])
    expected = plain_loop(scenario)
    got = []
    with CoSimulation(built["ssp"], scenario.parameters(), RunOptions(start_time=0.0, step_size=scenario.step,
                                                                      ordering=ordering, roles=ROLES)) as sim:
        names = ["time", "controller.F1", "controller.F2", "controller.F3", "plant.q1", "plant.q2", "plant.q3",
                 "plant.q1_true", "plant.q2_true", "plant.q3_true"]
        idx = [sim.columns.index(n) for n in names]
        got.append([sim.row()[i] for i in idx])
        for _ in range(scenario.n_steps):
            sim.step()
            got.append([sim.row()[i] for i in idx])
    got = np.array(got)
    assert got.shape == expected.shape == (1001, 10)
    assert np.abs(got[:, 0] - expected[:, 0]).max() == 0.0          # t0 + k h, never accumulated
    assert np.abs(got[:, 4:] - expected[:, 4:]).max() <= 1e-9         # positions [m]
    assert np.abs(got[:, 1:4] - expected[:, 1:4]).max() <= 1e-6       # forces [N]


def test_orderings_differ_by_the_extra_sample_of_delay(built):
    out = {}
    for ordering in ("gauss-seidel", "jacobi"):
        sc = load(PAPER, [f'ordering="{ordering}"', "stop_time=0.05"])
        out[ordering] = plain_loop(sc)
    # Jacobi: the plant's first step runs on the initial command; Gauss-Seidel on the first sample's.
    assert not np.array_equal(out["gauss-seidel"][1:, 7:], out["jacobi"][1:, 7:])


@pytest.mark.slow
def test_scdc_beats_apddc_on_every_motor(built, tmp_path):
    base = load(PAPER)  # the full 2.5 s circle: on q3 the margin is under 10 %, so no shortcut
    m = {law: run_scenario(base.with_changes(law=law), built["ssp"], tmp_path / law) for law in ("sc-dc", "apd-dc")}
    for i in range(3):
        assert m["sc-dc"]["tracking_mae_um"][i] < m["apd-dc"]["tracking_mae_um"][i]
        assert m["sc-dc"]["sync_mae_um"][i] < m["apd-dc"]["sync_mae_um"][i]


def test_failing_step_stops_keeps_results_and_leaves_nothing_behind(built, tmp_path, monkeypatch):
    scratch = tmp_path / "scratch"  # a private temp dir: other processes may run co-simulations
    scratch.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))
    sc = load(PAPER, ['gains="paper_simulation"', "plant.force_limit=0"])  # Eq. 40, no saturation
    with pytest.raises(CoSimulationError, match=r"plant: doStep failed at t = .* \|B\| < pi/2") as info:
        run_scenario(sc, built["ssp"], tmp_path / "run")
    rows = (tmp_path / "run" / "results.csv").read_text().splitlines()
    assert len(rows) >= 3 and rows[0].startswith("time,")
    assert all(len(r.split(",")) == len(rows[0].split(",")) for r in rows)
    run = json.loads((tmp_path / "run" / "run.json").read_text())
    assert run["status"] == "failed" and "doStep failed" in run["error"]
    assert info.value.element == "plant" and info.value.time == pytest.approx(run["failed_at_s"])
    assert list(scratch.iterdir()) == []  # every extracted FMU folder was removed


def test_unknown_parameter_is_named_with_what_is_allowed(built):
    with pytest.raises(CoSimulationError, match=r"plant.mass is not a parameter of TAPMP_Plant: allowed are .*m_p"):
        with CoSimulation(built["ssp"], {"plant": {"mass": 1.0}}, RunOptions(roles=ROLES)):
            pass


def test_missing_ssp_is_a_clear_error(tmp_path):
    with pytest.raises(CoSimulationError, match="does not exist: run `tapmp build` first"):
        with CoSimulation(tmp_path / "nope.ssp", {}):
            pass


def test_envelope_breach_stops_with_time_signal_value_and_hint(built, tmp_path):
    sc = load(PAPER, ['gains="paper_simulation"', "plant.force_limit=0", "limits.motor_travel=0.001"])
    with pytest.raises(DivergenceError) as info:
        run_scenario(sc, built["ssp"], tmp_path / "run")
    err = info.value
    assert err.signal.startswith("plant.q") and abs(err.value) > 0.001 and err.time == pytest.approx(4e-4)
    assert f"at t = 0.0004 s is outside the envelope |{err.signal}| <= 0.001 m (limits.motor_travel)" in str(err)
    assert "gains unstable at this step size" in str(err)
    rows = (tmp_path / "run" / "results.csv").read_text().splitlines()
    assert len(rows) == 1 + 4  # t = 0 .. 0.0003 kept; the breaching row is not written
    run = json.loads((tmp_path / "run" / "run.json").read_text())
    assert (run["status"], run["failed_signal"], run["failed_value"]) == ("failed", err.signal, err.value)


BROKEN_STEP = """
    def step(self, t, h):
        super().step(t, h)
        if t >= 4.5e-4:
            self.q2_true = float("nan")
"""


# A third-party FMU that publishes a NaN with status OK (plain pythonfmu, no TAPMP runtime): the
# master's own finiteness check must catch it.
NAN_PROBE = '''
from pythonfmu import Fmi2Causality, Fmi2Slave, Real


class NanProbe(Fmi2Slave):
    """y = 0, then NaN after the step from t = 0.5 ms."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.y = 0.0
        self.register_variable(Real("y", causality=Fmi2Causality.output))

    def do_step(self, current_time, step_size):
        if current_time >= 4.5e-4:
            self.y = float("nan")
        return True
'''


@pytest.mark.slow
def test_a_non_finite_output_of_any_fmu_stops_the_run(built, tmp_path):
    from tests.engine.master.test_master_any_ssp import _build, rewrite_ssp
    probe = _build(tmp_path, NAN_PROBE, "NanProbe")
    ssp = rewrite_ssp(built["ssp"], tmp_path / "probed.ssp", add=[("probe", probe, [("y", "output")])])
    with pytest.raises(DivergenceError, match=r"probe.y = nan at t = 0.0006 s is not finite") as info:
        run_scenario(load(PAPER), ssp, tmp_path / "run")
    assert info.value.signal == "probe.y"
    assert len((tmp_path / "run" / "results.csv").read_text().splitlines()) == 1 + 6  # t = 0 .. 0.5 ms


@pytest.mark.slow
def test_a_tapmp_fmu_refuses_to_publish_a_non_finite_output(built, tmp_path):
    """The TAPMP runtime checks its outputs itself: the same NaN in the plant is an error status
    with the runtime's message, which the master reports naming the plant."""
    broken = faulty_plant_fmu(tmp_path, BROKEN_STEP, "The real plant, except that q2_true is NaN after the step "
                                                     "from t = 0.5 ms.")
    ssp = faulty_ssp(tmp_path / "broken.ssp", broken, built)
    with pytest.raises(CoSimulationError, match=r"^plant: doStep failed at t = 0.0005 s: \[ERROR\] plant: q2_true = "
                                                r"nan at t = 0.0006 s is invalid: allowed is a finite number") as info:
        run_scenario(load(PAPER), ssp, tmp_path / "run")
    assert not isinstance(info.value, DivergenceError)
    assert len((tmp_path / "run" / "results.csv").read_text().splitlines()) == 1 + 6  # t = 0 .. 0.5 ms
