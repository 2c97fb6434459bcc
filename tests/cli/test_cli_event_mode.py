"""The scenario key event_mode (FMI 3.0 Event Mode) through the real `tapmp` command: `tapmp run` of the
clocked system (native/fmi3/TAPMP_Clocked.ssp) with event_mode = true writes the Event Mode run's results
bit for bit; without it the clocked SSP is one line, exit 2; `tapmp export` says which mode in its
scenario annotation."""

import json
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

import pytest

from orchestrator.cli import main

pytestmark = pytest.mark.slow  # builds the FMI 3.0 FMUs and runs closed loops

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "scenarios" / "paper_simulation.toml"


@pytest.fixture(scope="module")
def fmi3(tmp_path_factory):
    from orchestrator.builder.build_native import build_native
    return build_native(tmp_path_factory.mktemp("native"), families=("fmi3",), log=lambda *_: None,
                        windows=False)["fmi3"]


def run(ssp, out, *settings):
    return main(["run", str(PAPER), "--ssp", str(ssp), "--out", str(out), "--set", "stop_time=0.02",
                 *(a for s in settings for a in ("--set", s))])


def test_run_of_the_clocked_system_with_event_mode_is_the_event_mode_run_bit_for_bit(fmi3, tmp_path):
    assert run(fmi3["clocked_ssp"], tmp_path / "clocked", "event_mode=true") == 0
    assert run(fmi3["ssp"], tmp_path / "events", "event_mode=true") == 0
    clocked = (tmp_path / "clocked" / "results.csv").read_bytes()
    assert clocked == (tmp_path / "events" / "results.csv").read_bytes()
    assert len(clocked.splitlines()) == 202  # header, t = 0 and 200 steps
    assert json.loads((tmp_path / "clocked" / "run.json").read_text())["event_mode"] is True


def test_run_of_the_clocked_system_without_event_mode_is_one_line_exit_2(fmi3, tmp_path, capsys):
    assert run(fmi3["clocked_ssp"], tmp_path / "r") == 2
    err = capsys.readouterr().err
    assert err == (f"error: event_mode = false is invalid for SSP file {fmi3['clocked_ssp']}: the FMU "
                   "TAPMP_ControllerClocked of element controller has the input clock(s) sample_clock, which tick "
                   "only in Event Mode: allowed is event_mode = true\n")


def test_event_mode_that_is_not_a_boolean_is_refused(fmi3, tmp_path, capsys):
    assert run(fmi3["clocked_ssp"], tmp_path / "r", "event_mode=2") == 2
    assert capsys.readouterr().err.startswith("error: event_mode")


@pytest.mark.parametrize("value, written", [("true", "true"), ("false", "false")])
def test_export_says_which_mode_in_its_scenario_annotation(fmi3, tmp_path, value, written):
    out = tmp_path / f"paper_{value}.ssp"
    assert main(["export", str(PAPER), "--ssp", str(fmi3["clocked_ssp"]), "--out", str(out),
                 "--set", f"event_mode={value}"]) == 0
    root = ET.fromstring(zipfile.ZipFile(out).read("SystemStructure.ssd"))
    scenario = [e for e in root.iter() if e.tag.endswith("}Scenario")]
    assert [e.get("eventMode") for e in scenario] == [written]
