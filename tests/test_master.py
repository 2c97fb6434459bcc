"""The master algorithm: FMI plumbing adds nothing, SC-DC beats APD-DC, failures keep results."""

import json
import tempfile
from pathlib import Path

import numpy as np
import pytest

from orchestrator.master import CoSimulation, CoSimulationError
from orchestrator.results import run_scenario
from orchestrator.scenario import load, model_tuple
from tapmp.closed_loop import simulate
from tapmp.control import ControllerModel
from tapmp.params import ModelParams
from tapmp.plant import PlantConfig, PlantModel
from tapmp.trajectory import TrajectoryParams

ROOT = Path(__file__).resolve().parent.parent
PAPER = ROOT / "scenarios" / "paper_simulation.toml"


def plain_loop(scenario):
    """The same closed loop from the model functions alone (no FMI)."""
    par = scenario.parameters()
    pl, ct, tr = par["plant"], par["controller"], par["trajectory"]

    plant = PlantModel(model_tuple(ModelParams, pl), model_tuple(PlantConfig, pl),
                       tuple(pl[k] for k in ("X0", "Z0", "B0")), tuple(pl[k] for k in ("dX0", "dZ0", "dB0")))
    ctrl = ControllerModel(model_tuple(ModelParams, ct), scenario.gain_values(), ct["law"],
                           ct.get("velocity_source", 0), ct.get("force_limit", 0.0))
    rows = []
    simulate(plant, ctrl, model_tuple(TrajectoryParams, tr), scenario.start_time, scenario.n_steps, scenario.step,
             scenario.ordering, lambda t, ref, F, q, qt: rows.append((t, *F, *q, *qt)))
    return np.array(rows)


@pytest.mark.parametrize("ordering", ["gauss-seidel", "jacobi"])
def test_fmu_closed_loop_equals_the_plain_python_loop(built, ordering):
    scenario = load(PAPER, [f'ordering="{ordering}"', "stop_time=0.1"])
    expected = plain_loop(scenario)
    got = []
    with CoSimulation(built["ssp"], scenario.parameters(), 0.0, scenario.step, ordering) as sim:
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


def test_scdc_beats_apddc_on_every_motor(built, tmp_path):
    base = load(PAPER)  # the full 2.5 s circle: on q3 the margin is under 10 %, so no shortcut
    m = {law: run_scenario(base.with_changes(law=law), built["ssp"], tmp_path / law) for law in ("sc-dc", "apd-dc")}
    for i in range(3):
        assert m["sc-dc"]["tracking_mae_um"][i] < m["apd-dc"]["tracking_mae_um"][i]
        assert m["sc-dc"]["sync_mae_um"][i] < m["apd-dc"]["sync_mae_um"][i]


def test_failing_step_stops_keeps_results_and_leaves_nothing_behind(built, tmp_path, monkeypatch):
    (tmp_path / "tmp").mkdir()  # a private temp folder: other processes may co-simulate meanwhile
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "tmp"))
    before = set(Path(tempfile.gettempdir()).glob("tapmp_cosim_*"))
    sc = load(PAPER, ['gains="paper_simulation"', "plant.force_limit=0"])  # Eq. 40, no saturation
    with pytest.raises(CoSimulationError, match=r"plant: doStep failed at t = .* \|B\| < pi/2") as info:
        run_scenario(sc, built["ssp"], tmp_path / "run")
    rows = (tmp_path / "run" / "results.csv").read_text().splitlines()
    assert len(rows) >= 3 and rows[0].startswith("time,")
    assert all(len(r.split(",")) == len(rows[0].split(",")) for r in rows)
    run = json.loads((tmp_path / "run" / "run.json").read_text())
    assert run["status"] == "failed" and "doStep failed" in run["error"]
    assert info.value.element == "plant" and info.value.time == pytest.approx(run["failed_at_s"])
    assert set(Path(tempfile.gettempdir()).glob("tapmp_cosim_*")) == before


def test_unknown_parameter_is_named_with_what_is_allowed(built):
    with pytest.raises(CoSimulationError, match=r"plant.mass is not a parameter of TAPMP_Plant: allowed are .*m_p"):
        with CoSimulation(built["ssp"], {"plant": {"mass": 1.0}}):
            pass


def test_missing_ssp_is_a_clear_error(tmp_path):
    with pytest.raises(CoSimulationError, match="does not exist: run `tapmp build` first"):
        with CoSimulation(tmp_path / "nope.ssp", {}):
            pass
