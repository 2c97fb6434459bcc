"""TAPMP.ssp and the SSP loader (orchestrator.engine.master.CoSimulation): bad files give one
clear error naming the file, bad connections are rejected before any FMU runs."""

import re
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import pytest
from fmpy.ssp.ssd import read_ssd

from orchestrator.cli import main
from orchestrator.engine import instance
from orchestrator.engine.master import CoSimulation, CoSimulationError
from tapmp.interface import CONNECTIONS, ELEMENT, FMU_NAMES

ROOT = Path(__file__).resolve().parents[2]
PAPER = str(ROOT / "scenarios" / "paper_simulation.toml")


def test_ssp_holds_the_three_fmus_and_every_connection_of_the_interface(built):
    ssd = read_ssd(str(built["ssp"]))
    assert {(e.name, e.source) for e in ssd.system.elements} == {
        (ELEMENT[m], f"resources/{m}.fmu") for m in FMU_NAMES}
    got = {(c.startElement, c.startConnector, c.endElement, c.endConnector) for c in ssd.system.connections}
    assert got == {(ELEMENT[a], x, ELEMENT[b], y) for a, x, b, y in CONNECTIONS} and len(got) == 18


def rewrite_ssp(src: Path, dst: Path, ssd=None, drop=(), replace=None) -> Path:
    """A copy of the SSP archive with SystemStructure.ssd edited (``ssd``: str -> str),
    members dropped or replaced (name -> bytes)."""
    replace = replace or {}
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for name in zin.namelist():
            if name in drop:
                continue
            data = replace.get(name, zin.read(name))
            if name == "SystemStructure.ssd" and ssd:
                data = ssd(data.decode()).encode()
            zout.writestr(name, data)
    return dst


def bad_ssps(built, tmp: Path) -> dict:
    """name -> (path of a broken SSP, expected message after "error: ")."""
    ssp = built["ssp"]
    plant = "resources/TAPMP_Plant.fmu"
    plant_bytes = zipfile.ZipFile(ssp).read(plant)
    conn = 'startElement="plant" startConnector="q1" endElement="controller" endConnector="q1"'
    force = 'startElement="controller" startConnector="F1" endElement="plant" endConnector="F1"'
    cases = {}
    (tmp / "text.ssp").write_text("not an archive\n")
    cases["not a zip"] = (tmp / "text.ssp", r"cannot read SSP file .*text\.ssp: File is not a zip file")
    (tmp / "truncated.ssp").write_bytes(Path(ssp).read_bytes()[:4000])
    cases["truncated"] = (tmp / "truncated.ssp", r"cannot read SSP file .*truncated\.ssp: File is not a zip")
    cases["an FMU"] = (built["TAPMP_Plant"], r"cannot read SSP file .*TAPMP_Plant\.fmu: .*no item named "
                       r"'SystemStructure\.ssd'")
    cases["FMU missing"] = (rewrite_ssp(ssp, tmp / "nofmu.ssp", drop=(plant,)),
                            r"nofmu\.ssp: the FMU resources/TAPMP_Plant\.fmu of element plant is missing")
    cases["FMU corrupt"] = (rewrite_ssp(ssp, tmp / "corrupt.ssp", replace={plant: b"garbage"}),
                            r"corrupt\.ssp: cannot load the FMU resources/TAPMP_Plant\.fmu of element plant "
                            r"\(truncated or not an FMU\)")
    cases["FMU truncated"] = (rewrite_ssp(ssp, tmp / "cut.ssp", replace={plant: plant_bytes[:20000]}),
                              r"cut\.ssp: cannot load the FMU resources/TAPMP_Plant\.fmu of element plant")
    cases["unknown output"] = (
        rewrite_ssp(ssp, tmp / "q9.ssp",
                    ssd=lambda s: s.replace(conn, conn.replace('Connector="q1" end', 'Connector="q9" end'))),
        r"q9\.ssp: connection plant\.q9 -> controller\.q1: plant \(TAPMP_Plant\) has no Real output 'q9': "
        r"allowed are q1, q2, q3, q1_true")
    cases["unknown input"] = (
        rewrite_ssp(ssp, tmp / "force.ssp", ssd=lambda s: s.replace(force, force.replace('endConnector="F1"', 'endConnector="Fx1"'))),
        r"connection controller\.F1 -> plant\.Fx1: plant \(TAPMP_Plant\) has no Real input 'Fx1': "
        r"allowed are F1, F2, F3")
    cases["unknown element"] = (
        rewrite_ssp(ssp, tmp / "elem.ssp", ssd=lambda s: s.replace(conn, conn.replace('"plant"', '"plnt"'))),
        r"connection plnt\.q1 -> controller\.q1: element 'plnt' does not exist: allowed are trajectory, "
        r"controller, plant")
    cases["reversed"] = (
        rewrite_ssp(ssp, tmp / "rev.ssp", ssd=lambda s: s.replace(conn, conn.replace('"plant"', '"X"')
                                                                   .replace('"controller"', '"plant"')
                                                                   .replace('"X"', '"controller"'))),
        r"connection controller\.q1 -> plant\.q1: controller \(TAPMP_Controller\) has no Real output 'q1'")
    cases["input driven twice"] = (
        rewrite_ssp(ssp, tmp / "twice.ssp", ssd=lambda s: s.replace(
            conn, conn.replace('endConnector="q1"', 'endConnector="q2"'))),
        r"connection plant\.q2 -> controller\.q2: input controller\.q2 is driven already by plant\.q1")
    return cases


CASES = ["not a zip", "truncated", "an FMU", "FMU missing", "FMU corrupt", "FMU truncated", "unknown output",
         "unknown input", "unknown element", "reversed", "input driven twice"]


@pytest.fixture(scope="module")
def broken(built, tmp_path_factory):
    return bad_ssps(built, tmp_path_factory.mktemp("bad_ssp"))


@pytest.mark.parametrize("case", CASES)
def test_bad_ssp_is_rejected_by_the_loader_naming_the_file_before_any_fmu_runs(broken, case, tmp_path,
                                                                              monkeypatch):
    path, message = broken[case]
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))  # where the loader extracts the SSP
    instantiated = []
    real = instance.FMU2Slave.instantiate
    monkeypatch.setattr(instance.FMU2Slave, "instantiate",
                        lambda self, *a, **k: instantiated.append(self) or real(self, *a, **k))
    with pytest.raises(CoSimulationError, match=message) as info:
        with CoSimulation(path, {}):
            pytest.fail("entered a co-simulation of a broken SSP")
    assert Path(path).name in str(info.value)
    assert instantiated == []                              # no FMU was instantiated
    assert list(tmp_path.glob("tapmp_cosim_*")) == []     # and nothing extracted is left


@pytest.mark.parametrize("case", ["truncated", "FMU missing", "FMU corrupt", "unknown output"])
def test_tapmp_run_with_a_bad_ssp_prints_one_line_and_exits_2(broken, tmp_path, capsys, case):
    path, message = broken[case]
    out = tmp_path / "run"
    assert main(["run", PAPER, "--ssp", str(path), "--out", str(out), "--set", "stop_time=0.001",
                 "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: ") and "Traceback" not in err
    assert Path(path).name in err and re.search(message, err)
    assert not (out / "results.csv").exists()  # rejected before any step


@pytest.mark.slow
def test_tapmp_run_debug_shows_the_traceback(broken, tmp_path):
    path, _ = broken["unknown output"]
    proc = subprocess.run([sys.executable, "-m", "orchestrator", "--debug", "run", PAPER, "--ssp", str(path),
                           "--out", str(tmp_path / "run"), "--no-progress"], capture_output=True, text=True)
    assert proc.returncode == 2 and "Traceback" in proc.stderr and "has no Real output 'q9'" in proc.stderr
