"""A study worker keeps the SSP's FMUs loaded and resets them between cases (run_case with
engine.loaded.process_fmus): every case's files are those of a run on new instances."""

import json
from pathlib import Path

import pytest

from orchestrator.engine.loaded import close_process_fmus, process_fmus
from orchestrator.tool.results import run_scenario
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


def _worker_folders() -> list:
    """The extracted-FMU folders of this process's loaded FMUs (run on a worker)."""
    from orchestrator.engine.loaded import process_fmus
    return [str(s.tmp) for idle in process_fmus()._idle.values() for s in idle]


@pytest.mark.slow  # a Dask LocalCluster
def test_a_workers_loaded_fmus_are_freed_when_the_study_ends_and_when_the_worker_exits(native_built, tmp_path):
    import tempfile

    from orchestrator.studies.remote import shipping
    from orchestrator.studies.study import close_client, open_client
    study = load_study(ROOT / "benchmarks" / "bench_study.toml")
    base, ssp = scenario_data(study.base_scenario()), native_built["fmi2"]["ssp"]
    client = open_client(workers=1)
    try:
        address = client.scheduler.address
        with shipping(client, ssp, address, data=True, timeout=60) as ship:  # the study's plugin, with the SSP
            for d in (450.0, 900.0):
                row = client.submit(run_case, base, {"stop_time": 0.01, "gain_overrides.D": d}, None, None,
                                    plugin=ship.plugin, pure=False).result()
                assert row["status"] == "completed", row
            (during,) = client.run(_worker_folders).values()
            assert len(during) == 1 and Path(during[0]).is_dir()
        # the plugin's teardown at the study's end freed them while the worker lives on
        assert not Path(during[0]).exists() and list(client.run(_worker_folders).values()) == [[]]
        row = client.submit(run_case, base, {"stop_time": 0.01}, str(ssp), str(tmp_path / "local"),
                            pure=False).result()
        assert row["status"] == "completed", row
        (after,) = client.run(_worker_folders).values()
        assert len(after) == 1 and Path(after[0]).is_dir()
    finally:
        close_client(client)
    # the worker process removed its folder when it exited
    assert not Path(after[0]).exists()
    assert not list(Path(tempfile.gettempdir()).glob("tapmp_cosim_*"))
