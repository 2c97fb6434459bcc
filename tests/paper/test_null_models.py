"""Null models for the paper's 36 reductions, recomputed from the printed Tables 1-6."""

import math

from orchestrator.paper import null_models as nm


def test_the_36_printed_reductions_are_read_cell_by_cell():
    cells = nm.paper_cells()
    assert len(cells) == 36
    # hand-copied from the paper: Table 1 STD q1, Table 5 STD q1 (70.01 as printed), Table 6 MAE B
    assert cells[0] == nm.Cell("Table 1", "q1", "STD", 59.64)
    assert cells[4 * 6] == nm.Cell("Table 5", "q1", "STD", 70.01)
    assert cells[-1] == nm.Cell("Table 6", "B", "MAE", 61.69)
    # the X column repeats the q2 column of the same experiment
    by = {(c.table, c.quantity, c.stat): c.paper for c in cells}
    for axis, motor in (("Table 3", "Table 1"), ("Table 6", "Table 4")):
        for stat in ("STD", "MAE"):
            assert by[(axis, "X", stat)] == by[(motor, "q2", stat)]


def test_the_constant_mean_gets_25_of_36_within_15_points():
    cells = nm.paper_cells()
    mean = sum(c.paper for c in cells) / 36
    assert round(mean, 2) == 74.07
    s = nm.score([mean] * 36, cells)
    assert s.cells == 36 and s.hits == (25, 30)
    # on the experiment tables alone: 15 of 18, mean deviation 7.9 points
    e = nm.score([mean] * 36, cells, lambda c: c.table in nm.EXPERIMENT_TABLES)
    assert e.cells == 18 and e.hits[0] == 15 and round(e.mad, 1) == 7.9


def test_the_best_constant_gets_27_within_15_and_32_within_20_points():
    cells = nm.paper_cells()
    b15, b20 = nm.best_constant(cells, 15.0), nm.best_constant(cells, 20.0)
    assert nm.score([b15] * 36, cells).hits[0] == 27
    assert nm.score([b20] * 36, cells).hits[1] == 32
    # no constant on a finer search does better
    for c in [x / 10 for x in range(500, 1000)]:
        assert nm.score([c] * 36, cells).hits[0] <= 27
        assert nm.score([c] * 36, cells).hits[1] <= 32


def test_the_gain_ratio_of_eq_40_is_69_and_84_5_percent_by_hand():
    r = nm.gain_ratio_reductions()
    # common: 1 - k_p / (Lambda_v D) per motor (Eq. 40: k_p = Lambda_p by Eq. 41)
    common = [1 - 8000 / (150 * 200), 1 - 8000 / (158.5 * 200), 1 - 8850 / (108.5 * 200)]
    diff = [1 - 8000 / (150 * 200 + 3 * (150 * 0.0005 + 8000)), 1 - 8000 / (158.5 * 200 + 3 * (158.5 * 8.1 + 8000)),
            1 - 8850 / (108.5 * 200 + 3 * (108.5 * 1.5 + 8850))]
    assert math.isclose(r["common"], 100 * sum(common) / 3, rel_tol=1e-12)
    assert math.isclose(r["differential"], 100 * sum(diff) / 3, rel_tol=1e-12)
    assert round(r["common"]) == 69 and round(r["differential"], 1) == 84.5
    cells = nm.paper_cells()
    pred = [r[nm.mode_of(c)] for c in cells]
    assert nm.score(pred, cells).hits == (30, 32)


def test_sixteen_cells_are_independent():
    cells = nm.paper_cells()
    kept = [c for c in cells if nm.independent(c)]
    assert len(kept) == 16
    assert all(c.stat == "MAE" and c.quantity != "X" for c in kept)


def test_the_table_scores_a_simulated_prediction_beside_the_null_models():
    cells = nm.paper_cells()
    perfect = [c.paper for c in cells]
    text = nm.null_model_table({"a perfect predictor": perfect})
    row = next(line for line in text.splitlines() if line.startswith("| a perfect predictor"))
    assert row == ("| a perfect predictor | 36/36 / 36/36, 0.0 pp | 18/18 / 18/18, 0.0 pp "
                   "| 16/16 / 16/16, 0.0 pp |")
    assert "| constant: mean of the printed reductions (74.07 %) | 25/36 / 30/36, 10.8 pp" in text


def test_tapmp_null_models_prints_the_table(capsys):
    from orchestrator.cli import main
    assert main(["null-models"]) == 0
    assert capsys.readouterr().out == nm.null_model_table() + "\n"
