"""A misspelled name is refused with the allowed names and the closest ones: one line, exit 2.

Every case runs the real CLI (``python -m orchestrator``) on a bad file written to the test's
folder; the suggestion is difflib's closest allowed name.
"""

import subprocess
import sys
from pathlib import Path

import pytest

from orchestrator.tool.roles import ROLES, SCENARIO_TABLES
from orchestrator.tool.scenario import TABLES
from tapmp.errors import allowed_are, suggestion

pytestmark = pytest.mark.slow  # every case runs the CLI in a child process

ROOT = Path(__file__).resolve().parents[2]
PAPER = (ROOT / "scenarios" / "paper_simulation.toml").as_posix()


def _cli(*args, cwd):
    return subprocess.run([sys.executable, "-m", "orchestrator", *args], capture_output=True, text=True,
                          cwd=cwd)


def _one_line_exit_2(res, *expected):
    assert res.returncode == 2, res.stderr
    err = res.stderr.strip()
    assert len(err.splitlines()) == 1, err
    assert err.startswith("error: ") and "Traceback" not in err
    for text in expected:
        assert text in err, err
    return err


def test_the_helper_names_the_closest_allowed_names_or_none():
    assert allowed_are("gain_overides", ["trajectory", "gain_overrides", "plant"]) == \
        "allowed are trajectory, gain_overrides, plant; did you mean gain_overrides?"
    assert suggestion("nativ", ["python", "native", "fmi3"]) == "; did you mean native?"
    assert suggestion("zzz", ["python", "native", "fmi3"]) == ""
    assert suggestion("plnt", ["plant", "plant", "controller"]) == "; did you mean plant?"  # listed once


def test_the_scenario_tables_offered_by_the_ssp_check_are_the_scenarios_own():
    # a table the scenario reads itself never reaches the master: the master offers the others
    assert set(SCENARIO_TABLES) == TABLES - set(ROLES)


SCENARIOS = {
    "key": ('name = "x"\nstop_tme = 1.0\n', ["stop_tme is unknown: allowed are name,", "did you mean stop_time"]),
    "law": ('name = "x"\nlaw = "sc_dc"\n', ["law = 'sc_dc' is invalid: allowed are sc-dc,", "did you mean sc-dc"]),
    "gain preset": ('name = "x"\ngains = "paper_simulaton"\n',
                    ["gains = 'paper_simulaton' is invalid", "did you mean paper_simulation"]),
    "family": ('name = "x"\nfmus = "nativ"\n',
               ["fmus = 'nativ' is invalid: allowed are python, native, fmi3; did you mean native?"]),
    "gain name": ('name = "x"\n[gain_overrides]\nLambda_pp = 1.0\n',
                  ["gain_overrides.Lambda_pp is unknown", "did you mean Lambda_p"]),
    "plant parameter": ('name = "x"\n[plant]\nk_pul = 1.0\n', ["plant.k_pul is unknown", "did you mean k_pull"]),
    "limit": ('name = "x"\n[limits]\nmotor_travl = 1.0\n',
              ["limits.motor_travl is unknown: allowed are motor_travel, platform_angle; did you mean motor_travel?"]),
    "mismatch": ('name = "x"\n[mismatch]\nm_pp = 1.1\n', ["mismatch.m_pp is unknown", "did you mean m_p"]),
}


@pytest.mark.parametrize("case", SCENARIOS)
def test_a_misspelled_scenario_name_gets_the_closest_allowed_one(case, tmp_path):
    text, expected = SCENARIOS[case]
    (tmp_path / "bad.toml").write_text(text)
    res = _cli("run", "bad.toml", "--out", "out", cwd=tmp_path)
    _one_line_exit_2(res, *expected)
    assert not (tmp_path / "out").exists()


MISSPELLED_TABLES = {
    "empty": ("", "parameters given for unknown element(s) gain_overides: allowed are trajectory, controller, plant"),
    "a number": ("D = 900.0\n",
                 "parameters given for unknown element(s) gain_overides: allowed are trajectory, controller, plant"),
    # a list is no FMU parameter: the scenario refuses it before the master reads the SSP
    "a list": ("D = [900.0, 900.0, 900.0]\n", "gain_overides.D = [900.0, 900.0, 900.0] is invalid"),
}


@pytest.mark.parametrize("case", MISSPELLED_TABLES)
def test_a_misspelled_table_is_refused_with_the_scenario_table_it_resembles_even_when_empty(case, tmp_path,
                                                                                           built):
    body, expected = MISSPELLED_TABLES[case]
    (tmp_path / "bad.toml").write_text(f'name = "x"\nstop_time = 0.01\n[gain_overides]\n{body}')
    res = _cli("run", "bad.toml", "--ssp", str(built["ssp"]), "--out", "out", "--no-progress", cwd=tmp_path)
    _one_line_exit_2(res, expected, "did you mean gain_overrides?")
    assert not (tmp_path / "out" / "results.csv").exists()


STUDIES = {
    "table": ("[study]\nbase = 'base.toml'\n[grd]\n'law' = ['sc-dc']\n",
              ["[grd] is unknown: allowed are [study], [set], [grid]", "did you mean grid"]),
    "study key": ("[study]\nbase = 'base.toml'\nouptut = 'x'\n[grid]\n'law' = ['sc-dc']\n",
                  ["study.ouptut is unknown: allowed are name,", "did you mean output"]),
    "scenario key": ("[study]\nbase = 'base.toml'\n[grid]\n'stop_tim' = [0.1]\n",
                     ["stop_tim is not a scenario key a study may set", "did you mean stop_time"]),
    "gain": ("[study]\nbase = 'base.toml'\n[grid]\n'gain_overrides.Lambda_vv' = [0.1]\n",
             ["gain_overrides.Lambda_vv is unknown", "did you mean gain_overrides.Lambda_v"]),
    "section parameter": ("[study]\nbase = 'base.toml'\n[grid]\n'plant.k_pul' = [0.0]\n",
                          ["plant.k_pul is unknown", "did you mean k_pull"]),
    "tuned law": ("[study]\nbase = 'base.toml'\n[tune]\nlaws = ['scdc']\n",
                  ["tune.laws = ['scdc'] is invalid: allowed is a list of sc-dc, apd-dc, pid-dc-full; did you mean sc-dc"]),
    "distribution": ("[study]\nbase = 'base.toml'\n[monte_carlo]\nsamples = 2\nseed = 1\n"
                     "[monte_carlo.vary.m]\ntargets = ['plant.k_pull']\ndistribution = 'unifrom'\nlow = 0.0\n"
                     "high = 1.0\n",
                     ["distribution = 'unifrom' is invalid: allowed are uniform, loguniform, normal; "
                      "did you mean uniform"]),
}


@pytest.mark.parametrize("case", STUDIES)
def test_a_misspelled_study_name_gets_the_closest_allowed_one(case, tmp_path):
    text, expected = STUDIES[case]
    (tmp_path / "base.toml").write_text('name = "base"\nstop_time = 0.01\n')
    (tmp_path / "bad.toml").write_text(text)
    res = _cli("study", "bad.toml", cwd=tmp_path)
    _one_line_exit_2(res, *expected)


def test_an_unknown_family_on_the_command_line_gets_the_closest_name(tmp_path):
    res = subprocess.run([sys.executable, "-m", "orchestrator", "run", str(ROOT / "scenarios" / "paper_simulation.toml"),
                          "--fmus", "nativ", "--out", str(tmp_path / "out")], capture_output=True, text=True,
                         cwd=tmp_path)
    assert res.returncode == 2 and not (tmp_path / "out").exists()
    assert res.stderr == ("error: tapmp run: argument --fmus: fmus = 'nativ' is invalid: allowed are python, native, "
                          "fmi3; did you mean native? (see tapmp run --help)\n")
