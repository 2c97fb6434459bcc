"""The tuned presets shipped in docs/tuning/ (written by `tapmp study studies/tune.toml --write-docs`)
stay within the tuning's robustness bound: the peak sensitivity Ms of every mode of each preset's
sampled loop, computed as `tapmp analyze` does, is at most studies/tune.toml's ms_bound."""

from pathlib import Path

import pytest

from orchestrator.tool.robustness import MODES, mode_peaks
from orchestrator.tool.scenario import load
from orchestrator.tool.stability import check
from orchestrator.studies.study import load_study

ROOT = Path(__file__).resolve().parents[2]
TUNE = ROOT / "studies" / "tune.toml"


@pytest.mark.parametrize("law", ["sc-dc", "apd-dc"])
def test_each_shipped_tuned_preset_has_its_peak_sensitivity_within_the_tuning_bound(law, tmp_path):
    study = load_study(TUNE)
    bound = study.tune["ms_bound"]
    assert bound == 2.0
    preset = ROOT / study.tune["write_to"] / f"{law}.toml"
    scenario = tmp_path / "tuned.toml"  # the study's base scenario with the preset as its gains_file
    scenario.write_text(Path(study.base).read_text().replace('gains = "default"', f'gains_file = "{preset}"'))
    sc = load(scenario).with_changes(law=law)
    assert sc.gain_values().Lambda_p[0] != 300.0  # the preset's gains, not the default preset's
    assert check(sc).stable
    peaks = mode_peaks(sc)
    assert set(peaks) == set(MODES)
    assert max(peaks.values()) <= bound, peaks
