"""The study tests' Dask cluster (a module fixture) and a study file of the paper's simulation
scenario written for a test."""

from pathlib import Path

import pytest

from .runs import PAPER


@pytest.fixture(scope="module")
def client():
    """A real LocalCluster: two single-threaded worker processes."""
    from orchestrator.studies.study import close_client, open_client
    c = open_client(workers=2)
    yield c
    close_client(c)


def write_study(folder: Path, text: str, name="s") -> Path:
    """``folder``/<name>.toml: the study ``name`` on the paper's simulation scenario, writing into
    ``folder``/out, followed by ``text`` (its other tables)."""
    path = folder / f"{name}.toml"
    path.write_text(f'[study]\nname = "{name}"\nbase = "{PAPER}"\noutput = "{folder / "out"}"\n' + text)
    return path
