"""The robustness section of comparison.md is the same whether its analysis was computed in a
forked process while the runs went on (report.AnalysisAside, what `tapmp compare --jobs N` does)
or in the command's own process, and closing the aside ends its process."""

from pathlib import Path

import numpy as np
import pytest

from orchestrator.tool import report
from orchestrator.tool.baselines import compare_runs
from orchestrator.tool.scenario import load

pytestmark = pytest.mark.slow  # a forked process

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def runs():
    every = compare_runs(load(ROOT / "scenarios" / "paper_simulation.toml"))
    return {name: every[name] for name in ("sc-dc", "apd-dc")}


def _same(a, b) -> bool:
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, np.ndarray):
        return np.array_equal(a, b)
    return a == b or (a != a and b != b)  # NaN equals NaN here


@pytest.mark.parametrize("processes", [1, 2])
def test_the_analysis_computed_aside_is_the_one_computed_here(runs, processes):
    report._ANALYZED.clear()
    aside = report.AnalysisAside(runs, processes)
    try:
        aside.keep()
    finally:
        aside.close()
    key = report._analysis_key(runs)
    assert key in report._ANALYZED  # kept: robustness_section computes nothing again
    aside_result, aside_lines = report._ANALYZED[key], report.robustness_section(runs)
    report._ANALYZED.clear()
    here_lines = report.robustness_section(runs)
    assert _same(aside_result, report._ANALYZED[key])
    assert aside_lines == here_lines
    assert any(line.startswith("| sc-dc |") for line in here_lines)


def test_closing_the_aside_ends_its_process_at_once(runs):
    report._ANALYZED.clear()
    aside = report.AnalysisAside(runs, 2)
    procs = list(aside.pool._processes.values())
    assert len(procs) == 2 and all(p.is_alive() for p in procs)
    aside.close()  # before the analysis could end
    assert all(not p.is_alive() and p.exitcode is not None for p in procs)
    assert report._analysis_key(runs) not in report._ANALYZED
