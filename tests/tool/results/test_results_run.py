"""Result folders (orchestrator/tool/results.py): nothing lost on Ctrl-C, decimation that leaves
the dynamics alone, determinism and isolation of closed loops in one process."""

import csv
import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from orchestrator.engine.master import CoSimulation, RunOptions
from orchestrator.tool.roles import ROLES
from orchestrator.tool.results import run_scenario
from orchestrator.tool.scenario import load

ROOT = Path(__file__).resolve().parents[3]
PAPER = ROOT / "scenarios" / "paper_simulation.toml"


def read_csv(path: Path) -> list[list[str]]:
    with open(path, newline="") as f:
        return list(csv.reader(f))


@pytest.mark.slow
def test_sigint_stops_the_run_and_keeps_valid_partial_results(built, tmp_path):
    out = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "orchestrator", "run", str(PAPER), "--ssp", str(built["ssp"]),
                             "--out", str(out), "--set", "stop_time=60", "--no-progress"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    results = out / "results.csv"
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and (not results.exists() or results.stat().st_size < 2_000_000):
        time.sleep(0.05)  # about 1,700 steps (1.2 kB each) are on disk
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "interrupted by SIGINT at t = " in err and "results so far are in the output folder" in err
    rows = read_csv(results)
    assert len(rows) > 1000 and all(len(r) == len(rows[0]) for r in rows)  # whole rows only
    times = [float(r[0]) for r in rows[1:]]
    assert all(b > a for a, b in zip(times, times[1:])) and times[-1] < 60
    run = json.loads((out / "run.json").read_text())
    assert run["status"] == "interrupted" and run["exit_code"] == 130
    assert "SIGINT" in run["error"] and run["failed_at_s"] >= times[-1]
    assert not (out / "metrics.json").exists()


def test_record_every_thins_the_file_but_not_the_dynamics_or_metrics(built, tmp_path):
    base = load(PAPER, ["stop_time=0.02"])
    m_all = run_scenario(base, built["ssp"], tmp_path / "all")
    m_thin = run_scenario(base.with_changes(record_every=7), built["ssp"], tmp_path / "thin")
    rows_all, rows_thin = read_csv(tmp_path / "all" / "results.csv"), read_csv(tmp_path / "thin" / "results.csv")
    keep = [0] + [k for k in range(1, 201) if k % 7 == 0 or k == 200]
    assert rows_thin == [rows_all[0]] + [rows_all[k + 1] for k in keep]
    assert m_thin == m_all and m_all["samples"] == 201


@pytest.mark.slow
def test_the_same_scenario_twice_gives_a_bit_identical_results_csv(built, tmp_path):
    sc = load(PAPER, ["stop_time=0.03"])
    run_scenario(sc, built["ssp"], tmp_path / "a")
    run_scenario(sc, built["ssp"], tmp_path / "b")
    assert (tmp_path / "a" / "results.csv").read_bytes() == (tmp_path / "b" / "results.csv").read_bytes()


def run_alone(ssp, scenario, steps):
    with CoSimulation(ssp, scenario.parameters(), RunOptions(start_time=0.0, step_size=scenario.step,
                                                             ordering=scenario.ordering, roles=ROLES)) as sim:
        return [sim.row()] + [sim.step() or sim.row() for _ in range(steps)]


def test_two_closed_loops_side_by_side_do_not_affect_each_other(built):
    scdc = load(PAPER, ['law="sc-dc"'])
    apd = load(PAPER, ['law="apd-dc"', 'ordering="jacobi"'])
    alone = {"sc-dc": run_alone(built["ssp"], scdc, 300), "apd-dc": run_alone(built["ssp"], apd, 300)}
    together = {"sc-dc": [], "apd-dc": []}
    with CoSimulation(built["ssp"], scdc.parameters(), RunOptions(start_time=0.0, step_size=1e-4,
                                                                  ordering=scdc.ordering, roles=ROLES)) as a, \
            CoSimulation(built["ssp"], apd.parameters(), RunOptions(start_time=0.0, step_size=1e-4,
                                                                    ordering=apd.ordering, roles=ROLES)) as b:
        for k in range(301):
            if k:
                a.step()
                b.step()
            together["sc-dc"].append(a.row())
            together["apd-dc"].append(b.row())
    assert together == alone
    assert alone["sc-dc"][-1] != alone["apd-dc"][-1]  # the two loops really differ
