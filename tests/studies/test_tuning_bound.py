"""Tuning under a robustness bound: every candidate whose peak sensitivity Ms on a mode exceeds
[tune] ms_bound is rejected without running, the tuned preset stays within the bound, an
unreachable bound is an error and not a preset, and a bad bound is one line with exit code 2."""

from pathlib import Path

import pytest

from orchestrator.cli import main
from orchestrator.tool.robustness import mode_peaks
from orchestrator.tool.scenario import load
from orchestrator.studies.run import run_study
from orchestrator.studies.study import StudyError, load_study, read_study_csv
from tests.support.studies import client, write_study  # noqa: F401 (client is a fixture)

ROOT = Path(__file__).resolve().parents[2]
BASE = ROOT / "scenarios" / "paper_simulation.toml"


def tuning_study(folder: Path, tune: str) -> Path:
    """A study that tunes SC-DC on 0.02 s runs; ``tune`` adds to its [tune] table."""
    return write_study(folder, f'[set]\nstop_time = 0.02\n[tune]\nlaws = ["sc-dc"]\nwrite_to = "{folder / "tuned"}"\n'
                       f'compare_stop_time = 0.02\nseed = 3\n{tune}\n'
                       '[tune.bounds.sc-dc]\nLambda_v = [0.05, 2.0]\nLambda_p = [10.0, 3000.0]\n')


@pytest.mark.slow
def test_the_constrained_tuning_never_returns_a_design_beyond_its_bound(built, client, tmp_path):
    bound = 1.6  # below the start gains' 2.55: the start itself is rejected
    study = load_study(tuning_study(tmp_path, f"population = 4\ngenerations = 2\nms_bound = {bound}"))
    summary = run_study(study, built["ssp"], client, progress=False, command="tapmp study s.toml")
    r = summary["tuning"]["sc-dc"]
    assert r["start"] is None and "above tune.ms_bound = 1.6" in r["start_note"]
    tuned = load(BASE, [f'gains_file = "{r["preset"]}"', 'law = "sc-dc"'])
    assert max(mode_peaks(tuned).values()) <= bound
    rows = [row for row in read_study_csv(tmp_path / "out" / "study.csv") if row["case"].startswith("sc-dc-")]
    beyond = [row for row in rows if "above tune.ms_bound" in (row["error"] or "")]
    done = [row for row in rows if row["status"] == "completed"]
    assert beyond and done
    base = load(BASE, ['law = "sc-dc"'])
    for row in done:  # every design that was run is within the bound, every one refused is beyond it
        sc = base.with_changes(gain_overrides={"Lambda_v": [row["Lambda_v"]] * 3, "Lambda_p": [row["Lambda_p"]] * 3})
        assert max(mode_peaks(sc).values()) <= bound
    for row in beyond[:3]:
        sc = base.with_changes(gain_overrides={"Lambda_v": [row["Lambda_v"]] * 3, "Lambda_p": [row["Lambda_p"]] * 3})
        assert max(mode_peaks(sc).values()) > bound
        assert not (tmp_path / "out" / "cases" / row["case"]).exists()  # not run
    assert "Ms beyond the bound" in (tmp_path / "out" / "tuning" / "comparison.md").read_text()


@pytest.mark.slow
def test_an_unreachable_bound_is_an_error_and_writes_no_preset(built, client, tmp_path):
    study = load_study(tuning_study(tmp_path, "population = 2\ngenerations = 1\nms_bound = 1.0"))
    with pytest.raises(StudyError, match=r"^tune: no candidate of sc-dc was stable with Ms <= tune.ms_bound = 1.0 "):
        run_study(study, built["ssp"], client, progress=False)
    assert not (tmp_path / "out" / "tuning" / "sc-dc.toml").exists()


@pytest.mark.parametrize("value", ["inf", "nan", "0.5", '"2"', "-3.0"])
def test_a_bound_that_is_not_finite_or_below_one_is_one_line_naming_it(tmp_path, capsys, value):
    path = tuning_study(tmp_path, f"ms_bound = {value}")
    assert main(["study", str(path), "--workers", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and "tune.ms_bound = " in err[0]
    assert err[0].endswith("is invalid: allowed is a finite number >= 1 (the largest peak sensitivity Ms on any mode)")


@pytest.mark.parametrize("value", ["inf", "0.0", '"1e-4"', "-1e-4"])
def test_a_delay_margin_bound_that_is_not_a_finite_positive_number_is_one_line_naming_it(tmp_path, capsys, value):
    path = tuning_study(tmp_path, f"delay_margin_min = {value}")
    assert main(["study", str(path), "--workers", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "tune.delay_margin_min = " in err[0]
    assert err[0].endswith("is invalid: allowed is a finite number > 0 [s] (the smallest delay margin, all motors)")


def test_pid_dc_full_is_tuned_on_its_modal_gains_and_a_gain_it_does_not_read_is_one_line(tmp_path, capsys):
    path = write_study(tmp_path, '[set]\nstop_time = 0.02\n[tune]\nlaws = ["pid-dc-full"]\n'
                       f'write_to = "{tmp_path / "tuned"}"\n[tune.bounds.pid-dc-full]\nLambda_p = [10.0, 100.0]\n')
    assert main(["study", str(path), "--workers", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "tune.bounds.pid-dc-full.Lambda_p" in err[0]
    assert "allowed are kp_c, kp_d, kv_c, kv_d, ki" in err[0]


@pytest.mark.slow
def test_the_delay_margin_bound_rejects_exactly_the_designs_below_it_and_pid_dc_full_gets_one_integral_gain(
        built, client, tmp_path):
    bound = 3e-4  # [s]: below SC-DC's modal gains' 0.18 ms, so the start of pid-dc-full is rejected
    path = write_study(tmp_path, '[set]\nstop_time = 0.02\n[tune]\nlaws = ["pid-dc-full"]\npopulation = 2\n'
                       f'generations = 1\nseed = 3\nms_bound = 3.0\ndelay_margin_min = {bound}\n'
                       f'write_to = "{tmp_path / "tuned"}"\ncompare_stop_time = 0.02\n'
                       '[tune.bounds.pid-dc-full]\nkp_c = [5.0, 500.0]\nkp_d = [10.0, 2000.0]\nkv_c = [0.05, 1.0]\n'
                       'kv_d = [0.05, 1.0]\nki = [100.0, 100000.0]\n')
    summary = run_study(load_study(path), built["ssp"], client, progress=False, command="tapmp study s.toml")
    r = summary["tuning"]["pid-dc-full"]
    assert r["start"] is None and "below tune.delay_margin_min = 300 us" in r["start_note"]
    rows = [row for row in read_study_csv(tmp_path / "out" / "study.csv") if row["case"].startswith("pid-dc-full-")]
    base = load(BASE, [])

    def margin(row):
        from orchestrator.studies.tuning import all_motors_delay_margin, candidate_changes
        from orchestrator.studies.study_file import apply_changes
        values = {n: row[n] for n in ("kp_c", "kp_d", "kv_c", "kv_d", "ki")}
        return all_motors_delay_margin(apply_changes(base, candidate_changes("pid-dc-full", values)))
    below = [row for row in rows if "below tune.delay_margin_min" in (row["error"] or "")]
    done = [row for row in rows if row["status"] == "completed"]
    assert below and done
    assert all(margin(row) >= bound for row in done) and all(margin(row) < bound for row in below[:3])
    best = min(done, key=lambda row: row["objective"])
    preset = (tmp_path / "out" / "tuning" / "pid-dc-full.toml").read_text()
    assert 'law = "pid-dc"' in preset and "[controller]" in preset
    assert f"ki_c = {best['ki']!r}" in preset and f"ki_d = {best['ki']!r}" in preset
