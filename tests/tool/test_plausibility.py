"""Parameters far outside this machine's usual range: one warning line each, the run goes on."""

import subprocess
import sys
from pathlib import Path

import pytest

from orchestrator.tool.plausibility import USUAL, implausible
from orchestrator.tool.scenario import load

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "scenarios" / "paper_simulation.toml"


def test_the_paper_scenarios_and_the_defaults_are_plausible():
    for name in ("paper_simulation", "paper_experiment", "paper_simulation_tuned"):
        assert implausible(load(ROOT / "scenarios" / f"{name}.toml")) == []
    assert implausible(load(PAPER, ["plant.force_limit=0", "plant.encoder_resolution=0", "plant.k_pull=0"])) == []


def test_each_implausible_value_is_one_line_naming_value_and_range():
    sc = load(PAPER, ["plant.encoder_resolution=0.5", "controller.m_p=1835.0", "plant.force_limit=1e6"])
    lines = implausible(sc)
    assert "plant.encoder_resolution = 0.5 m is far outside the usual range for this machine (1e-09 to 0.0001 m); " \
           "running anyway" in lines
    assert "controller.m_p = 1835 kg is far outside the usual range for this machine (0.1 to 50 kg); running anyway" \
           in lines
    assert "plant.force_limit = 1e+06 N is far outside the usual range for this machine (10 to 10000 N); " \
           "running anyway" in lines
    assert len(lines) == 3
    assert USUAL[("plant", "encoder_resolution")][1] == 1e-4  # the bound


@pytest.mark.slow
def test_the_cli_prints_one_warning_line_and_runs(built, tmp_path):
    res = subprocess.run([sys.executable, "-m", "orchestrator", "run", str(PAPER), "--ssp", str(built["ssp"]),
                          "--out", str(tmp_path / "r"), "--set", "stop_time=0.01", "--set",
                          "plant.encoder_resolution=0.5", "--no-progress"], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    warnings = [line for line in res.stderr.splitlines() if line.startswith("warning:")]
    assert warnings == ["warning: plant.encoder_resolution = 0.5 m is far outside the usual range for this machine "
                        "(1e-09 to 0.0001 m); running anyway"]
    assert (tmp_path / "r" / "metrics.json").is_file()
