"""The native FMI 2.0 and 3.0 plants for Model Exchange, beside their Co-Simulation interface under one
model identifier: FMPy (CVode) and fmusim (CVODE) on both, OMSimulator (CVODE, which it picks by
default when an FMU offers both) on FMI 2.0, integrate the states X, Z, B, dX, dZ, dB from their
derivatives and agree with the Co-Simulation plant's RK4 at 0.1 ms on open-loop forces; the FMI
Compliance Checker (FMI 2.0 only: it knows no FMI 3.0) and FMIL pass the Model Exchange interface, and
a host on FMIL (fmil_me3.c) integrates the FMI 3.0 plant with RK4 as the Co-Simulation plant does.
OMSimulator 3.0.0 runs an FMI 3.0 FMU only inside an SSP ("Unsupported FMI version: 3" for the FMU
alone), so its Model Exchange default is checked on FMI 2.0.

The tolerance. RK4's own error at 0.1 ms, estimated by Richardson extrapolation from the plant at
one and at two RK4 substeps per 0.1 ms (error(h) ~ 16/15 |y_h - y_h/2|), is ~1e-14 of each state's
range over 0.2 s: the Co-Simulation plant is exact to round-off here, so what the comparison
sees is the host's integrator. Its global error, a tolerance rtol per step relative to the
state's magnitude or its nominal (1, as the FMU declares), accumulated over the run, is bounded
by ERROR_GROWTH x rtol x max(max |y|, 1) (measured at rtol = 1e-10: FMPy's CVode and fmusim's
CVODE 16 x, OMSimulator's CVODE 247 x with the forces at their start values). A state agrees if
|ME - CS| <= RK4's estimated error + ERROR_GROWTH x rtol x max(max |y|, 1).
"""

import subprocess
from pathlib import Path

from tests.interop import compatibility
import numpy as np
import pytest
from tests.support.fmil_gaps import fmil_messages, terminal_messages, warnings_and_errors
from tests.support.shared import shared
from fmpy import simulate_fmu
from tests.interop.test_omsimulator import omsimulator, read_mat, run_omsimulator  # noqa: F401 (omsimulator: its fixture)

from tapmp.interface import PLANT

FMUSIM = "tools/fmusim/bin/fmusim"
OMS = "tools/OMSimulator/bin/OMSimulator"
FMU_CHECK = "tools/fmuCheck/fmuCheck.linux64"
FMIL_CHECK = "tools/fmil/fmil_check"
FMIL_LIB = "tools/fmil/lib/libfmilib_shared.so"
STATES = ("X", "Z", "B", "dX", "dZ", "dB")
FORCES = {"F1": 20.0, "F2": 10.0, "F3": 60.0}  # N, held: the platform moves ~0.1 m and ~0.9 rad in 0.2 s
STOP, STEP = 0.2, 1e-4
RTOL = 1e-10
ERROR_GROWTH = 1000.0  # global error over rtol x max(|y|, nominal): measured at most 247 (module docstring)


FAMILIES = ("fmi2", "fmi3")
FMI = {"fmi2": "2.0", "fmi3": "3.0"}


@pytest.fixture(scope="module", params=FAMILIES)
def family(request):
    return request.param


@pytest.fixture(scope="module")
def plant(native_built, family):
    return native_built[family][PLANT]


def run_cs(fmu: Path, start: dict, substeps: int = 1) -> np.ndarray:
    """The Co-Simulation plant (RK4, ``substeps`` per 0.1 ms) in FMPy: rows of STATES at t_0 ... t_n."""
    result = simulate_fmu(str(fmu), fmi_type="CoSimulation", stop_time=STOP, output_interval=STEP,
                          start_values={**start, "substeps": substeps}, output=list(STATES))
    return np.array([result[n] for n in STATES]).T


@pytest.fixture(scope="module")
def rk4(plant):
    """(the Co-Simulation rows, RK4's estimated error per state [m, m, rad, m/s, m/s, rad/s])."""
    one, two = run_cs(plant, FORCES), run_cs(plant, FORCES, substeps=2)
    return one, 16.0 / 15.0 * np.abs(one - two).max(axis=0)


def assert_agrees(me: np.ndarray, cs: np.ndarray, rk4_error: np.ndarray, rtol: float) -> np.ndarray:
    """|ME - CS| within RK4's error and the integrator's bound, state by state; the differences."""
    diff = np.abs(me - cs).max(axis=0)
    bound = rk4_error + ERROR_GROWTH * rtol * np.maximum(np.abs(cs).max(axis=0), 1.0)
    assert np.all(diff <= bound), dict(zip(STATES, zip(diff, bound)))
    return diff


def test_rk4_at_the_servo_step_is_exact_to_round_off_here(rk4):
    cs, error = rk4
    assert np.all(error <= 1e-12 * np.abs(cs).max(axis=0)), dict(zip(STATES, error))  # measured <= 1e-14
    assert np.abs(cs[-1, :3]).min() > 0.05  # m, rad: it moved


def test_fmpy_cvode_on_the_model_exchange_plant_agrees_with_rk4(family, plant, rk4, request):
    cs, error = rk4
    result = simulate_fmu(str(plant), fmi_type="ModelExchange", solver="CVode", relative_tolerance=RTOL,
                          stop_time=STOP, output_interval=STEP, start_values=FORCES, output=list(STATES))
    me = np.array([result[n] for n in STATES]).T
    assert me.shape == cs.shape
    diff = assert_agrees(me, cs, error, RTOL)
    assert diff.max() > 0.0  # another integrator: not the same doubles
    compatibility.record(
        request, tool="FMPy", version=compatibility.python_version("fmpy"), fmi=FMI[family], interface="ME",
        command=compatibility.python_c(
            f"from fmpy import simulate_fmu; r = simulate_fmu('build/native/{family}/TAPMP_Plant.fmu', "
            "fmi_type='ModelExchange', solver='CVode', relative_tolerance=1e-10, stop_time=0.2, output_interval=1e-4, "
            f"start_values={FORCES!r}); print(r[-1])"),
        difference=compatibility.difference(compatibility.relative(me, cs), "relative",
                                            "the Co-Simulation plant (RK4 at 0.1 ms)"))


def test_fmusim_cvode_on_the_model_exchange_plant_agrees_with_rk4(family, plant, rk4, tmp_path, request):
    cs, error = rk4
    args = [str(shared(FMUSIM)), "--interface-type", "me", "--solver", "cvode", "--tolerance", repr(RTOL),
            "--stop-time", repr(STOP), "--output-interval", repr(STEP), "--logging-on", "--log-level", "warning",
            "--log-file", "log.txt", "--output-file", "me.csv"]
    for name, value in FORCES.items():
        args += ["--start-value", name, repr(value)]
    proc = subprocess.run([*args, str(plant)], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert (tmp_path / "log.txt").read_text() == ""  # no warning, no error
    result = np.genfromtxt(tmp_path / "me.csv", delimiter=",", names=True)
    me = np.array([result[n] for n in STATES]).T
    assert me.shape == cs.shape
    assert_agrees(me, cs, error, RTOL)
    compatibility.record(
        request, tool="fmusim", version=compatibility.fmusim_version(shared(FMUSIM)), fmi=FMI[family], interface="ME",
        command=f"{compatibility.FMUSIM} --interface-type me --solver cvode --tolerance 1e-10 --stop-time 0.2 "
                "--output-interval 1e-4 " + "".join(f"--start-value {n} {v!r} " for n, v in FORCES.items())
                + f"build/native/{family}/TAPMP_Plant.fmu",
        difference=compatibility.difference(compatibility.relative(me, cs), "relative",
                                            "the Co-Simulation plant (RK4 at 0.1 ms)"))


@pytest.mark.needs_shared(OMS)
def test_omsimulator_picks_model_exchange_by_default_and_agrees_with_rk4(omsimulator, native_built, tmp_path,
                                                                         request):
    """OMSimulator's --mode defaults to "me" when an FMU offers both: its CVODE (tolerance 1e-4 unless
    --tolerance) integrates the plant. Here with no input set: F at its start values, the paper run's first
    command, held (the platform drifts off)."""
    program, plant = omsimulator, native_built["fmi2"][PLANT]
    log = run_omsimulator(program, ["--tempDir=.", "--resultFile=me.mat", f"--stopTime={STOP!r}",
                                    f"--stepSize={STEP!r}", f"--tolerance={RTOL!r}", plant], tmp_path)
    assert "NumRhsEvals" in log  # CVODE's statistics: Model Exchange
    result = read_mat(tmp_path / "me.mat")
    times = result["time"]
    keep = np.r_[np.diff(times) > 0, True]  # each time once (OMSimulator records event points twice)
    me = np.array([result[n][keep] for n in STATES]).T
    cs_result = simulate_fmu(str(plant), fmi_type="CoSimulation", stop_time=STOP, output_interval=STEP,
                             output=list(STATES))
    cs = np.array([np.interp(times[keep], cs_result["time"], cs_result[n]) for n in STATES]).T
    on_grid = np.isclose(times[keep] / STEP, np.round(times[keep] / STEP), rtol=0, atol=1e-6)
    assert on_grid.sum() >= 2000
    diff = np.abs(me[on_grid] - cs[on_grid]).max(axis=0)
    bound = ERROR_GROWTH * RTOL * np.maximum(np.abs(cs).max(axis=0), 1.0)  # RK4's error: ~1e-14, left out
    assert np.all(diff <= bound), dict(zip(STATES, zip(diff, bound)))
    cs_log = run_omsimulator(program, ["--tempDir=.", "--resultFile=cs.mat", "--mode=cs", f"--stopTime={STOP!r}",
                                       f"--stepSize={STEP!r}", plant], tmp_path)
    assert "NumRhsEvals" not in cs_log  # --mode=cs: the FMU's own RK4
    compatibility.record(
        request, tool="OMSimulator", version=compatibility.omsimulator_version(program), fmi="2.0", interface="ME",
        command=f"{compatibility.OMSIMULATOR} --stopTime=0.2 --stepSize=0.0001 --tolerance=1e-10 "
                "build/native/fmi2/TAPMP_Plant.fmu",  # Model Exchange: its default when an FMU offers both
        difference=compatibility.difference(compatibility.relative(me[on_grid], cs[on_grid]), "relative",
                                            "the Co-Simulation plant (RK4 at 0.1 ms)"))


# A system of the FMI 3.0 plant alone in OMSimulator's strongly coupled system (CVODE: Model Exchange)
ONE_PLANT_SSD = """<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:oms="https://raw.githubusercontent.com/OpenModelica/OMSimulator/master/schema/oms.xsd" name="me" version="1.0">
  <ssd:System name="root">
    <ssd:Elements>
      <ssd:Component name="plant" type="application/x-fmu-sharedlibrary" source="resources/TAPMP_Plant.fmu">
        <ssd:Connectors><ssd:Connector name="X" kind="output"><ssc:Real/></ssd:Connector></ssd:Connectors>
      </ssd:Component>
    </ssd:Elements>
    <ssd:Annotations><ssc:Annotation type="org.openmodelica"><oms:Annotations><oms:SimulationInformation>
      <oms:VariableStepSolver description="cvode" absoluteTolerance="1e-10" relativeTolerance="1e-10"
          minimumStepSize="1e-12" maximumStepSize="1e-4" initialStepSize="1e-6"/>
    </oms:SimulationInformation></oms:Annotations></ssc:Annotation></ssd:Annotations>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0.0" stopTime="0.2"/>
</ssd:SystemStructureDescription>
"""


@pytest.mark.needs_shared(OMS)
def test_omsimulator_runs_the_fmi3_plant_only_as_co_simulation_inside_an_ssp(omsimulator, native_built, tmp_path):
    """OMSimulator 3.0.0 has no FMI 3.0 Model Exchange: the FMI 3.0 plant alone is refused ("Unsupported FMI
    version: 3"), and so is a strongly coupled (CVODE) SSP system holding it; its users get the plant's
    Co-Simulation RK4, in an SSP's fixed-step system (tests/interop/test_omsimulator.py)."""
    import zipfile
    plant = native_built["fmi3"][PLANT]
    alone = subprocess.run([str(omsimulator), "--tempDir=.", "--stopTime=0.2", str(plant)], cwd=tmp_path,
                           capture_output=True, text=True, timeout=300)
    log = alone.stdout + alone.stderr
    assert alone.returncode != 0 and "error:   [NewComponent] Unsupported FMI version: 3" in log, log
    with zipfile.ZipFile(tmp_path / "me.ssp", "w") as z:
        z.writestr("SystemStructure.ssd", ONE_PLANT_SSD)
        z.write(plant, "resources/TAPMP_Plant.fmu")
    coupled = subprocess.run([str(omsimulator), "--tempDir=.", "--resultFile=me.mat", "--stopTime=0.2", "me.ssp"],
                             cwd=tmp_path, capture_output=True, text=True, timeout=300)
    log = coupled.stdout + coupled.stderr
    assert coupled.returncode != 0 and "error:   [importFromSnapshot] wrong xml schema detected: ssd:Component" in log, log
    assert not (tmp_path / "me.mat").exists()


@pytest.mark.needs_shared(FMU_CHECK)
def test_fmu_compliance_checker_passes_the_model_exchange_interface(native_built, tmp_path, request):
    plant = native_built["fmi2"][PLANT]  # the checker knows FMI 1.0 and 2.0 only
    (tmp_path / "unpack").mkdir()
    proc = subprocess.run([str(shared(FMU_CHECK)), "-k", "me", "-h", "1e-4", "-s", "0.01", "-t", "unpack", "-o",
                           "out.csv", "-e", "log.txt", str(plant)], cwd=tmp_path, capture_output=True, text=True,
                          timeout=300)
    log = (tmp_path / "log.txt").read_text()
    summary = log[log.find("FMU check summary:"):]
    assert proc.returncode == 0, summary or log
    assert "FMU reported:\n\t0 warning(s) and error(s)" in summary, log
    assert "Checker reported:\n\t0 Warning(s)\n\t0 Error(s)" in summary, log
    data = np.genfromtxt(tmp_path / "out.csv", delimiter=",", names=True)
    # t = 0 (twice: before and after its initial event iteration), 1e-4 ... 0.01
    assert len(data) >= 101 and data["time"][-1] == pytest.approx(0.01)
    assert np.all(np.isfinite(data["B"])) and data["B"][-1] != 0.0  # the plant falls
    compatibility.record(
        request, tool="fmuCheck", version=compatibility.readme_version("fmuCheck"), fmi="2.0", interface="ME",
        command=f"{compatibility.FMUCHECK} -k me -h 1e-4 -s 0.01 build/native/fmi2/TAPMP_Plant.fmu",
        difference="none checked (its explicit Euler at 0.1 ms): 0 warnings, 0 errors")


@pytest.mark.needs_shared(FMIL_CHECK)
def test_fmil_reads_both_interfaces_under_one_model_identifier(family, plant, tmp_path, request):
    """FMI 2.0: FMIL names both kinds. FMI 3.0: fmil_check's summary names the Co-Simulation kind only;
    the six state derivatives are read as initial unknowns (15 outputs + 6), and the only messages are
    FMIL's known gaps on the terminals (tests/support/fmil_gaps.py)."""
    proc = subprocess.run([str(shared(FMIL_CHECK)), "parse", str(plant)], cwd=tmp_path, capture_output=True,
                          text=True, timeout=300)
    assert "outputs 15, initial unknowns 21" in proc.stdout  # the 15 outputs and the 6 state derivatives
    if family == "fmi2":
        assert proc.returncode == 0 and proc.stderr == "", proc.stdout + proc.stderr
        assert "kind ModelExchange and CoSimulation, model TAPMP_Plant" in proc.stdout, proc.stdout
        assert "FMIL parse: 0 warnings, 0 errors" in proc.stdout
        difference = "none (reads the FMU's XML only): no warning or error, both interfaces"
    else:
        assert proc.returncode == 1, proc.stdout + proc.stderr  # fmil_check: exit 1 on any message
        assert fmil_messages(proc.stderr) == terminal_messages(plant), proc.stderr
        warnings, errors = warnings_and_errors(terminal_messages(plant))
        assert f"FMIL parse: {warnings} warnings, {errors} errors" in proc.stdout, proc.stdout
        assert "variables 65," in proc.stdout  # time, the 58 variables, the 6 state derivatives
        difference = ("none (reads the FMU's XML only): the state derivatives read; no message but its known "
                      "gaps on the terminals")
    compatibility.record(
        request, tool="FMIL", version=compatibility.readme_version("fmil"), fmi=FMI[family], interface="ME",
        command=f"{compatibility.FMIL_CHECK} parse build/native/{family}/TAPMP_Plant.fmu"
        + ('' if family == "fmi2" else ' || echo "exit code $?"'), difference=difference)


@pytest.mark.needs_shared(FMIL_LIB)
def test_an_fmil_host_runs_the_fmi3_model_exchange_interface_as_the_co_simulation_plant_steps(native_built, tmp_path,
                                                                                             request):
    """FMI Library loads the FMI 3.0 plant for Model Exchange (tests/interop/fmil_me3.c, compiled here against
    ../shared/tools/fmil) and the host integrates it with the Co-Simulation plant's own method, RK4 at
    0.1 ms: the same states to round-off (the C model's operations in another order: measured 6e-15
    of each state's range). FMIL's only messages are its known gaps on the terminals."""
    from tests.support.ctools import compile_c
    plant = native_built["fmi3"][PLANT]
    fmil = shared("tools/fmil")
    host = tmp_path / "fmil_me3"
    built = compile_c(["-O2", f"-I{fmil / 'include'}", "-o", host, Path(__file__).with_name("fmil_me3.c"),
                       f"-L{fmil / 'lib'}", "-lfmilib_shared", f"-Wl,-rpath,{fmil / 'lib'}", "-lm"])
    assert built.returncode == 0, built.stderr
    (tmp_path / "unpack").mkdir()
    proc = subprocess.run([str(host), str(plant), str(tmp_path / "unpack"), "me.csv", repr(STOP), repr(STEP)],
                          cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert proc.stdout.splitlines() == [
        "kind ModelExchange and CoSimulation: yes, model identifiers ME TAPMP_Plant CS TAPMP_Plant, state "
        "derivatives 6", "continuous states 6", "FMIL Model Exchange run: 2000 RK4 steps"]
    assert fmil_messages(proc.stderr.replace("[FMIL me3]", "[FMIL alone]")) == terminal_messages(plant), proc.stderr
    me = np.loadtxt(tmp_path / "me.csv", delimiter=",")
    cs = run_cs(plant, {})
    assert me.shape == (cs.shape[0], 1 + len(STATES))
    scale = np.abs(cs).max(axis=0)
    assert np.all(np.abs(me[:, 1:] - cs).max(axis=0) <= 1e-13 * scale)
    compatibility.record(
        request, tool="FMIL", version=compatibility.readme_version("fmil"), fmi="3.0", interface="ME",
        command="bash tests/interop/rows/fmil_me3.sh build/native/fmi3/TAPMP_Plant.fmu results/fmil_me3",
        difference=compatibility.difference(compatibility.relative(me[:, 1:], cs), "relative",
                                            "the Co-Simulation plant (RK4 at 0.1 ms)"))
