"""`tapmp analyze --worst-case`: the worst margins of each law over poses, the envelope's corners and
the vertices of a study's parameter box, against points sampled inside the box and a vertex built
by hand."""

import json

import numpy as np
import pytest

from orchestrator.cli import main
from orchestrator.studies.study_file import load_study
from orchestrator.tool import robustness
from orchestrator.tool.baselines import compare_runs
from orchestrator.tool.scenario import load
from tapmp.params import ModelParams

from tests.support.shared import ROOT

PAPER = ROOT / "scenarios" / "paper_simulation.toml"
FRICTION = ["plant.c_v1", "plant.c_v2", "plant.c_v3", "plant.F_c1", "plant.F_c2", "plant.F_c3"]
BOX = f"""[study]
name = "box"
base = "{PAPER}"

[grid]
baseline = ["sc-dc"]

[monte_carlo]
samples = 3
seed = 7

[monte_carlo.vary.movers]
targets = ["plant.m_1", "plant.m_2", "plant.m_3"]
distribution = "uniform"
low = 0.5
high = 1.5
relative = true

[monte_carlo.vary.friction]
targets = {json.dumps(FRICTION)}
distribution = "uniform"
low = 0.0
high = 2.0
relative = true

[monte_carlo.vary.encoder_resolution]
targets = ["plant.encoder_resolution"]
distribution = "uniform"
low = 5e-8
high = 5e-7
"""


@pytest.fixture(scope="module")
def box(tmp_path_factory):
    """(study path, the command's worst_case.json, its printed lines) for SC-DC over the box, no poses."""
    folder = tmp_path_factory.mktemp("worst")
    path = folder / "box.toml"
    path.write_text(BOX)
    out = folder / "out"
    assert main(["analyze", str(PAPER), "--worst-case", "--box", str(path), "--poses", "0", "--out", str(out)]) == 0
    return path, json.loads((out / "worst_case.json").read_text()), (out / "worst_case.md").read_text()


def _by_hand(sc, movers: float, friction: float):
    """SC-DC's scenario with the movers' masses and the friction scaled, written out key by key."""
    d = ModelParams()
    plant = dict(sc.plant, m_1=movers * d.m_1, m_2=movers * d.m_2, m_3=movers * d.m_3)
    for key in FRICTION:
        name = key.split(".")[1]
        plant[name] = friction * sc.parameters()["plant"].get(name, 0.0)
    return sc.with_changes(plant=plant)


@pytest.mark.slow
def test_the_worst_case_over_the_box_is_no_better_than_any_point_sampled_inside_it(box):
    path, result, _ = box
    worst = result["runs"]["sc-dc"]
    assert result["points"] == 1 + 8 + 4 and result["left_out"] == ["encoder_resolution"]
    sc = compare_runs(load(PAPER))["sc-dc"]
    study = load_study(path)
    rng = np.random.default_rng(study.seed)
    draws = {f.name: f.draw(rng, study.samples) for f in study.factors}
    for i in range(study.samples):
        r = robustness.point_margins(_by_hand(sc, draws["movers"][i], draws["friction"][i]))
        assert r["verdict"] == "stable"
        assert worst["Ms"]["value"] >= r["Ms"]
        assert worst["gm_upper"]["value"] <= r["gm_upper"]
        assert worst["disk_margin"]["value"] <= r["disk_margin"]
        assert worst["delay_margin_all_s"]["value"] <= r["delay_margin_all_s"]
        assert r["gm_lower"] is None or worst["gm_lower"]["value"] >= r["gm_lower"]


@pytest.mark.slow
def test_the_worst_case_equals_the_margin_of_the_vertex_where_it_occurs(box):
    _, result, table = box
    worst = result["runs"]["sc-dc"]
    sc = compare_runs(load(PAPER))["sc-dc"]
    ends = {"low": {"movers": 0.5, "friction": 0.0}, "high": {"movers": 1.5, "friction": 2.0}}
    at_vertices = [m for m in robustness.MEASURES if worst[m]["where"].startswith("box ")]
    assert at_vertices  # the box's masses move the margins beyond the nominal plant's corners
    for m in at_vertices:
        where = worst[m]["where"]  # "box movers high, friction low"
        parts = dict(p.split() for p in where[len("box "):].split(", "))
        r = robustness.point_margins(_by_hand(sc, ends[parts["movers"]]["movers"], ends[parts["friction"]]["friction"]))
        assert worst[m]["value"] == pytest.approx(float(r[m]), rel=1e-9), m
        assert f"({where})" in table


@pytest.mark.parametrize("args, message", [
    (["--poses", "-1"], "error: --poses = -1 is invalid: allowed is an integer from 0 to 1000"),
    (["--runs", "sc-dc,nope"], "error: --runs = 'sc-dc,nope' is invalid: allowed is a comma-separated list of "),
    (["--box", "nope"], "error: --box = 'nope': study 'nope' is neither a file nor a shipped study"),
])
def test_a_bad_worst_case_option_is_one_line_and_exit_2(tmp_path, capsys, args, message):
    assert main(["analyze", str(PAPER), "--worst-case", "--out", str(tmp_path / "a"), *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(message)
    assert not (tmp_path / "a").exists()


def test_a_worst_case_option_without_worst_case_is_one_line_and_exit_2(tmp_path, capsys):
    assert main(["analyze", str(PAPER), "--poses", "4", "--out", str(tmp_path / "a")]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        "error: --poses is invalid without --worst-case: allowed only with --worst-case"]
    assert not (tmp_path / "a").exists()
