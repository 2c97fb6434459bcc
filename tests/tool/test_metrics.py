"""Streaming metrics (orchestrator/tool/metrics.py) equal numpy over the whole table."""

import numpy as np
import pytest

from orchestrator.tool.metrics import ErrorStatistics, compute

COLUMNS = ["time"] + [f"trajectory.q{i}_d" for i in (1, 2, 3)] + [f"plant.q{i}_true" for i in (1, 2, 3)] \
    + ["trajectory.X_d", "trajectory.Z_d", "trajectory.B_d", "plant.X", "plant.Z", "plant.B"]


def test_blockwise_statistics_equal_whole_table_statistics():
    rng = np.random.default_rng(7)
    data = rng.normal(1e-3, 2e-7, size=(5003, len(COLUMNS)))  # a large mean: the hard case for the STD
    stats = ErrorStatistics(COLUMNS)
    start = 0
    for size in (1, 999, 1000, 3, 2000, 1000):
        stats.add(data[start:start + size])
        start += size
    got = stats.result()
    e = data[:, 1:4] - data[:, 4:7]
    es = np.stack([e[:, 0] - e[:, 1], e[:, 1] - e[:, 2], e[:, 2] - e[:, 0]], axis=1)
    axis = data[:, 7:10] - data[:, 10:13]
    for name, x in (("tracking", e), ("sync", es), ("axis", axis)):
        key = "axis" if name == "axis" else f"{name}_"
        mae, std = (f"{key}_mae", f"{key}_std") if name == "axis" else (f"{key}mae_um", f"{key}std_um")
        assert got[mae] == pytest.approx(np.abs(x).mean(0) * 1e6, rel=1e-12)
        assert got[std] == pytest.approx(x.std(0) * 1e6, rel=1e-9)
    assert got["samples"] == 5003
    whole = compute(COLUMNS, data)  # one block
    assert whole["tracking_std_um"] == pytest.approx(got["tracking_std_um"], rel=1e-9)


def test_a_system_without_the_tapmp_plant_gets_metrics_that_name_the_missing_columns():
    from orchestrator.tool.metrics import ErrorStatistics
    columns = ["time", "trajectory.q1_d", "trajectory.q2_d", "trajectory.q3_d", "myplant.x"]
    stats = ErrorStatistics(columns)
    stats.add(np.zeros((7, len(columns))))
    stats.add(np.zeros((3, len(columns))))
    result = stats.result()
    assert result["samples"] == 10
    assert "plant.q1_true" in result["not_computed"] and "trajectory.B_d" in result["not_computed"]
    assert "trajectory.q1_d" not in result["not_computed"]
    assert "tracking_mae_um" not in result


def test_limit_cycle_finds_the_amplitude_and_period_of_a_cycle_on_a_drift_and_ignores_chatter():
    """A 2 ms cycle of amplitude 3 on a linear drift, with a 0.5 chatter every sample: the drift is taken
    out, the chatter (under half the cycle) counts no cycle; a pure drift has no cycle."""
    from orchestrator.tool.metrics import limit_cycle
    t = np.arange(0.0, 0.1, 1e-5)
    cycle = 3.0 * np.sin(2.0 * np.pi * t / 2e-3)
    chatter = 0.5 * (-1.0) ** np.arange(len(t))
    m = limit_cycle(t, np.column_stack([cycle + 40.0 * t + chatter, 7.0 + 40.0 * t]))
    assert m["amplitude"][0] == pytest.approx(3.5, abs=0.1)  # the fitted line takes a little of the sine
    assert m["period_s"][0] == pytest.approx(2e-3, rel=1e-3)
    assert m["cycles"][0] == 49  # 50 periods: the first rise from below comes in the second
    assert m["mean"][0] == pytest.approx(2.0, abs=0.01)
    assert m["amplitude"][1] == pytest.approx(0.0, abs=1e-9) and m["period_s"][1] is None and m["cycles"][1] == 0
