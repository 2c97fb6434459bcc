"""A study's case count is checked before any case is listed: above the cap a one-line refusal
naming the count and how to raise it (no grid is built, so three 3000-value keys cost nothing)."""

from pathlib import Path

import pytest

from orchestrator.cli import main
from orchestrator.studies.study import MAX_CASES, StudyError, case_count, cases, load_study

ROOT = Path(__file__).resolve().parents[2]
BASE = ROOT / "scenarios" / "paper_simulation.toml"


def big_study(folder: Path, n: int, samples: int = 0) -> Path:
    values = ", ".join(str(float(400 + i)) for i in range(n))
    text = (f'[study]\nname = "big"\nbase = "{BASE}"\n[grid]\n"gain_overrides.D" = [{values}]\n'
            f'"gain_overrides.b" = [{values}]\n"gain_overrides.Lambda_v" = [{values}]\n')
    if samples:
        text += (f'[monte_carlo]\nsamples = {samples}\nseed = 1\n[monte_carlo.vary.m]\ntargets = ["plant.m_1"]\n'
                 'distribution = "uniform"\nlow = 4.0\nhigh = 5.0\n')
    path = folder / "big.toml"
    path.write_text(text)
    return path


def test_three_3000_value_grid_keys_are_refused_naming_the_count_and_the_option(tmp_path, capsys):
    path = big_study(tmp_path, 3000)
    assert case_count(load_study(path)) == 27_000_000_000
    code = main(["study", path, "--ssp", __file__, "--out", tmp_path / "o"])
    err = capsys.readouterr().err.splitlines()
    assert code == 2 and err == [
        "error: big has 27000000000 cases (3000 values of gain_overrides.D x 3000 values of gain_overrides.b x 3000 "
        f"values of gain_overrides.Lambda_v): allowed are at most {MAX_CASES} cases; pass --max-cases 27000000000 to "
        "run them all"]


def test_the_cap_counts_monte_carlo_samples_and_max_cases_raises_it(tmp_path):
    study = load_study(big_study(tmp_path, 2, samples=3))
    assert case_count(study) == 24
    with pytest.raises(StudyError, match="big has 24 cases .* x 3 samples\\): allowed are at most 20 cases; "
                       "pass --max-cases 24"):
        cases(study, 20)
    assert len(cases(study, 24)) == 24


def test_max_cases_below_1_is_refused(tmp_path, capsys):
    code = main(["study", big_study(tmp_path, 2), "--ssp", __file__, "--max-cases", "0"])
    assert code == 2 and capsys.readouterr().err.splitlines()[-1] == (
        "error: --max-cases = 0 is invalid: allowed is an integer >= 1")
