"""The SSP loader against crafted systems, through the real `tapmp run`: element
names and FMU sources are not trusted as paths, every FMU input is driven or declared open."""

import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from tests.support.faults import faulty_plant_fmu, faulty_ssp

pytestmark = pytest.mark.slow  # every case runs tapmp run in a child process

ROOT = Path(__file__).resolve().parents[2]
PAPER = str(ROOT / "scenarios" / "paper_simulation.toml")
SSD = "SystemStructure.ssd"
TRAJECTORY = 'name="trajectory" type="application/x-fmu-sharedlibrary" source="resources/TAPMP_Trajectory.fmu"'
CONTROLLER = 'name="controller" type="application/x-fmu-sharedlibrary" source="resources/TAPMP_Controller.fmu"'
DQ1 = '<ssd:Connection startElement="plant" startConnector="dq1" endElement="controller" endConnector="dq1" />'


def craft_ssp(src: Path, dst: Path, edit=lambda ssd: ssd, extra: dict | None = None) -> Path:
    """A copy of the SSP archive ``src`` with SystemStructure.ssd edited and ``extra`` members
    (name -> bytes) added, written as given (zipfile keeps names like ``../x`` as they are)."""
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for name in zin.namelist():
            data = zin.read(name)
            zout.writestr(name, edit(data.decode()).encode() if name == SSD else data)
        for name, data in (extra or {}).items():
            zout.writestr(zipfile.ZipInfo(name), data)
    return dst


def tapmp(*args, cwd: Path, tmpdir: Path, timeout=120) -> subprocess.CompletedProcess:
    """The real command line in a child process, with its temp folder in ``tmpdir``."""
    env = dict(os.environ, TMPDIR=str(tmpdir))
    return subprocess.run([sys.executable, "-m", "orchestrator", *map(str, args)], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=timeout)


def files_under(folder: Path) -> set:
    """Every path below ``folder`` (files and folders), relative to it."""
    return {p.relative_to(folder) for p in folder.rglob("*")}


@pytest.fixture
def sandbox(tmp_path):
    """A working folder, a private TMPDIR and an output folder below tmp_path."""
    (tmp_path / "tmp").mkdir()
    return tmp_path


# name -> (edit of the SSD given the sandbox, decoy FMU placed where a trusting loader would read it,
#          text the one-line error must hold)
PATH_CASES = {
    "name ../../x": (lambda ssd, box: ssd.replace('name="trajectory"', 'name="../../x"'), None,
                     "element name '../../x' is invalid: allowed is a name matching [A-Za-z_][A-Za-z0-9_]*"),
    "absolute name": (lambda ssd, box: ssd.replace('name="trajectory"', f'name="{box}/abs/dir"'), None,
                      "/abs/dir' is invalid: allowed is a name matching [A-Za-z_][A-Za-z0-9_]*"),
    "duplicate name plant": (lambda ssd, box: ssd.replace('name="controller"', 'name="plant"'), None,
                             "element plant is defined twice: allowed is a name matching [A-Za-z_][A-Za-z0-9_]* "
                             "(letters, digits, _), unique in the system"),
    "absolute source": (lambda ssd, box: ssd.replace(TRAJECTORY, TRAJECTORY.replace(
                            "resources/TAPMP_Trajectory.fmu", f"{box}/abs/x.fmu")), "abs/x.fmu",
                        "element trajectory: source '{box}/abs/x.fmu' points outside the archive: allowed is a "
                        "relative path inside the archive"),
    "source ../../x.fmu": (lambda ssd, box: ssd.replace(TRAJECTORY, TRAJECTORY.replace(
                               "resources/TAPMP_Trajectory.fmu", "../../x.fmu")), "tmp/x.fmu",
                           "element trajectory: source '../../x.fmu' points outside the archive: allowed is a "
                           "relative path inside the archive"),
    "source not in the archive": (lambda ssd, box: ssd.replace(CONTROLLER, CONTROLLER.replace(
                                      "resources/TAPMP_Controller.fmu", "resources/../TAPMP_Controller.fmu")), None,
                                  "the FMU resources/../TAPMP_Controller.fmu of element controller is missing from "
                                  "the archive: allowed are its members resources/TAPMP_Trajectory.fmu, "
                                  "resources/TAPMP_Controller.fmu, resources/TAPMP_Plant.fmu"),
}


@pytest.mark.parametrize("case", PATH_CASES)
def test_element_names_and_sources_are_not_trusted_as_paths(built, sandbox, case):
    edit, decoy, message = PATH_CASES[case]
    box = sandbox
    if decoy:  # a real FMU where the crafted source points: a loader that follows it would run
        (box / decoy).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(built["TAPMP_Trajectory"], box / decoy)
    ssp = craft_ssp(built["ssp"], box / "crafted.ssp", lambda ssd: edit(ssd, box))
    before = files_under(box)
    res = tapmp("run", PAPER, "--ssp", ssp, "--out", box / "out", "--set", "stop_time=0.3", "--no-progress",
                cwd=box, tmpdir=box / "tmp")
    assert res.returncode == 2, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: SSP file {ssp}: "), res.stderr
    assert message.format(box=box) in lines[0]
    created = files_under(box) - before
    assert {p for p in created if p.parts[0] != "out"} == set(), created  # nothing outside out/, tmp/ empty
    run = json.loads((box / "out" / "run.json").read_text())
    assert run["status"] == "failed" and run["exit_code"] == 2 and run["error"] == lines[0][len("error: "):]


@pytest.mark.parametrize("member", ["../evil.txt", "/abs/evil.txt"])
def test_an_archive_member_named_outside_the_archive_is_refused_before_extraction(built, sandbox, member):
    ssp = craft_ssp(built["ssp"], sandbox / "crafted.ssp", extra={member: b"not for you"})
    before = files_under(sandbox)
    res = tapmp("run", PAPER, "--ssp", ssp, "--out", sandbox / "out", "--set", "stop_time=0.3", "--no-progress",
                cwd=sandbox, tmpdir=sandbox / "tmp")
    assert res.returncode == 2, res.stderr
    assert res.stderr.strip() == (f"error: SSP file {ssp}: archive member {member!r} points outside the archive: "
                                  "allowed is a relative path inside the archive, without a leading /, a URI scheme, "
                                  "backslashes or .. above its root, e.g. resources/TAPMP_Plant.fmu")
    assert {p for p in files_under(sandbox) - before if p.parts[0] != "out"} == set()
    assert not Path("/abs/evil.txt").exists()


@pytest.fixture(scope="module")
def no_dq1(built, tmp_path_factory):
    """TAPMP.ssp without the connection plant.dq1 -> controller.dq1."""
    def edit(ssd):
        assert DQ1 in ssd
        return ssd.replace(DQ1, "")
    return craft_ssp(built["ssp"], tmp_path_factory.mktemp("open") / "no_dq1.ssp", edit)


def test_an_input_no_connection_drives_is_refused_with_the_list(no_dq1, sandbox):
    res = tapmp("run", PAPER, "--ssp", no_dq1, "--out", sandbox / "out", "--set", "stop_time=0.3", "--no-progress",
                cwd=sandbox, tmpdir=sandbox / "tmp")
    assert res.returncode == 2, res.stderr
    assert res.stderr.strip() == (f"error: SSP file {no_dq1}: no connection drives the input(s) controller.dq1: "
                                  "allowed is every FMU input driven by a connection, or named in the scenario's "
                                  "open_inputs to keep its start value")
    assert json.loads((sandbox / "out" / "run.json").read_text())["status"] == "failed"
    assert list((sandbox / "tmp").iterdir()) == []


def test_an_input_named_in_open_inputs_may_stay_undriven(no_dq1, sandbox):
    res = tapmp("run", PAPER, "--ssp", no_dq1, "--out", sandbox / "out", "--set", "stop_time=0.3",
                "--set", 'open_inputs=["controller.dq1"]', "--no-progress", cwd=sandbox, tmpdir=sandbox / "tmp")
    assert res.returncode == 0, res.stderr
    run = json.loads((sandbox / "out" / "run.json").read_text())
    assert run["status"] == "completed" and run["scenario"]["open_inputs"] == ["controller.dq1"]


OPEN_INPUT_ERRORS = {
    "not an input": ('["controller.dq9"]', True, "error: open_inputs: 'controller.dq9' is not an input of the "
                     "system in SSP file {ssp}: allowed are controller.X_d, "),
    "an output": ('["plant.q1"]', True, "error: open_inputs: 'plant.q1' is not an input of the system"),
    "driven": ('["controller.dq2"]', True, "error: open_inputs: controller.dq2 is driven by plant.dq2 in SSP file "
               "{ssp}: allowed are inputs that no connection drives"),
    "no element": ('["dq1"]', False, "error: open_inputs[0] = 'dq1' is invalid: allowed is \"element.variable\", "
                   "an FMU input of the system"),
    "twice": ('["controller.dq1", "controller.dq1"]', False,
              "error: open_inputs[1] = 'controller.dq1' is listed twice: allowed is each input once"),
    "not a list": ('"controller.dq1"', False, "error: open_inputs = 'controller.dq1' has the wrong type: allowed is list"),
}


@pytest.mark.parametrize("case", OPEN_INPUT_ERRORS)
def test_open_inputs_entries_are_checked_against_the_system(no_dq1, sandbox, case):
    value, reaches_master, message = OPEN_INPUT_ERRORS[case]
    res = tapmp("run", PAPER, "--ssp", no_dq1, "--out", sandbox / "out", "--set", "stop_time=0.3",
                "--set", f"open_inputs={value}", "--no-progress", cwd=sandbox, tmpdir=sandbox / "tmp")
    assert res.returncode == 2, res.stderr
    assert len(res.stderr.strip().splitlines()) == 1 and res.stderr.startswith(message.format(ssp=no_dq1))
    assert (sandbox / "out").exists() == reaches_master  # scenario errors stop before the output folder


WARNING_STEP = """
    def step(self, t, h):
        super().step(t, h)
        if t >= 4.5e-4:
            self.log(f"friction table extrapolated at t = {t:.6g} s", 1, "logStatusWarning")
"""


def test_a_warning_logged_during_a_step_does_not_stop_the_run(built, tmp_path):
    from orchestrator.engine.master import CoSimulation, RunOptions
    from orchestrator.tool.roles import ROLES
    from orchestrator.tool.scenario import load

    plant = faulty_plant_fmu(tmp_path, WARNING_STEP, "The real plant, logging a warning (not an error) on every "
                                                      "step from t = 0.5 ms.")
    ssp = faulty_ssp(tmp_path / "warn.ssp", plant, built)
    sc = load(PAPER, ["stop_time=0.002"])
    with CoSimulation(ssp, sc.parameters(), RunOptions(start_time=0.0, step_size=sc.step,
                                                       roles=ROLES)) as sim:
        for _ in range(sc.n_steps):
            sim.step()
        assert sim.time == pytest.approx(0.002)
    warnings = [m for m in sim.log if m.startswith("[WARNING] plant: friction table extrapolated")]
    assert len(warnings) == 15  # t = 0.5 ms ... 1.9 ms: logged, and the run went on
