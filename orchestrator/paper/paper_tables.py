"""The paper's Tables 1-6 (paper_tables.toml beside this module).

Every module that shows, scores or fits against the paper's numbers reads them here: the
reproduction page and the rows beside ours in comparison.md (``reference_rows``), the null
models, the calibration and the predictors. Our reductions of SC-DC against APD-DC are all
computed by orchestrator.tool.metrics.reduction.
"""

from importlib import resources
from typing import NamedTuple

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

from ..tool.metrics import METRIC_KEYS

ROWS = ("apd_dc", "sc_dc", "reduction")  # the printed rows: APD-DC, proposed (SC-DC), "Reduction (%)"


class Table(NamedTuple):
    """One of the paper's tables: its target ("simulation" or "experiment"), quantity (a key of
    METRIC_KEYS), the three column names and units, and each row of ROWS as printed (STD of the
    columns then MAE, strings with the paper's digits; um, urad for B, % for the reduction)."""

    name: str
    target: str
    quantity: str
    columns: tuple
    units: tuple
    rows: dict


def _load() -> dict:
    data = tomllib.loads(resources.files(__package__).joinpath("paper_tables.toml").read_text(encoding="utf-8"))
    return {name: Table(name, t["target"], t["quantity"], tuple(t["columns"]), tuple(t["units"]),
                        {row: tuple(t[row]) for row in ROWS})
            for name, t in data.items()}


TABLES = _load()  # {"Table 1": Table, ..., "Table 6": Table}, in the paper's order
TARGETS = tuple(dict.fromkeys(t.target for t in TABLES.values()))  # ("simulation", "experiment")


def tables_of(target: str) -> tuple[str, ...]:
    """The names of the three tables of ``target`` (tracking, sync, axis), e.g. Tables 1-3."""
    return tuple(name for name, t in TABLES.items() if t.target == target)


# The paper's tables of each paper scenario (scenarios/paper_<target>.toml reproduces a target).
SCENARIO_TABLES = {f"paper_{target}": tables_of(target) for target in TARGETS}


def printed(table: str, row: int | str) -> list[str]:
    """The six cells of ``row`` (0 or "apd_dc", 1 or "sc_dc", 2 or "reduction") of the paper's
    ``table``, as printed: STD of the three columns, then MAE (um, urad for B, or %)."""
    return list(TABLES[table].rows[ROWS[row] if isinstance(row, int) else row])


def values(table: str, row: int | str) -> list[float]:
    """The cells of ``printed(table, row)`` as numbers."""
    return [float(x) for x in printed(table, row)]


def by_metric(target: str, row: str) -> dict[str, tuple]:
    """{metrics.json key: (value per column)} of one printed row (a name of ROWS) over the three
    tables of ``target``, e.g. by_metric("simulation", "apd_dc")["sync_mae_um"] = Table 2's
    APD-DC MAE of q1..q3 [um]."""
    out = {}
    for name in tables_of(target):
        cells = values(name, row)
        std, mae = METRIC_KEYS[TABLES[name].quantity]
        out[std], out[mae] = tuple(cells[:3]), tuple(cells[3:])
    return out


def reference_rows(scenario_name: str) -> dict | None:
    """The paper's rows as printed for comparison.md of a paper scenario (None for any other
    scenario): {quantity: ("paper: Table N", [(label, six cells)])}, see
    orchestrator.tool.report.comparison_tables."""
    tables = SCENARIO_TABLES.get(scenario_name)
    if not tables:
        return None
    labels = ("paper: APD-DC", "paper: SC-DC (proposed)", "paper: reduction (%), as printed")
    return {TABLES[t].quantity: (f"paper: {t}", [(label, printed(t, r)) for r, label in enumerate(labels)])
            for t in tables}
