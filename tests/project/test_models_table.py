"""docs/architecture.md lists the models as their records say (tapmp.models.models_table)."""

from pathlib import Path

from tapmp.models import MODELS, models_table

ARCHITECTURE = Path(__file__).resolve().parents[2] / "docs" / "architecture.md"


def test_the_architecture_page_lists_every_model_as_its_record_says():
    table = models_table()
    assert len(table.splitlines()) == 2 + len(MODELS)  # header, rule, one row per record
    assert table in ARCHITECTURE.read_text(), ("docs/architecture.md's table of the models differs from the "
                                              "records: paste tapmp.models.models_table() into it")
