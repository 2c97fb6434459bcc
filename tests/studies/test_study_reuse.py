"""A study worker keeps the SSP's FMUs loaded and resets them between cases (run_case with
engine.loaded.process_fmus): every case's files are those of a run on new instances."""

import json
from pathlib import Path

import pytest

from orchestrator.engine.loaded import close_process_fmus, process_fmus
from orchestrator.experiments.results import run_scenario
from orchestrator.studies.study import case_scenario, load_study, run_case, scenario_data

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def worker_fmus():
    """This process's loaded FMUs as a study worker has them, closed after the test."""
    close_process_fmus()
    yield process_fmus()
    close_process_fmus()


def test_cases_on_a_worker_that_keeps_its_fmus_loaded_write_the_files_of_runs_on_new_instances(
        native_built, worker_fmus, tmp_path):
    study = load_study(ROOT / "benchmarks" / "bench_study.toml")
    base, ssp = scenario_data(study.base_scenario()), native_built["fmi2"]["ssp"]
    cases = [{"stop_time": 0.05, "gain_overrides.D": 450.0, "gain_overrides.Lambda_v": 1.44},
             {"stop_time": 0.05, 'gains': "paper_simulation", "plant.force_limit": 0.0},  # diverges
             {"stop_time": 0.05, "gain_overrides.D": 3600.0, "gain_overrides.Lambda_v": 0.18}]
    rows = [run_case(base, changes, str(ssp), str(tmp_path / f"case{i}"), keep_results=True)
            for i, changes in enumerate(cases)]
    assert [r["status"] for r in rows[::2]] == ["completed", "completed"]
    # the case between them stopped mid-run: at the envelope or at the plant's domain check
    assert rows[1]["status"] in ("diverged", "failed") and "at t = " in rows[1]["error"], rows[1]["error"]
    assert worker_fmus.counts["loaded"] == 1 and worker_fmus.counts["reused"] == 2
    for i in (0, 2):
        fresh = tmp_path / f"fresh{i}"
        metrics = run_scenario(case_scenario(base, cases[i], {}), ssp, fresh)
        assert (tmp_path / f"case{i}" / "results.csv").read_bytes() == (fresh / "results.csv").read_bytes()
        assert rows[i]["metrics"] == metrics
        assert json.loads((tmp_path / f"case{i}" / "run.json").read_text())["guids"] == \
            json.loads((fresh / "run.json").read_text())["guids"]
