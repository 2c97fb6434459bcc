"""Result formats: results.csv (text) and results.mat (MATLAB 5 MAT-file) hold the same doubles,
bit for bit; both are read back by read_results, the metrics and the plots; a MAT run that is
stopped leaves a consistent results.mat, a killed one a loadable results.part.npy."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from scipy.io import loadmat

from orchestrator.cli import main
from orchestrator.engine.master import CoSimulation, RunOptions
from orchestrator.tool.roles import ROLES
from orchestrator.tool import metrics
from orchestrator.tool.reading import read_results
from orchestrator.tool.results import run_scenario
from orchestrator.tool.writers import mat_names
from orchestrator.tool.scenario import ScenarioError, load

ROOT = Path(__file__).resolve().parents[3]
PAPER = ROOT / "scenarios" / "paper_simulation.toml"


def alone(ssp, scenario, steps):
    """Rows of the co-simulation stepped by hand, no writer: the reference values."""
    with CoSimulation(ssp, scenario.parameters(), RunOptions(start_time=0.0, step_size=scenario.step,
                                                             ordering=scenario.ordering, roles=ROLES)) as sim:
        return sim.columns, np.array([sim.row()] + [sim.step() or sim.row() for _ in range(steps)])


@pytest.mark.slow
def test_csv_and_mat_hold_the_co_simulations_doubles_bit_for_bit(built, tmp_path):
    sc = load(PAPER, ["stop_time=0.25"])  # 2,501 rows: three blocks of 1,000 steps, the last one partial
    columns, rows = alone(built["ssp"], sc, 2500)
    m = {fmt: run_scenario(sc.with_changes(format=fmt), built["ssp"], tmp_path / fmt) for fmt in ("csv", "mat")}
    for fmt in ("csv", "mat"):
        cols, data = read_results(tmp_path / fmt)
        assert cols == columns and data.shape == (2501, 40)
        assert np.array_equal(data, rows), fmt  # exact: repr round-trips, MAT stores the doubles
        assert json.loads((tmp_path / fmt / "run.json").read_text())["results_file"] == f"results.{fmt}"
    assert m["csv"] == m["mat"]  # the same rows, the same blocks
    whole = metrics.compute(columns, rows)  # in one block: equal to round-off
    assert m["csv"]["tracking_mae_um"] == pytest.approx(whole["tracking_mae_um"], rel=1e-12)
    assert sorted(p.name for p in (tmp_path / "mat").iterdir()) == [".tapmp.lock", "metrics.json", "results.mat",
                                                                      "run.json"]


@pytest.mark.slow
def test_the_default_result_file_reads_back_to_the_co_simulations_doubles(built, tmp_path, capsys):
    """`tapmp run` with no --format: results.csv, written by its own thread while the run steps
    (three blocks and a partial one), holds every double bit for bit, read by tapmp's reader and by
    Python's csv module with float() alike, header first, rows in time order."""
    import csv
    sc = load(PAPER, ["stop_time=0.35"])
    columns, rows = alone(built["ssp"], sc, 3500)
    out = tmp_path / "run"
    assert main(["run", str(PAPER), "--ssp", str(built["ssp"]), "--set", "stop_time=0.35", "--out", str(out),
                 "--no-progress"]) == 0
    assert json.loads((out / "run.json").read_text())["results_file"] == "results.csv"
    cols, data = read_results(out)
    assert cols == columns and np.array_equal(data.view(np.int64), rows.view(np.int64))
    with open(out / "results.csv", newline="") as f:
        header, *text = list(csv.reader(f))
    assert header == columns
    assert np.array_equal(np.array([[float(x) for x in r] for r in text]).view(np.int64), rows.view(np.int64))


def test_a_write_that_fails_in_the_writing_thread_is_raised_in_the_run_once(tmp_path):
    """results.csv on a device that is always full (/dev/full): the block handed to the writing
    thread fails there; the run gets its ResultsWriteError (one line naming the file, errno and the
    rows kept) from finish(), once; blocks after it are dropped, not written."""
    from orchestrator.tool.folders import ResultsWriteError
    from orchestrator.tool.writers import CsvBlocks
    writer = CsvBlocks(tmp_path, ["time", "x"])
    full = os.open("/dev/full", os.O_WRONLY)  # the file's descriptor now writes there (a link there is refused)
    os.dup2(full, writer.fd)
    os.close(full)
    try:
        writer.write(np.array([[0.0, 1.5], [1e-4, 2.5]]))
        with pytest.raises(ResultsWriteError) as err:
            writer.finish()
        assert str(err.value) == (f"cannot write {tmp_path / 'results.csv'}: No space left on device (errno 28): "
                                  "it keeps no rows, whole rows only")
        writer.write(np.array([[2e-4, 3.5]]))  # dropped: the failure was reported
        writer.finish()
        assert writer.rows == 0
    finally:
        writer.close()


def test_the_mat_file_has_one_variable_per_column_as_matlab_reads_it(built, tmp_path):
    sc = load(PAPER, ["stop_time=0.01", 'format="mat"'])
    run_scenario(sc, built["ssp"], tmp_path / "r")
    content = loadmat(tmp_path / "r" / "results.mat")
    columns = [c.rstrip() for c in content["columns"]]
    assert columns[:2] == ["time", "trajectory.X_d"] and "plant.q1_true" in columns
    assert content["time"].shape == (101, 1) and content["time"][-1, 0] == pytest.approx(0.01)
    assert content["plant_q1_true"].dtype == np.float64 and "controller_F1" in content
    assert mat_names(["time", "a.b", "a_b", "1x", "é.q"]) == ["time", "a_b", "a_b_2", "v_1x", "v___q"]


def test_record_every_thins_a_mat_file_like_a_csv_file(built, tmp_path):
    sc = load(PAPER, ["stop_time=0.02", "record_every=7"])
    run_scenario(sc, built["ssp"], tmp_path / "csv")
    run_scenario(sc.with_changes(format="mat"), built["ssp"], tmp_path / "mat")
    (cc, c), (mc, m) = read_results(tmp_path / "csv"), read_results(tmp_path / "mat")
    assert cc == mc and np.array_equal(c, m) and c.shape[0] == 1 + 200 // 7 + 1  # every 7th step and the last


@pytest.mark.slow
def test_format_flag_and_scenario_key(built, tmp_path, capsys):
    out = tmp_path / "r"
    assert main(["run", str(PAPER), "--ssp", str(built["ssp"]), "--out", str(out), "--format", "mat",
                 "--set", "stop_time=0.01", "--no-progress"]) == 0
    assert (out / "results.mat").is_file() and not (out / "results.csv").exists()
    assert main(["plot", str(out)]) == 0 and (out / "run_fig8_force_commands.png").stat().st_size > 10000
    with pytest.raises(ScenarioError, match=r"format = 'parquet' is invalid: allowed are csv, mat"):
        load(PAPER, ['format="parquet"'])


@pytest.mark.slow
def test_a_stopped_mat_run_leaves_a_consistent_mat_file(built, tmp_path):
    out = tmp_path / "r"
    proc = subprocess.Popen([sys.executable, "-m", "orchestrator", "run", str(PAPER), "--ssp", str(built["ssp"]),
                             "--out", str(out), "--format", "mat", "--set", "stop_time=30", "--no-progress"],
                            stderr=subprocess.PIPE, text=True)
    part = out / "results.part.npy"
    while proc.poll() is None and (not part.exists() or part.stat().st_size < 1_000_000):
        time.sleep(0.02)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert not part.exists()
    columns, data = read_results(out)
    assert data.shape[0] >= 3000 and data.shape[1] == len(columns) == 40
    assert np.allclose(np.diff(data[:, 0]), 1e-4)  # whole rows, none lost
    run = json.loads((out / "run.json").read_text())
    assert run["status"] == "interrupted" and run["failed_at_s"] >= data[-1, 0]


@pytest.mark.slow
def test_a_killed_mat_run_leaves_a_loadable_part_file(built, tmp_path):
    out = tmp_path / "r"
    proc = subprocess.Popen([sys.executable, "-m", "orchestrator", "run", str(PAPER), "--ssp", str(built["ssp"]),
                             "--out", str(out), "--format", "mat", "--set", "stop_time=30", "--no-progress"])
    part = out / "results.part.npy"
    while proc.poll() is None and (not part.exists() or part.stat().st_size < 1_000_000):
        time.sleep(0.02)
    proc.kill()
    proc.wait(timeout=60)
    whole = np.load(part)  # a valid .npy of the whole blocks written so far
    assert whole.shape[1] == 40 and whole.shape[0] % 1000 == 0 and whole.shape[0] >= 3000
    columns, data = read_results(out)  # column names from run.json
    assert columns[0] == "time" and np.array_equal(data, whole)
    assert np.allclose(data[:, 0], np.arange(data.shape[0]) * 1e-4)
    assert main(["run", str(PAPER), "--ssp", str(built["ssp"]), "--out", str(out), "--format", "mat",
                 "--set", "stop_time=0.01", "--no-progress"]) == 0  # a killed run is no completed one
    assert not part.exists() and read_results(out)[1].shape == (101, 40)
