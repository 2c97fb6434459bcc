"""OpenModelica's OMSimulator (../shared/tools/OMSimulator) runs every native FMU on its own and
every built and exported SSP, FMI 2.0 and FMI 3.0, as a user of OMSimulator types it.

Each run must exit 0 with no ``warning:`` or ``error:`` line in its log, and give what the
orchestrator (the engine of ``tapmp run``) gives on OMSimulator's conventions: Jacobi ordering
(every FMU steps from t on the inputs of t) and an accumulated clock (t += h, so 2,000 steps of
1e-4 s end at 0.1999999999999943 s and OMSimulator adds a last step of 5.7e-15 s). That time lies
on the controller's sample grid (k = 2000), so the short step computes the command of that sample,
exactly the one a further 1e-4 s step would compute, and nothing blows up.

OMSimulator 3.0.0 reads the ``dependencies`` of FMI 2.0 FMUs but takes none from FMI 3.0 FMUs:
there it assumes every initial unknown depends on every input, reports ``Alg. loop (size 9/45)``
(an info line) and its default loop solver (KINSOL) needs directional derivatives the FMUs do not
provide. FMI 3.0 systems therefore run with ``--algLoopSolver=fixedpoint``, which converges on
the first pass (there is no loop) and gives the FMI 2.0 results bit for bit.
"""

import shutil
import subprocess
import types
from pathlib import Path

from tests.interop import compatibility
import numpy as np
import pytest
import scipy.io
from tests.support.runs import COMMANDS, MOTOR_POSITIONS, PAPER, orchestrator_rows, paper_scenario
from tests.support.shared import shared
from fmpy import simulate_fmu

from orchestrator.cli import main
from tapmp.interface import CONTROLLER, FMU_NAMES

OMS = "tools/OMSimulator/bin/OMSimulator"
pytestmark = pytest.mark.needs_shared(OMS)
NAMES = MOTOR_POSITIONS + COMMANDS
STEP = 1e-4
FIXED_POINT = ["--algLoopSolver=fixedpoint"]  # FMI 3.0: see the module docstring
LOOP_OF_FMI3 = "Alg. loop (size 9/45)"
# Measured maxima (tests/interop/measure_tools.py): against the orchestrator on OMSimulator's conventions
# the commands and encoder positions are identical and the true positions differ in the last bit;
# against `tapmp run` with its defaults (Gauss-Seidel, exact clock) by the Jacobi delay.
POSITION_LAST_BIT = 1e-15      # [m]
DEFAULTS_POSITION = 0.2e-6     # [m]   measured 0.094 um
DEFAULTS_ENCODER = 0.1e-6      # [m]   one encoder count
DEFAULTS_COMMAND = 25.0        # [N]   measured 20 N


@pytest.fixture(scope="session")
def omsimulator(tmp_path_factory) -> Path:
    """The OMSimulator program, able to find its SSP schemas.

    OMSimulator validates every SystemStructure.ssd against the SSP schemas it looks for in
    ``../share/OMSimulator/schema`` beside its ``bin/``; a copy of the tool that turned that
    symbolic link into a file holding the link's target warns "could not load the ssd schema file"
    and validates nothing. Then the program is run from a scratch tree where the link is restored,
    so the schema check runs (the libraries stay where they are)."""
    return runnable(shared(OMS), tmp_path_factory.mktemp("omsimulator"))


def runnable(program: Path, tree: Path) -> Path:
    """``program``, or a copy of it in ``tree`` that finds its schemas (see :func:`omsimulator`)."""
    root = program.parent.parent
    schema = root / "share" / "OMSimulator" / "schema"
    if schema.is_dir():
        return program
    target = (schema.parent / schema.read_text().strip()).resolve()
    assert (target / "ssp" / "SystemStructureDescription.xsd").is_file(), target
    (tree / "bin").mkdir()
    (tree / "share" / "OMSimulator").mkdir(parents=True)
    shutil.copy2(program, tree / "bin" / "OMSimulator")  # it finds share/ from its own location
    (tree / "lib").symlink_to(root / "lib")
    (tree / "share" / "OMSimulator" / "schema").symlink_to(target)
    return tree / "bin" / "OMSimulator"


def run_omsimulator(program: Path, args: list, cwd: Path, loop: str | None = None) -> str:
    """Run OMSimulator in ``cwd``; assert exit 0, no warning or error line and no algebraic loop
    but ``loop`` (the info line OMSimulator prints for FMI 3.0 systems); return its log."""
    proc = subprocess.run([str(program), *map(str, args)], cwd=cwd, capture_output=True, text=True, timeout=600)
    log = proc.stdout + proc.stderr
    assert proc.returncode == 0, log
    bad = [line for line in log.splitlines() if line.startswith(("warning:", "error:"))]
    assert bad == [], log
    loops = [line for line in log.splitlines() if "Alg. loop" in line]
    assert loops == ([f"info:    {loop}"] if loop else []), log
    return log


def read_mat(path: Path) -> dict:
    """{variable: values} of an OMSimulator result file (.mat, the Modelica result format:
    names and dataInfo column-wise, data_2 one row per variable)."""
    m = scipy.io.loadmat(str(path), chars_as_strings=False)
    names = ["".join(col).rstrip("\x00 ") for col in m["name"].T]
    info = m["dataInfo"]
    n = m["data_2"].shape[1]
    out = {}
    for j, name in enumerate(names):
        matrix, column = info[0, j], info[1, j]
        data = m["data_1"] if matrix == 1 else m["data_2"]
        values = np.sign(column) * data[abs(column) - 1, :]
        out[name] = np.full(n, values[0]) if matrix == 1 else values
    return out


def at_communication_points(result: dict, names, prefix: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(times, rows at t_0 ... t_n, row after OMSimulator's last short step). OMSimulator records
    every time twice (before and after it updates the inputs; the outputs are the same); the last
    recorded time of each step is kept."""
    t = result["time"]
    last = {}
    for i, ti in enumerate(t):
        last[ti] = i
    times = np.array(sorted(last))
    rows = np.array([[result[prefix + n][last[ti]] for n in names] for ti in times])
    return times[:-1], rows[:-1], rows[-1]


def assert_the_clock_of_omsimulator(times):
    """2,000 accumulated steps of 1e-4 s, then one of ~5.7e-15 s to reach 0.2 s."""
    assert len(times) == 2001
    assert np.array_equal(times, np.cumsum([0.0] + [STEP] * 2000))
    assert 0 < 0.2 - times[-1] < 1e-13


# -- the native FMUs on their own -------------------------------------------------------------------

@pytest.mark.parametrize("model", FMU_NAMES)
@pytest.mark.parametrize("version", ["fmi2", "fmi3"])
def test_omsimulator_runs_each_native_fmu_alone_as_fmpy_does(omsimulator, native_built, version, model, tmp_path,
                                                           request):
    fmu = native_built[version][model]
    run_omsimulator(omsimulator, ["--tempDir=.", "--resultFile=alone.mat", "--mode=cs", "--stopTime=0.2",
                                  f"--stepSize={STEP}", fmu], tmp_path)
    result = read_mat(tmp_path / "alone.mat")
    # inputs at their start values; one step more than OMSimulator's 2,000 for the sample k = 2000
    ours = simulate_fmu(str(fmu), stop_time=0.2001, output_interval=STEP)
    outputs = [n for n in ours.dtype.names if n != "time"]
    times, rows, final = at_communication_points(result, outputs, "")
    assert_the_clock_of_omsimulator(times)
    expected = np.array([ours[n] for n in outputs]).T[:2001]
    after = np.array([ours[n] for n in outputs]).T[2001]
    # fmpy steps to t0 + k h with h = 1e-4, OMSimulator to the accumulated sum with h = the
    # difference of its times: the trajectory (a function of t) and the plant (integrated over h)
    # differ in the last digits
    diff = np.abs(rows - expected).max(axis=0)
    assert np.all(diff <= 1e-12 * np.abs(expected).max(axis=0)), dict(zip(outputs, diff))
    assert np.abs(rows[-1]).max() > 1e-3  # the FMU computed something (gravity, feedforward, reference)
    if model == CONTROLLER:  # the 5.7e-15 s step from t = 0.2 - 5.7e-15 s takes the sample k = 2000
        assert np.array_equal(final, after), dict(zip(outputs, final - after))
    else:                    # the plant and the reference move by 5.7e-15 s
        assert np.allclose(final, rows[-1], rtol=1e-12, atol=1e-15)
    compatibility.record(
        request, tool="OMSimulator", version=compatibility.omsimulator_version(omsimulator), fmi=version[3] + ".0",
        interface="CS", command=f"{compatibility.OMSIMULATOR} --mode=cs --stopTime=0.2 --stepSize=0.0001 "
                                f"{compatibility.family_path(version, model)}",
        difference=compatibility.difference(compatibility.relative(rows, expected), "relative",
                                            "FMPy simulate_fmu (OMSimulator's accumulated clock)"))


# -- the built SSPs, as shipped ---------------------------------------------------------------------

def built_ssp(family, built, native_built):
    return built["ssp"] if family == "python" else native_built[family]["ssp"]


FMU_DEFAULTS = types.SimpleNamespace(parameters=lambda: {}, start_time=0.0, step=STEP, n_steps=2000)


@pytest.mark.parametrize("family", ["python", "fmi2", "fmi3"])
def test_omsimulator_runs_the_built_ssp_as_shipped_writing_the_result_file_it_names(
        omsimulator, built, native_built, family, tmp_path, request):
    ssp = built_ssp(family, built, native_built)
    extra = FIXED_POINT if family == "fmi3" else []
    # OMSimulator's stop time defaults to 1 s whatever the SSP says; the step comes from the SSP
    run_omsimulator(omsimulator, [*extra, "--stopTime=0.2", ssp], tmp_path, LOOP_OF_FMI3 if family == "fmi3" else None)
    csv = tmp_path / "TAPMP_res.csv"  # named in the SSP's DefaultExperiment annotation
    header = csv.read_text().splitlines()[0].split(",")
    data = np.loadtxt(csv, delimiter=",", skiprows=1)
    result = {name.strip('"'): data[:, i] for i, name in enumerate(header)}
    # the CSV holds 12 significant digits: the times 0.2 - 5.7e-15 s and 0.2 s print alike, the
    # row of the latter is kept
    times, rows, _ = at_communication_points(result, NAMES, "TAPMP.TAPMP.")
    assert np.allclose(times, np.arange(2000) * STEP, rtol=0, atol=1e-15)  # the SSP's step: 1e-4 s
    ours = orchestrator_rows(ssp, FMU_DEFAULTS, NAMES, "jacobi", clock="accumulated")[:2000]
    assert np.allclose(rows, ours, rtol=1e-11, atol=1e-18), dict(zip(NAMES, np.abs(rows - ours).max(axis=0)))
    assert np.abs(ours[-1, :3]).min() > 1e-3
    compatibility.record(
        request, tool="OMSimulator", version=compatibility.omsimulator_version(omsimulator),
        fmi="3.0" if family == "fmi3" else "2.0", interface="SSP 1.0, CS",
        command=f"{compatibility.OMSIMULATOR} {' '.join(extra + [''])}--stopTime=0.2 {compatibility.family_path(family)}TAPMP.ssp",
        difference=compatibility.difference(compatibility.relative(rows, ours), "relative",
                                            "tapmp run, ordering=jacobi, clock=accumulated (12-digit CSV)"))


# -- the exported SSPs: the scenario's parameter sets applied -----------------------------------------

# What the export carries beyond the FMUs' defaults: the reference at twice the paper's frequency
FASTER = ("trajectory.f_xz=0.8", "trajectory.f_B=0.8")


@pytest.fixture(scope="module")
def exported(built, native_built, tmp_path_factory):
    """{family: exported SSP} of `tapmp export` on the paper scenario shortened to 0.2 s, its
    reference at twice the frequency (FASTER: the paper's own values are the FMUs' defaults)."""
    out = {}
    for family in ("python", "fmi2", "fmi3"):
        path = tmp_path_factory.mktemp(f"export_{family}") / "paper.ssp"
        assert main(["export", str(PAPER), "--ssp", str(built_ssp(family, built, native_built)), "--out",
                     str(path), "--set", "stop_time=0.2", *(a for kv in FASTER for a in ("--set", kv))]) == 0
        out[family] = path
    return out


def run_exported(omsimulator, ssp, family, folder) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    extra = FIXED_POINT if family == "fmi3" else []
    run_omsimulator(omsimulator, [*extra, "--stopTime=0.2", "--resultFile=paper.mat", ssp], folder,
                    LOOP_OF_FMI3 if family == "fmi3" else None)
    return at_communication_points(read_mat(folder / "paper.mat"), NAMES, "TAPMP.TAPMP.")


@pytest.mark.parametrize("family", ["python", "fmi2", "fmi3"])
def test_omsimulator_applies_the_exported_parameter_sets_and_matches_the_orchestrator(
        omsimulator, exported, family, tmp_path, request):
    times, rows, final = run_exported(omsimulator, exported[family], family, tmp_path)
    assert_the_clock_of_omsimulator(times)
    scenario = paper_scenario(0.2, *FASTER)
    ours = orchestrator_rows(exported[family], scenario, NAMES, "jacobi", clock="accumulated")
    after = orchestrator_rows(exported[family], paper_scenario(0.2001, *FASTER), NAMES, "jacobi",
                              clock="accumulated")
    assert np.array_equal(after[:2001], ours)
    diff = np.abs(rows - ours).max(axis=0)
    assert np.all(diff[:3] <= POSITION_LAST_BIT), dict(zip(NAMES, diff))
    assert np.array_equal(rows[:, 3:], ours[:, 3:]), dict(zip(NAMES, diff))  # encoder and commands
    # the bindings reach the FMUs: from the plant's default initial state the motors end up far away
    rest = orchestrator_rows(exported[family], scenario.with_changes(start_on_trajectory=False), NAMES, "jacobi",
                             clock="accumulated")
    assert np.abs(rows[:, :3] - rest[:, :3]).max() > 1e-6
    # the 5.7e-15 s step takes the sample k = 2000: the command a further 1e-4 s step computes
    assert np.array_equal(final[6:], after[2001, 6:]), (final, after[2001])
    assert np.abs(final[:3] - rows[-1, :3]).max() < 1e-15 and np.all(np.abs(final[6:]) < 600)
    extra = FIXED_POINT if family == "fmi3" else []
    compatibility.record(
        request, tool="OMSimulator", version=compatibility.omsimulator_version(omsimulator),
        fmi="3.0" if family == "fmi3" else "2.0", interface="SSP 1.0, CS",
        command=compatibility.export(f"{compatibility.family_path(family)}TAPMP.ssp", f"results/export/paper_{family}.ssp")
                + f" && {compatibility.OMSIMULATOR} {' '.join(extra + [''])}--stopTime=0.2 "
                f"--resultFile=results/export/paper_{family}.mat results/export/paper_{family}.ssp",
        difference=compatibility.difference(compatibility.largest(rows[:, :3], ours[:, :3]), "m",
                                            "tapmp run, ordering=jacobi, clock=accumulated (encoder and "
                                            "commands bit for bit)"))


def test_omsimulator_differs_from_tapmp_run_with_its_defaults_by_the_jacobi_delay(omsimulator, exported, tmp_path):
    times, rows, _ = run_exported(omsimulator, exported["fmi2"], "fmi2", tmp_path)
    ours = orchestrator_rows(exported["fmi2"], paper_scenario(0.2, *FASTER), NAMES, "gauss-seidel")
    diff = np.abs(rows - ours).max(axis=0)
    assert np.all(diff[:3] <= DEFAULTS_POSITION) and np.all(diff[3:6] <= DEFAULTS_ENCODER + 1e-12), diff
    assert np.all(diff[6:] <= DEFAULTS_COMMAND), diff
    assert diff[6:].max() > 1.0  # the orderings do differ: this compares something


def test_fmi3_and_fmi2_ssps_give_the_same_results_in_omsimulator(omsimulator, exported, tmp_path):
    (tmp_path / "fmi2").mkdir()
    (tmp_path / "fmi3").mkdir()
    _, fmi2, _ = run_exported(omsimulator, exported["fmi2"], "fmi2", tmp_path / "fmi2")
    _, fmi3, _ = run_exported(omsimulator, exported["fmi3"], "fmi3", tmp_path / "fmi3")
    assert np.array_equal(fmi2, fmi3)


def test_without_the_fixed_point_solver_omsimulator_fails_on_the_fmi3_ssp(omsimulator, exported, tmp_path):
    """Why FMI 3.0 systems need --algLoopSolver=fixedpoint: KINSOL asks for directional derivatives."""
    proc = subprocess.run([str(omsimulator), "--stopTime=0.2", "--resultFile=paper.mat", str(exported["fmi3"])],
                          cwd=tmp_path, capture_output=True, text=True, timeout=600)
    log = proc.stdout + proc.stderr
    assert LOOP_OF_FMI3 in log
    assert "doesn't support directional derivatives" in log and "KINSol failed" in log, log
    # what a script checking only the exit code misses (docs/other-tools.md)
    assert proc.returncode == 0 and not (tmp_path / "paper.mat").exists(), log


def test_the_fmi3_ssps_say_in_their_ssd_that_omsimulator_needs_the_fixed_point_solver(native_built):
    """OMSimulator reads its loop solver from its command line only, so the flag is documented in the SSP
    itself; the FMI 2.0 SSP, which needs none, says nothing."""
    import zipfile
    from xml.etree import ElementTree as ET

    def description(ssp):
        with zipfile.ZipFile(ssp) as z:
            return ET.fromstring(z.read("SystemStructure.ssd")).get("description")

    assert "--algLoopSolver=fixedpoint" in description(native_built["fmi3"]["ssp"])
    assert "Event Mode" in description(native_built["fmi3"]["clocked_ssp"])
    assert description(native_built["fmi2"]["ssp"]) is None


def test_omsimulator_writes_two_rows_per_time_with_equal_outputs_and_the_inputs_of_both_steps(
        omsimulator, native_built, tmp_path):
    """docs/other-tools.md: the outputs are equal in both rows of a time; the plant's input F holds in the
    first row the command of the step just done (the controller's F of the previous time), in the second
    the one it passes on for the next step."""
    run_omsimulator(omsimulator, ["--stopTime=0.01", "--resultFile=r.mat", native_built["fmi2"]["ssp"]], tmp_path)
    result = read_mat(tmp_path / "r.mat")
    t = result["time"]
    first = [i for i in range(1, len(t)) if t[i] == t[i - 1]]  # the second row of each time from t1 on
    assert len(first) >= 99
    for name in ("controller.F1", "plant.q1", "plant.q1_true"):
        values = result[f"TAPMP.TAPMP.{name}"]
        assert all(values[i] == values[i - 1] for i in first), name
    F, u = result["TAPMP.TAPMP.controller.F1"], result["TAPMP.TAPMP.plant.F1"]
    assert all(u[i] == F[i] for i in first)                      # second row: the command passed on
    assert all(u[i - 1] == F[i - 2] for i in first)              # first row: the previous time's command
    assert any(u[i] != u[i - 1] for i in first)


def test_the_ssp_step_rules_omsimulator_whatever_its_step_option(omsimulator, exported, tmp_path):
    run_omsimulator(omsimulator, ["--stopTime=0.01", "--stepSize=2e-4", "--resultFile=r.mat", exported["fmi2"]],
                    tmp_path)
    times, _, _ = at_communication_points(read_mat(tmp_path / "r.mat"), NAMES, "TAPMP.TAPMP.")
    assert np.allclose(np.diff(times), STEP, rtol=1e-9) and len(times) >= 100


def test_an_ssp_without_omsimulators_annotation_is_refused_by_it(omsimulator, exported, tmp_path):
    """The vendor annotation is what OMSimulator needs: the same SSP without it aborts on load."""
    import zipfile
    stripped = tmp_path / "stripped.ssp"
    with zipfile.ZipFile(exported["fmi2"]) as src, zipfile.ZipFile(stripped, "w") as dst:
        for item in src.infolist():
            data = src.read(item)
            if item.filename == "SystemStructure.ssd":
                from xml.etree import ElementTree as ET

                from orchestrator.builder.ssp import OMS_ANNOTATION, SSD
                root = ET.fromstring(data)
                for annotations in root.iter(f"{{{SSD}}}Annotations"):
                    for a in list(annotations):
                        if a.get("type") == OMS_ANNOTATION:
                            annotations.remove(a)
                data = ET.tostring(root, encoding="UTF-8", xml_declaration=True)
            dst.writestr(item, data)
    proc = subprocess.run([str(omsimulator), "--stopTime=0.01", str(stripped)], cwd=tmp_path, capture_output=True,
                          text=True, timeout=600)
    assert "[NewSystem] internal error" in proc.stdout + proc.stderr
