"""Null models for the paper's reductions: how much a prediction of Tables 1-6 is worth.

The paper prints 36 reductions of SC-DC against APD-DC (Tables 1-6, STD and MAE of three
quantities each), in percent. A predictor gives a number for each cell; it is scored by how
many cells it gets within a tolerance (15 and 20 percentage points) and by its mean absolute
deviation. To say what a simulation's prediction is worth, it is scored beside predictors
that need no simulation:

* the constant mean of the 36 printed reductions (uses the answers: an upper bound for a
  constant guess), and the best constant for the tolerance (also uses the answers);
* the gain ratio of Eq. 40-41: per mode, the reduction a stiffer proportional gain alone
  would give, 1 - k_p / k_p(SC-DC) with SC-DC's per-mode stiffness (tapmp.params
  .scdc_mode_gains): the common-mode stiffness Lambda_v D for the tracking errors and the
  X, Z axes, the differential-mode stiffness Lambda_v D + 3 (Lambda_v b + Lambda_p) for the
  synchronization errors and the B axis, each averaged over the three motors.

The 36 cells are not 36 independent numbers: the X axis is q2 (Eq. 1-2: at the paper's
poses X moves with the middle motor; Tables 3 and 6 repeat Tables 1 and 4's q2 column) and
the STD and MAE reductions of one quantity differ by a few points. ``independent`` keeps one
cell per quantity (the MAE, X left out): 16 cells.
"""

from typing import NamedTuple

import numpy as np

from tapmp.params import GAIN_PRESETS, scdc_mode_gains

from . import paper_tables
from .paper_tables import TABLES, tables_of

TOLERANCES = (15.0, 20.0)  # percentage points
EXPERIMENT_TABLES = tables_of("experiment")  # Tables 4-6


class Cell(NamedTuple):
    """One printed reduction: table name, quantity (q1..q3 or X, Z, B), statistic, value [%]."""

    table: str
    quantity: str
    stat: str
    paper: float


def paper_cells() -> list[Cell]:
    """The 36 reductions of Tables 1-6 as printed, in table order, STD then MAE, [%]."""
    cells = []
    for table, t in TABLES.items():
        for j, value in enumerate(paper_tables.values(table, "reduction")):
            cells.append(Cell(table, t.columns[j % 3], ("STD", "MAE")[j // 3], value))
    return cells


def independent(cell: Cell) -> bool:
    """True for the 16 cells counted as independent: MAE reductions, the X axis left out (= q2)."""
    return cell.stat == "MAE" and cell.quantity != "X"


def mode_of(cell: Cell) -> str:
    """'common' for tracking errors and the X, Z axes, 'differential' for sync errors and B."""
    kind = TABLES[cell.table].quantity
    if kind == "sync" or (kind == "axis" and cell.quantity == "B"):
        return "differential"
    return "common"


def gain_ratio_reductions(preset: dict | None = None) -> dict[str, float]:
    """Reduction [%] a stiffer P gain alone predicts per mode for a gain preset (default Eq. 40,
    APD-DC's k_p = Lambda_p by Eq. 41): 100 (1 - k_p / k_p,mode), averaged over the motors."""
    g = preset or GAIN_PRESETS["paper_simulation"]
    out = {"common": [], "differential": []}
    for i in range(3):
        m = scdc_mode_gains(g["Lambda_p"][i], g["Lambda_v"][i], g["b"][i], g["D"][i])
        out["common"].append(1.0 - g["Lambda_p"][i] / m["kp_c"])
        out["differential"].append(1.0 - g["Lambda_p"][i] / m["kp_d"])
    return {k: 100.0 * float(np.mean(v)) for k, v in out.items()}


def best_constant(cells: list[Cell], tol: float) -> float:
    """The constant [%] that gets the most cells within ``tol`` points (ties: the smallest mean
    absolute deviation; searched on a 0.01-point grid over the printed range)."""
    paper = np.array([c.paper for c in cells])
    grid = np.arange(np.floor(paper.min()), np.ceil(paper.max()) + 0.005, 0.01)
    hits = (np.abs(paper[None, :] - grid[:, None]) <= tol).sum(axis=1)
    mad = np.abs(paper[None, :] - grid[:, None]).mean(axis=1)
    best = np.lexsort((mad, -hits))[0]
    return float(grid[best])


class Score(NamedTuple):
    """How a predictor does on a set of cells: cells, hits within each of TOLERANCES, mean |dev| [pp]."""

    cells: int
    hits: tuple[int, ...]
    mad: float


def score(predicted: list[float], cells: list[Cell], select=lambda c: True) -> Score:
    """Score ``predicted`` [%] (one per cell of ``cells``, NaN where a predictor says nothing) on
    the cells ``select`` keeps; mean |dev| is NaN when no cell is left."""
    dev = np.array([abs(p - c.paper) for p, c in zip(predicted, cells) if select(c) and not np.isnan(p)])
    mad = float(dev.mean()) if dev.size else float("nan")
    return Score(len(dev), tuple(int((dev <= t).sum()) for t in TOLERANCES), mad)


def predictors(cells: list[Cell], simulated: dict[str, list[float]] | None = None) -> dict[str, list[float]]:
    """Every predictor's 36 values [%]: the null models, then ``simulated`` ({label: values})."""
    paper = [c.paper for c in cells]
    ratio = gain_ratio_reductions()
    out = {
        f"constant: mean of the printed reductions ({np.mean(paper):.2f} %)": [float(np.mean(paper))] * len(cells),
    }
    for tol in TOLERANCES:
        b = best_constant(cells, tol)
        out[f"constant: best for {tol:g} points ({b:.2f} %)"] = [b] * len(cells)
    out[f"gain ratio of Eq. 40-41 ({ratio['common']:.1f} % common, {ratio['differential']:.1f} % differential)"] = [
        ratio[mode_of(c)] for c in cells]
    out.update(simulated or {})
    return out


_SUBSETS = (("Tables 1-6", lambda c: True), ("experiment, Tables 4-6", lambda c: c.table in EXPERIMENT_TABLES),
            ("independent cells", independent))


def null_model_table(simulated: dict[str, list[float]] | None = None) -> str:
    """Markdown table: each predictor's hits within 15 and 20 points and mean |deviation| [pp],
    on all 36 cells, on the experiment tables alone and on the 16 independent cells."""
    cells = paper_cells()
    head = "| predictor | " + " | ".join(
        f"{name}: within {TOLERANCES[0]:g} / {TOLERANCES[1]:g} pp, mean dev." for name, _ in _SUBSETS) + " |"
    lines = [head, "|---" * (1 + len(_SUBSETS)) + "|"]
    for label, values in predictors(cells, simulated).items():
        parts = []
        for _, select in _SUBSETS:
            s = score(values, cells, select)
            parts.append(f"{s.hits[0]}/{s.cells} / {s.hits[1]}/{s.cells}, {s.mad:.1f} pp" if s.cells else "not run")
        lines.append(f"| {label} | " + " | ".join(parts) + " |")
    return "\n".join(lines)
