"""The tuned presets shipped in docs/tuning/ (written by `tapmp study studies/tune.toml --write-docs`)
meet the tuning's bounds as the tuner computes them, on the loop with the default drive in it: the peak
sensitivity Ms of every mode at most studies/tune.toml's ms_bound and the delay margin with every motor
delayed at once at least its delay_margin_min; and each is stable with one sample of delay (Jacobi, no
drive) and with the default drive."""

import tomllib
from pathlib import Path

import pytest

from orchestrator.studies.study import load_study
from orchestrator.studies.study_file import FULL_PID, apply_changes
from orchestrator.studies.tuning import all_motors_delay_margin
from orchestrator.tool.robustness import MODES, mode_peaks
from orchestrator.tool.scenario import load
from orchestrator.tool.stability import check

ROOT = Path(__file__).resolve().parents[2]
TUNE = ROOT / "studies" / "tune.toml"
LAWS = ["sc-dc", "apd-dc", FULL_PID]


def tuned(law: str, tmp_path: Path, changes: dict):
    """The study's base scenario (without its [set]) with the shipped preset of ``law`` and ``changes``."""
    study = load_study(TUNE)
    preset = ROOT / study.tune["write_to"] / f"{law}.toml"
    if law == FULL_PID:  # the law and the [controller] settings the preset names
        text = tomllib.loads(preset.read_text())
        base = load(study.base)
        return apply_changes(base, {"law": text["law"], **{f"controller.{k}": v for k, v in text["controller"].items()},
                                    **changes})
    scenario = tmp_path / "tuned.toml"
    scenario.write_text(Path(study.base).read_text().replace('gains = "default"', f'gains_file = "{preset}"'))
    sc = apply_changes(load(scenario), {"law": law, **changes})
    assert sc.gain_values().Lambda_p[0] != 300.0  # the preset's gains, not the default preset's
    return sc


def test_the_tuning_bounds_are_ms_2_and_one_sample_of_delay_beyond_the_drive():
    study = load_study(TUNE)
    assert study.tune["laws"] == LAWS and study.set["drive"] is True
    assert study.tune["ms_bound"] == 2.0 and study.tune["delay_margin_min"] == load(study.base).step == 1e-4


@pytest.mark.parametrize("law", LAWS)
def test_each_shipped_tuned_preset_meets_ms_and_the_delay_margin_with_the_drive(law, tmp_path):
    spec = load_study(TUNE).tune
    sc = tuned(law, tmp_path, {"drive": True})
    assert check(sc).stable
    peaks = mode_peaks(sc)
    assert set(peaks) == set(MODES)
    assert max(peaks.values()) <= spec["ms_bound"], peaks
    assert all_motors_delay_margin(sc) >= spec["delay_margin_min"]


@pytest.mark.parametrize("law", LAWS)
@pytest.mark.parametrize("delay", [{"ordering": "jacobi"}, {"drive": True}], ids=["jacobi", "drive"])
def test_each_shipped_tuned_preset_is_stable_with_one_sample_of_delay_and_with_the_drive(law, delay, tmp_path):
    assert check(tuned(law, tmp_path, delay)).spectral_radius < 1.0
