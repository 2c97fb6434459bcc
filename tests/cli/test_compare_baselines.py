"""`tapmp compare`'s fair baselines and SC-DC ablations, on a 0.05 s horizon
through the real CLI and FMUs: every row exists with the numbers of its run, the gains each run
gets are the hand-derived modal gains of the scenario's preset, and what is identical is pinned
on the plant's true positions."""

import csv
import json
import re
from pathlib import Path

import numpy as np
import pytest

from orchestrator.cli import main
from orchestrator.tool.baselines import BASELINES, compare_runs, differential_stiffness, scdc_modal
from orchestrator.tool.scenario import load
from orchestrator.tool.stability import check

pytestmark = pytest.mark.slow  # tapmp compare through the real CLI

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "scenarios" / "paper_simulation.toml"
# default preset: Lambda_v = 0.36, D = 900, Lambda_p = 300, b = 50 on every motor
LVD = 0.36 * 900.0                        # common-mode P: 324
KP_D = LVD + 3.0 * (0.36 * 50.0 + 300.0)  # differential-mode P: 1278
KI_D = 3.0 * 0.36 * 900.0 * 50.0          # differential-mode I: 48600


@pytest.fixture(scope="module")
def comparison(built, tmp_path_factory):
    out = tmp_path_factory.mktemp("baselines") / "cmp"
    assert main(["compare", str(PAPER), "--ssp", str(built["ssp"]), "--out", str(out), "--set", "stop_time=0.05",
                 "--no-progress"]) == 0
    return out


def _true_positions(folder: Path) -> np.ndarray:
    with open(folder / "results.csv", newline="") as f:
        rows = list(csv.reader(f))
    cols = [rows[0].index(f"plant.q{i}_true") for i in (1, 2, 3)]
    return np.array([[float(r[c]) for c in cols] for r in rows[1:]])


def _cells(values) -> str:
    return " | ".join(f"{v:.3f}" for v in values)


def test_every_baseline_is_a_row_with_the_numbers_of_its_run(comparison):
    text = (comparison / "comparison.md").read_text()
    runs = compare_runs(load(PAPER, ["stop_time=0.05"]))
    for b in BASELINES:
        m = json.loads((comparison / b.name / "metrics.json").read_text())
        assert m["samples"] == 501
        for std, mae in (("tracking_std_um", "tracking_mae_um"), ("sync_std_um", "sync_mae_um"),
                         ("axis_std", "axis_mae")):
            assert f"| ours: {b.label} | {_cells((*m[std], *m[mae]))} |" in text, (b.name, std)
        # the runs table: what it isolates, the pre-check and the saturation of this run
        row = next(line for line in text.splitlines() if line.startswith(f"| `{b.name}` |"))
        assert b.isolates in row
        assert f"| {check(runs[b.name]).spectral_radius:.6f}, stable |" in row
        assert row.endswith(" | " + ", ".join(f"{100 * v:.3g}" for v in m["saturation_fraction"]) + " |")
    # SC-DC's reductions against the paper's and the two fair baselines
    for label in ("APD-DC", "APD-DC, differential-mode stiffness", "APD-DC mode-matched"):
        assert f"| ours: reduction of SC-DC vs {label} (%) |" in text


def test_each_run_gets_the_hand_derived_gains_of_the_default_preset(comparison):
    def scenario(name):
        return json.loads((comparison / name / "run.json").read_text())["scenario"]

    assert scenario("apd-dc-matched")["gain_values"]["Lambda_p"] == pytest.approx([LVD] * 3, rel=1e-15)
    assert scenario("apd-dc-diff-stiffness")["gain_values"]["Lambda_p"] == pytest.approx([KP_D] * 3, rel=1e-15)
    for name, ki_d in (("apd-dc-mode-matched", 0.0), ("pid-dc-mode-matched", KI_D)):
        s = scenario(name)
        assert s["law"] == "pid-dc"
        c = s["controller"]
        assert (c["kp_c"], c["kv_c"], c["ki_c"]) == pytest.approx((LVD, 0.36, 0.0), rel=1e-15)
        assert (c["kp_d"], c["kv_d"], c["ki_d"]) == pytest.approx((KP_D, 0.36, ki_d), rel=1e-15)
    assert scenario("sc-dc-b0")["gain_values"]["b"] == [0.0, 0.0, 0.0]
    assert scenario("sc-dc-lp0")["gain_values"]["Lambda_p"] == [0.0, 0.0, 0.0]
    assert scenario("sc-dc-b0")["gain_values"]["Lambda_p"] == [300.0] * 3  # one change per ablation


def test_pid_dc_mode_matched_is_scdc_on_the_true_positions(comparison):
    sc, pid = _true_positions(comparison / "sc-dc"), _true_positions(comparison / "pid-dc-mode-matched")
    assert sc.shape == (501, 3)
    assert np.max(np.abs(sc - pid)) < 1e-12
    # the integral matters on this horizon: without it (apd-dc-mode-matched) the motion differs
    assert np.max(np.abs(sc - _true_positions(comparison / "apd-dc-mode-matched"))) > 1e-9


def test_scdc_with_b0_is_the_pid_dc_without_integral_of_its_own_gains(comparison, built, tmp_path):
    """b = 0 removes the integral and 3 Lambda_v b from the differential P: SC-DC b = 0 is PID-DC with
    kp_c = Lambda_v D = 324, kp_d = Lambda_v D + 3 Lambda_p = 1224, ki = 0 (identical to round-off),
    not the mode-matched APD-DC (kp_d = 1278)."""
    out = tmp_path / "pid"
    sets = ["stop_time=0.05", 'law="pid-dc"', f"controller.kp_c={LVD!r}", f"controller.kp_d={LVD + 900.0!r}",
            "controller.kv_c=0.36", "controller.kv_d=0.36", "controller.ki_c=0", "controller.ki_d=0"]
    assert main(["run", str(PAPER), "--ssp", str(built["ssp"]), "--out", str(out), "--no-progress",
                 *[a for s in sets for a in ("--set", s)]]) == 0
    b0 = _true_positions(comparison / "sc-dc-b0")
    assert np.max(np.abs(b0 - _true_positions(out))) < 1e-12
    assert np.max(np.abs(b0 - _true_positions(comparison / "apd-dc-mode-matched"))) > 1e-9


def test_modal_gains_follow_a_uniform_override_and_a_non_uniform_preset():
    s = load(PAPER, ["gain_overrides.D=500", "gain_overrides.b=20"])
    runs = compare_runs(s)
    pid = runs["pid-dc-mode-matched"].controller
    assert (pid["kp_c"], pid["kp_d"], pid["ki_d"]) == pytest.approx(
        (0.36 * 500, 0.36 * 500 + 3 * (0.36 * 20 + 300), 3 * 0.36 * 500 * 20), rel=1e-15)
    assert runs["apd-dc-diff-stiffness"].gain_values().Lambda_p == pytest.approx([0.36 * 500 + 3 * (7.2 + 300)] * 3)
    assert runs["sc-dc-b0"].gain_values().D == (500.0,) * 3  # the override is kept
    # Eq. 42 (gains differ between motors): projected modal gains. Common mode: (1/3) sum_ij K_P[i][j] =
    # mean(Lambda_v D) as L's rows sum to zero; the I of the common mode is 0 for the same reason.
    e = load(PAPER, ['gains="paper_experiment"'])
    mg, note = scdc_modal(e.gain_values())
    assert mg.kp_c == pytest.approx((30 * 50 + 30 * 50 + 28 * 50) / 3, rel=1e-12) and mg.ki_c == 0.0
    assert mg.kv_c == pytest.approx((30 + 30 + 28) / 3, rel=1e-12)
    assert note.startswith("projected") and "coupling" in note
    assert differential_stiffness(e.gain_values()) == pytest.approx(
        [lv * 50 + 3 * (lv * b + lp) for lv, b, lp in ((30, 0.00059, 3.8), (30, 0.00051, 3.0), (28, 0.00059, 4.0))])
    assert scdc_modal(load(PAPER).gain_values())[1].startswith("exact")


def test_a_baseline_the_precheck_finds_unstable_is_warned_about_and_run(built, tmp_path, capsys):
    # Lambda_v = 10 (D = 900): kv / K_T far beyond what a 0.1 ms loop tolerates, for every run
    out = tmp_path / "cmp"
    assert main(["compare", str(PAPER), "--ssp", str(built["ssp"]), "--out", str(out), "--no-progress",
                 "--set", "stop_time=0.002", "--set", "gain_overrides.Lambda_v=10"]) == 0
    err = capsys.readouterr().err
    assert re.search(r"warning: paper_simulation apd-dc-mode-matched: the sampled closed loop is unstable "
                     r"\(spectral radius [0-9.]+", err)
    assert "unstable |" in (out / "comparison.md").read_text()
