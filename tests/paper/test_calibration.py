"""Calibration on APD-DC, prediction of SC-DC (orchestrator/paper/calibration.py).

The objective is computed from real co-simulations (checked by hand against the runs'
metrics.json); the calibrated scenario files load, pass the stability pre-check for both
laws and give APD-DC errors close to the fit record they carry.
"""

import json
import math
import re

import pytest

from orchestrator.paper import calibration as cal
from orchestrator.tool import stability
from orchestrator.tool.results import run_scenario
from orchestrator.tool.scenario import load

THETA = [2.5, 4.0, -300.0, 0.9]  # F_c_outer, F_c_middle [N], k_pull [N/m], m_p factor


def test_objective_on_a_tiny_horizon_equals_the_hand_computation_from_the_runs_metrics(built, tmp_path):
    ev = cal.Evaluator("simulation", built["ssp"], tmp_path, horizon=0.05)
    r = ev(THETA)
    r2 = ev([2.5, 4.0, 0.0, 1.0])
    for h, res in zip(ev.history, (r, r2)):
        m = json.loads((tmp_path / "evals" / h["folder"].split("/")[-1] / "metrics.json").read_text())
        assert m["samples"] == 501  # 0.05 s of 0.1 ms steps and the start
        paper_trk, paper_sync = (6.87, 12.53, 5.87), (6.98, 7.26, 4.92)  # Tables 1 and 2, APD-DC MAE
        hand = [math.log(m["tracking_mae_um"][i] / paper_trk[i]) for i in range(3)] + \
               [math.log(m["sync_mae_um"][i] / paper_sync[i]) for i in range(3)]
        assert list(res) == pytest.approx(hand, rel=1e-12, abs=1e-15)
        assert h["objective"] == pytest.approx(sum(x * x for x in hand), rel=1e-12)
    assert ev.history[0]["objective"] != ev.history[1]["objective"]  # the parameters reach the run
    run = json.loads((tmp_path / "evals" / "0000" / "run.json").read_text())["scenario"]
    assert run["law"] == "apd-dc"
    assert (run["plant"]["F_c1"], run["plant"]["F_c2"], run["plant"]["F_c3"]) == (2.5, 4.0, 2.5)
    assert run["plant"]["k_pull"] == -300.0 and run["mismatch"] == {"m_p": 0.9}
    # Eq. 40 x 0.36/150: Lambda_p 8000, 8000, 8850 -> 19.2, 19.2, 21.24; Lambda_v 150 -> 0.36
    assert run["gain_values"]["Lambda_p"] == pytest.approx([19.2, 19.2, 21.24], rel=1e-12)
    assert run["gain_values"]["Lambda_v"] == pytest.approx([0.36, 0.3804, 0.2604], rel=1e-12)
    assert run["gain_values"]["D"] == [200.0] * 3 and run["gain_values"]["b"] == [0.0005, 8.1, 1.5]


def test_a_parameter_outside_its_bounds_or_a_wrong_target_is_refused_by_name():
    with pytest.raises(ValueError, match=r"k_pull = 10\.0 is invalid: allowed is a number in \[-3000, 0\] N/m"):
        cal.check_theta([2.0, 2.0, 10.0, 1.0])
    with pytest.raises(ValueError, match=r"m_p_factor = nan is invalid"):
        cal.check_theta([2.0, 2.0, 0.0, float("nan")])
    with pytest.raises(ValueError, match=r"theta has 3 values: allowed are 4"):
        cal.check_theta([2.0, 2.0, 0.0])
    with pytest.raises(ValueError, match=r"target = 'lab' is invalid: allowed are simulation, experiment"):
        cal.calibrated_scenario("lab", [2.0, 2.0, 0.0, 1.0])


def test_tapmp_calibrate_refuses_a_bad_horizon_or_budget_in_one_line(capsys):
    from orchestrator.cli import main
    assert main(["calibrate", "--target", "simulation", "--horizon", "-1", "--ssp", "unused.ssp"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["error: --horizon = -1.0 is invalid: allowed is a number > 0 [s]"]
    assert main(["calibrate", "--target", "simulation", "--max-nfev", "0", "--ssp", "unused.ssp"]) == 2
    assert capsys.readouterr().err == "error: --max-nfev = 0 is invalid: allowed is an integer >= 1\n"


@pytest.mark.parametrize("target", cal.TARGETS)
def test_calibrated_scenario_files_carry_the_fit_and_pass_the_stability_precheck(target):
    path = cal.calibrated_file(target)
    rec = cal.read_fit_record(path)
    sc = load(path)
    assert sc.law == "apd-dc" and sc.gains == "paper_simulation"
    assert (sc.plant["F_c1"], sc.plant["F_c2"], sc.plant["F_c3"]) == (rec["F_c_outer"], rec["F_c_middle"],
                                                                       rec["F_c_outer"])
    assert sc.plant["k_pull"] == rec["k_pull"] and sc.mismatch["m_p"] == rec["m_p_factor"]
    # the record's objective is the sum of its squared residuals
    assert rec["objective_full"] == pytest.approx(sum(x * x for x in rec["residuals_full"]), rel=1e-12)
    base = load(cal.base_file(target))
    assert sc.trajectory == base.trajectory and sc.stop_time == base.stop_time  # the base's trajectory
    for law in ("apd-dc", "sc-dc"):
        rep = stability.check(sc.with_changes(law=law))
        assert rep.verdict == "stable", (target, law, rep.summary())


# Simulation: the full 2.5 s horizon of the fit, through the pythonfmu FMUs (bit-identical to the
# native ones the fit ran): the record's numbers to round-off. Experiment: its first B period
# (5.5556 s of the 11.1 s), within a factor 1.5 of the record's full-horizon APD-DC errors.
@pytest.mark.slow
@pytest.mark.parametrize("target,stop,factor", [("simulation", None, 1.0 + 1e-9), ("experiment", 5.5556, 1.5)])
def test_a_short_run_of_each_calibrated_scenario_gives_the_fits_apddc_errors(built, tmp_path, target, stop, factor):
    rec = cal.read_fit_record(cal.calibrated_file(target))
    sc = load(cal.calibrated_file(target))
    if stop is not None:
        sc = sc.with_changes(stop_time=stop)
    m = run_scenario(sc.with_changes(record_every=sc.n_steps), built["ssp"], tmp_path / "run")
    for key in ("tracking_mae_um", "sync_mae_um"):
        for ours, fit in zip(m[key], rec[f"apd_{key}"]):
            assert fit / factor <= ours <= fit * factor, (target, key, m[key], rec[f"apd_{key}"])


@pytest.mark.parametrize("target", cal.TARGETS)
def test_the_written_scenario_is_the_shipped_file_and_carries_no_wall_time(target):
    # `tapmp calibrate --write-to` with the shipped fit writes the shipped file byte for byte: a rerun
    # that finds the same fit leaves the tracked file unchanged, however long it took
    path = cal.calibrated_file(target)
    rec = cal.read_fit_record(path)
    theta = [rec[p.name] for p in cal.PARAMETERS]
    evaluations, horizon = re.search(r"(\d+) co-simulations of ([\d.]+) s", path.read_text()).groups()
    pred = {"objective_full": rec["objective_full"], "residuals_full": rec["residuals_full"]}
    for law, tag in (("apd-dc", "apd"), ("sc-dc", "scdc")):
        pred[law] = {"metrics": {k: rec[f"{tag}_{k}"] for k in ("tracking_mae_um", "tracking_std_um", "sync_mae_um",
                                                                 "sync_std_um")}}
    texts = {cal.scenario_text(target, {"theta": theta, "values": cal.check_theta(theta), "evaluations": int(evaluations),
                                        "horizon_s": float(horizon), "objective": rec["objective_fit"], "wall_s": wall},
                               pred) for wall in (34.0, 82.0)}
    assert texts == {path.read_text()}
