"""What the README and docs/studies.md say about the robustness and tuning studies follows their
runs: the Monte Carlo tables are those the shipped study file writes (summary.md), the tuning
sentences are the reductions of docs/tuning/comparison.md and the presets' own Ms."""

import os
import re
from pathlib import Path

import pytest

from orchestrator.cli import main
from orchestrator.tool.robustness import mode_peaks
from orchestrator.tool.scenario import load

ROOT = Path(__file__).resolve().parents[2]
README = (ROOT / "README.md").read_text()
STUDIES = (ROOT / "docs" / "studies.md").read_text()
TUNING = (ROOT / "docs" / "tuning" / "comparison.md").read_text()


def _flat(text: str) -> str:
    return " ".join(text.split())


def _reductions(table: str) -> list[float]:
    """The MAE cells (q1-q3) of the 'reduction of SC-DC vs APD-DC' row of comparison.md's ``table``."""
    section = TUNING[TUNING.index(table):]
    row = next(line for line in section.splitlines() if line.startswith("| ours: reduction of SC-DC vs APD-DC"))
    return [float(c) for c in row.strip("|").split("|")[4:7]]


def _full_horizon(law: str) -> tuple[list[float], list[float]]:
    """(tracking, synchronization MAE per motor [um]) of comparison.md's full-horizon row of tuned ``law``."""
    row = next(line for line in TUNING.splitlines() if line.startswith(f"| {law} | tuned |"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    return [float(v) for v in cells[3].split(",")], [float(v) for v in cells[4].split(",")]


def test_the_tuning_claims_are_the_reductions_of_the_tuned_comparison_and_the_presets_ms(tmp_path):
    from tests.studies.test_tuned_presets import tuned
    tracking = _reductions("### Comparison of the tracking error of each motor")
    sync = _reductions("### Comparison of the synchronization error of each motor")
    ms = {law: f"{max(mode_peaks(tuned(law, tmp_path, {'drive': True})).values()):.2f}"
          for law in ("sc-dc", "apd-dc", "pid-dc-full")}
    (t_sc, y_sc), (t_pid, y_pid) = _full_horizon("sc-dc"), _full_horizon("pid-dc-full")
    mean = lambda v: sum(v) / len(v)  # noqa: E731
    t = ", ".join(f"{x:.1f}" for x in tracking[:2]) + f" and {tracking[2]:.1f} % lower on the three motors"
    y = f"synchronization MAE {round(min(sync))}-{round(max(sync))} % lower"
    pid = (f"{round(100 * (1 - mean(t_pid) / mean(t_sc)))} % lower mean tracking MAE than tuned SC-DC "
           f"({mean(t_pid):.4f} against {mean(t_sc):.4f} um) and an {round(100 * (1 - mean(y_pid) / mean(y_sc)))} % "
           "lower synchronization MAE")
    readme = _flat(README)
    assert f"presets reach Ms {ms['sc-dc']} (SC-DC), {ms['apd-dc']} (APD-DC) and {ms['pid-dc-full']} (`pid-dc-full`)" in readme
    assert f"SC-DC's tracking MAE against tuned APD-DC's is {t} and its {y}" in readme
    assert pid in readme
    studies = _flat(STUDIES)
    assert (f"the largest Ms over the modes is {ms['sc-dc']} for SC-DC, {ms['apd-dc']} (" in studies
            and f"for APD-DC and {ms['pid-dc-full']} for `pid-dc-full`" in studies)
    assert f"SC-DC's tracking MAE against APD-DC's is {t} (higher on motor 3) and its {y}" in studies
    assert pid.replace(" than tuned SC-DC", " than SC-DC").replace(" lower synchronization MAE",
                                                                  " lower mean synchronization MAE") in studies


@pytest.mark.slow  # the shipped robustness study, 200 cases of 1 s on two Dask workers (about a minute)
def test_the_robustness_tables_and_claims_are_those_the_shipped_study_writes(built, tmp_path, capsys):
    text = (ROOT / "studies" / "robustness.toml").read_text()
    text = re.sub(r'(?m)^output = ".*"$', f'output = "{tmp_path / "out"}"', text)
    text = text.replace('base = "../scenarios/', f'base = "{ROOT / "scenarios"}/')
    (tmp_path / "robustness.toml").write_text(text)
    assert main(["study", str(tmp_path / "robustness.toml"), "--ssp", built["ssp"],
                 "--workers", str(min(2, os.cpu_count() or 1)), "--no-progress"]) == 0
    summary = (tmp_path / "out" / "summary.md").read_text()
    rows = [line for line in summary.splitlines() if line.startswith("| ") and not line.startswith("| baseline")]
    assert len(rows) == 5 + 4
    for row in rows:  # both tables of docs/studies.md, row by row
        assert row in STUDIES.splitlines(), row
    cells = {r.split("|")[1].strip(): [c.strip() for c in r.strip("|").split("|")[1:]] for r in rows[:5]}
    med = {k: (v[1].split(" / ")[0], v[2].split(" / ")[0]) for k, v in cells.items()}
    readme = _flat(README)
    assert f"(median synchronization MAE {med['sc-dc'][1]} against {med['apd-dc'][1]} um)" in readme
    assert f"(median {med['pid-dc-full'][0]} against {med['sc-dc'][0]} um)" in readme
    paired = {r.split("|")[1].strip(): [c.strip() for c in r.strip("|").split("|")[1:]] for r in rows[5:]}
    assert paired["apd-dc"][0] == paired["apd-dc"][2] == "40 of 40"  # "beats APD-DC on both errors on every plant"
    assert {paired[b][2] for b in ("apd-dc-mode-matched", "apd-dc-ms-matched")} == {"40 of 40"}
    lo, hi = sorted(float(paired[b][3]) for b in ("apd-dc-mode-matched", "apd-dc-ms-matched"))
    assert f"on synchronization on every plant (median reduction {round(lo)}-{round(hi)} %)" in readme
    assert paired["pid-dc-full"][0] == "0 of 40"  # pid-dc-full's tracking smaller on every plant
    assert f"(median difference {abs(float(paired['pid-dc-full'][3])):.1f} %)" in readme
