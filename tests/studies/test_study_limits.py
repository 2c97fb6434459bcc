"""A study's case count is checked before any case is listed: above the cap a one-line refusal
naming the count and how to raise it (no grid is built, so three 3000-value keys cost nothing)."""

import re
import subprocess
import sys
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


SIZES = "3000 values of gain_overrides.D x 3000 values of gain_overrides.b x 3000 values of gain_overrides.Lambda_v"
MEMORY = re.compile(r"listing them needs about 80\.6 TB of memory and this machine has [0-9.]+ [kMGT]?B free: make "
                    r"the grid smaller or split it into studies")


def test_three_3000_value_grid_keys_are_refused_naming_the_count_and_never_a_cap_that_cannot_run(tmp_path, capsys):
    """27e9 cases cannot be listed in memory (27e9 x 2987 B): the refusal names the memory, not a --max-cases."""
    path = big_study(tmp_path, 3000)
    assert case_count(load_study(path)) == 27_000_000_000
    code = main(["study", path, "--ssp", __file__, "--out", tmp_path / "o"])
    (err,) = capsys.readouterr().err.splitlines()
    assert code == 2 and "--max-cases" not in err
    assert err.startswith(f"error: big has 27000000000 cases ({SIZES}): allowed are at most {MAX_CASES} cases; ")
    assert MEMORY.fullmatch(err.split("; ", 1)[1]), err


@pytest.mark.slow  # seconds: runs tapmp or pytest in a fresh Python process
def test_a_grid_that_does_not_fit_in_memory_is_refused_before_it_is_listed(tmp_path):
    """With the case cap raised to the count, the memory check refuses: exit 2, one line naming the
    estimate and the free memory, and the command's peak memory stays that of starting it."""
    # the peak of this process's own memory (VmHWM [kB]: its address space's high-water mark; ru_maxrss would
    # also count the forking test process's size, which Linux carries across exec)
    code = ("import re, sys\nfrom orchestrator.cli import main\ncode = main(sys.argv[1:])\n"
            "print(re.search(r'VmHWM:\\s+(\\d+) kB', open('/proc/self/status').read())[1])\nsys.exit(code)")
    res = subprocess.run([sys.executable, "-c", code, "study", str(big_study(tmp_path, 3000)), "--ssp", __file__,
                          "--out", str(tmp_path / "o"), "--max-cases", "27000000000"],
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 2, res.stderr
    (err,) = res.stderr.splitlines()
    assert err.startswith(f"error: big has 27000000000 cases ({SIZES}): ")
    assert MEMORY.fullmatch(err.split("): ", 1)[1]), err
    assert int(res.stdout) < 500_000  # [kB]: the 80 TB list was never started (importing the CLI takes ~150 MB)
    assert not (tmp_path / "o").exists()


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
