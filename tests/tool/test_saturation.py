"""Saturation made visible: metrics.json's saturation_fraction per motor, the
share of samples whose force command |F_i| is at the force limit, against a hand-counted table
and a real run; the limit is the plant's, else the controller's, else none."""

import json

import numpy as np
import pytest

from orchestrator.tool.metrics import ErrorStatistics, compute, saturation_limit

COLUMNS = (["time"] + [f"trajectory.q{i}_d" for i in (1, 2, 3)] + [f"plant.q{i}_true" for i in (1, 2, 3)]
           + ["trajectory.X_d", "trajectory.Z_d", "trajectory.B_d", "plant.X", "plant.Z", "plant.B"]
           + [f"controller.F{i}" for i in (1, 2, 3)])

# F1, F2, F3 of 8 samples against a 600 N limit; at the limit: |F| = 600 (to 1e-9 relative) or beyond
FORCES = [
    [600.0, 10.0, -600.0],
    [-600.0, 599.0, -599.9999999],    # F3: 1.7e-10 relative below 600: clipped to rounding, counts
    [0.0, 600.0, 12.0],
    [650.0, -599.9, 0.0],             # F1 beyond the limit (a command the plant clips) counts
    [1.0, 2.0, 3.0],
    [599.99, 0.0, -600.0],            # F1 1.7e-5 relative below: does not count
    [600.0, 0.0, 0.0],
    [-1e3, -1e3, 599.0],
]


def table(forces):
    rows = np.zeros((len(forces), len(COLUMNS)))
    rows[:, 0] = np.arange(len(forces)) * 1e-4
    rows[:, -3:] = forces
    return rows


def test_saturation_fraction_is_the_hand_counted_share_of_samples_at_the_limit():
    # by hand: F1 at the limit in rows 1, 2, 4, 7, 8 (5 of 8); F2 in rows 3, 8 (2 of 8);
    # F3 in rows 1, 2, 6 (3 of 8)
    m = compute(COLUMNS, table(FORCES), force_limit=600.0)
    assert m["saturation_fraction"] == [5 / 8, 2 / 8, 3 / 8]
    assert m["force_limit_n"] == 600.0


def test_saturation_accumulates_block_by_block_like_the_whole_table():
    stats = ErrorStatistics(COLUMNS, 600.0)
    for block in (FORCES[:3], FORCES[3:4], FORCES[4:]):
        stats.add(table(block))
    assert stats.result()["saturation_fraction"] == [5 / 8, 2 / 8, 3 / 8]


def test_no_limit_counts_nothing():
    assert compute(COLUMNS, table(FORCES), force_limit=0.0)["saturation_fraction"] == [0.0, 0.0, 0.0]


@pytest.mark.parametrize("parameters, limit", [
    ({}, 600.0),                                                      # the plant FMU's default
    ({"plant": {"force_limit": 450.0}, "controller": {"force_limit": 300.0}}, 450.0),
    ({"plant": {"force_limit": 0.0}, "controller": {"force_limit": 300.0}}, 300.0),
    ({"plant": {"force_limit": 0.0}}, 0.0),
])
def test_the_limit_is_the_plants_else_the_controllers(parameters, limit):
    assert saturation_limit(parameters) == limit


def test_a_run_with_the_eq40_gains_chatters_at_the_limit_and_the_default_gains_do_not(built, tmp_path):
    """Through the real FMUs: the Eq. 40 gains (unstable at 0.1 ms) hold the 600 N limit most of
    the time; the default gains never reach it. The fraction equals a count over results.csv."""
    from tests.support.runs import paper_scenario
    from orchestrator.tool.results import run_scenario

    for name, gains in (("eq40", "paper_simulation"), ("default", "default")):
        sc = paper_scenario(0.05, f'gains="{gains}"')
        m = run_scenario(sc, built["ssp"], tmp_path / name)
        assert json.loads((tmp_path / name / "metrics.json").read_text())["saturation_fraction"] == m["saturation_fraction"]
        data = np.genfromtxt(tmp_path / name / "results.csv", delimiter=",", names=True)
        counted = [float(np.mean(np.abs(data[f"controllerF{i}"]) >= 600.0 * (1 - 1e-9))) for i in (1, 2, 3)]
        assert m["saturation_fraction"] == pytest.approx(counted, abs=1e-12)
        if name == "eq40":
            assert min(m["saturation_fraction"]) > 0.5
        else:
            assert m["saturation_fraction"] == [0.0, 0.0, 0.0]
