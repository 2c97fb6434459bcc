"""The paper's Tables 1-6 are read from one data file (orchestrator/paper/paper_tables.toml)
and every reduction of ours is computed by one formula."""

import math

from orchestrator.paper import paper_tables as pt
from orchestrator.tool import metrics


def test_each_printed_reduction_row_is_its_apd_and_scdc_rows_to_the_papers_rounding():
    # a cell mistyped in the data file breaks this: the paper's reductions are computed from
    # unrounded errors, so they agree with the printed errors to a few hundredths only
    assert list(pt.TABLES) == [f"Table {n}" for n in range(1, 7)]
    for name in pt.TABLES:
        apd, scdc, red = (pt.values(name, row) for row in pt.ROWS)
        assert len(apd) == len(scdc) == len(red) == 6
        for a, s, r in zip(apd, scdc, red):
            assert abs(metrics.reduction(a, s) - r) < 0.05, (name, a, s, r)


def test_the_tables_are_grouped_by_target_and_read_as_metrics():
    assert pt.TARGETS == ("simulation", "experiment")
    assert pt.tables_of("experiment") == ("Table 4", "Table 5", "Table 6")
    assert pt.SCENARIO_TABLES["paper_simulation"] == ("Table 1", "Table 2", "Table 3")
    # as printed: the paper's own digits, "5.00" and "82.7"
    assert pt.printed("Table 4", 0)[4] == "5.00" and pt.printed("Table 2", "reduction")[2] == "82.7"
    apd = pt.by_metric("simulation", "apd_dc")
    assert apd["sync_mae_um"] == (6.98, 7.26, 4.92) and apd["axis_std"] == (14.21, 4.75, 75.95)
    assert set(apd) == {k for pair in metrics.METRIC_KEYS.values() for k in pair}


def test_one_reduction_formula_for_every_metric():
    assert metrics.reduction(4.0, 1.0) == 75.0 and metrics.reduction(2.0, 3.0) == -50.0
    assert math.isnan(metrics.reduction(0.0, 1.0))
    base = {k: [2.0, 4.0, 8.0] for pair in metrics.METRIC_KEYS.values() for k in pair}
    new = {k: [1.0, 1.0, 1.0] for k in base}
    assert metrics.reductions(base, new) == {k: [50.0, 75.0, 87.5] for k in base}
