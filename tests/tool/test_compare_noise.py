"""The noise comparison of every `tapmp compare`: SC-DC, APD-DC and the matched baselines again
with seeded measurement noise at 20 and 100 nm rms, through the real CLI and FMUs on a short
horizon; comparison.md's table holds the noise runs' own numbers (their metrics.json), the seed
makes a noise run repeat exactly, and --no-noise leaves the runs and the table out."""

import json
from pathlib import Path

import pytest

from orchestrator.cli import main
from orchestrator.tool.compare import NOISE_LEVELS, NOISE_RUNS, NOISE_SEED

pytestmark = pytest.mark.slow  # tapmp compare through the real CLI

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "scenarios" / "paper_simulation.toml"
STOP = "stop_time=0.03"


def _mean(v) -> float:
    return sum(v) / len(v)


def _compare(built, out: Path, *extra) -> Path:
    assert main(["compare", str(PAPER), "--ssp", str(built["ssp"]), "--out", str(out), "--set", STOP,
                 "--no-progress", "--no-figures", *extra]) == 0
    return out


@pytest.fixture(scope="module")
def comparisons(built, tmp_path_factory):
    base = tmp_path_factory.mktemp("noise")
    return _compare(built, base / "first"), _compare(built, base / "second")


def _metrics(folder: Path) -> dict:
    return json.loads((folder / "metrics.json").read_text())


def test_the_noise_table_holds_the_numbers_of_the_noise_runs(comparisons):
    out, _ = comparisons
    text = (out / "comparison.md").read_text()
    section = text[text.index("## Measurement noise: SC-DC, APD-DC and the matched baselines"):]
    lines = section.splitlines()
    sc = {0.0: _metrics(out / "sc-dc"), **{x: _metrics(out / "noise" / f"sc-dc-{1e9 * x:g}nm") for x in NOISE_LEVELS}}
    for run in NOISE_RUNS:
        by = {0.0: _metrics(out / run), **{x: _metrics(out / "noise" / f"{run}-{1e9 * x:g}nm") for x in NOISE_LEVELS}}
        levels = (0.0, *NOISE_LEVELS)
        tracking = ", ".join(f"{_mean(by[x]['tracking_mae_um']):.4f}" for x in levels)
        sync = ", ".join(f"{_mean(by[x]['sync_mae_um']):.4f}" for x in levels)
        force = ", ".join(f"{_mean(by[x]['force_hf_rms_n']):.3g}" for x in levels)
        red = ", ".join(f"{100 * (_mean(by[x]['sync_mae_um']) - _mean(sc[x]['sync_mae_um'])) / _mean(by[x]['sync_mae_um']):+.1f}"
                        for x in levels)
        assert f"| `{run}` | {tracking} | {sync} | {force} | {red} |" in lines, run
        for x in NOISE_LEVELS:  # each noise run is its compare run with the seeded noise, nothing else
            plain = json.loads((out / run / "run.json").read_text())["scenario"]
            noisy = json.loads((out / "noise" / f"{run}-{1e9 * x:g}nm" / "run.json").read_text())["scenario"]
            assert (noisy["plant"]["noise_rms"], noisy["plant"]["noise_seed"]) == (x, NOISE_SEED)
            assert {k: v for k, v in noisy["plant"].items() if not k.startswith("noise")} == plain["plant"]
            assert (noisy["law"], noisy["controller"], noisy["gain_overrides"]) == (
                plain["law"], plain["controller"], plain["gain_overrides"])
        assert by[NOISE_LEVELS[-1]]["sync_mae_um"] != by[0.0]["sync_mae_um"]  # the noise reaches the loop


def test_the_seed_makes_the_noise_runs_repeat(comparisons):
    first, second = comparisons
    for run in NOISE_RUNS:
        for x in NOISE_LEVELS:
            a, b = (_metrics(out / "noise" / f"{run}-{1e9 * x:g}nm") for out in (first, second))
            assert (a["tracking_mae_um"], a["sync_mae_um"], a["force_hf_rms_n"]) == (
                b["tracking_mae_um"], b["sync_mae_um"], b["force_hf_rms_n"])
    section = (first / "comparison.md").read_text().split("## Measurement noise")[1]
    assert section == (second / "comparison.md").read_text().split("## Measurement noise")[1]


def test_no_noise_leaves_out_the_noise_runs_and_their_table(built, tmp_path):
    out = _compare(built, tmp_path / "cmp", "--no-noise")
    assert not (out / "noise").exists()
    assert "## Measurement noise" not in (out / "comparison.md").read_text()


def test_a_scenario_with_its_own_noise_heads_the_first_column_with_it(built, tmp_path):
    out = _compare(built, tmp_path / "cmp", "--set", "plant.noise_rms=5e-8")
    text = (out / "comparison.md").read_text()
    assert "| run | tracking MAE [um] at 50, 20, 100 nm | sync MAE [um] at 50, 20, 100 nm |" in text
    assert "% at 50 nm rms (the scenario's own) and " in text
    run = json.loads((out / "sc-dc" / "run.json").read_text())["scenario"]
    assert run["plant"]["noise_rms"] == 5e-8
