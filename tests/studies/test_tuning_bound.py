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
