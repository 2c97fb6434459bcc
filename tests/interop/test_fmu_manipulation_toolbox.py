"""FMU Manipulation Toolbox (``fmu-manipulation-toolbox`` on PyPI, Renault's FMU container
builder) builds one container FMU from the native TAPMP.ssp, FMI 2.0 and 3.0, with no parameter
set applied (it reads no .ssv), and FMPy runs it.

What its container does, measured here bit for bit: it initializes the embedded FMUs one after
the other in the SSP's order (trajectory, controller, plant), each on the values its inputs'
links hold at that moment, so the controller starts on the plant's outputs at 0 (the builder
warns about the loop it cuts there): a link holds 0 until its source FMU is initialized, and it
overwrites the controller's start values, which are the paper run's initial inputs
(tests/fmu/test_start_values.py: a host that keeps them gives the paper's run in any order); then it steps in its default PARALLEL mode, which is Jacobi:
every FMU steps from t on the link values of t. The three FMUs wired by hand in FMPy on those
conventions give the container's results bit for bit; wired on the orchestrator's (outputs
propagated in Initialization Mode, so the controller's first command sees the plant's initial
velocity) they give `tapmp run` of the paper scenario with ordering = jacobi bit for bit. The
difference between the container and `tapmp run` is therefore the container's first command only:
~336 N instead of ~15 N on motor 1 during the first 0.1 ms, which moves the motors by a few
micrometres and changes the encoder counts the controller sees afterwards.
"""

import math
import shutil
import subprocess
import sys
from pathlib import Path

from tests.interop import compatibility
import numpy as np
import pytest
from tests.support.fmu_host import ssp_fmi2_units
from tests.support.runs import orchestrator_rows, paper_scenario
from fmpy import read_model_description

STEP = 1e-4
STOP = 0.2
NAMES = tuple(f"plant.q{i}" for i in (1, 2, 3)) + tuple(f"controller.F{i}" for i in (1, 2, 3))
CONTAINER_NAMES = tuple(f"tapmp_{n}" for n in NAMES)  # the container's locals: tapmp_<FMU>.<output>
ORDER = ("trajectory", "controller", "plant")  # the SSP's order, the container's initialization order
DEPENDENCY_ORDER = ("trajectory", "plant", "controller")  # the orchestrator's: the plant's outputs need no input
FMT_VERSION = compatibility.python_version("fmu-manipulation-toolbox")
LOOP_WARNING = ("Loop of links through the embedded FMU 'TAPMP_Controller.fmu': it is initialized without the "
                "values its inputs get from the loop.")


def build_container(ssp: Path, folder: Path, fmi: str) -> tuple[Path, str]:
    """`fmucontainer -container TAPMP.ssp:1e-4 [-fmi 3]` in ``folder`` on a copy of ``ssp``; (the
    container FMU, its log)."""
    folder.mkdir(parents=True, exist_ok=True)
    shutil.copy(ssp, folder / "TAPMP.ssp")
    program = Path(sys.executable).with_name("fmucontainer")
    proc = subprocess.run([str(program), "-container", "TAPMP.ssp:0.0001", "-fmi", fmi], cwd=folder,
                          capture_output=True, text=True, timeout=600)
    log = proc.stdout + proc.stderr
    assert proc.returncode == 0, log
    assert "ERROR" not in log.replace("[ERROR] Solver configure", ""), log
    return folder / "TAPMP.fmu", log


@pytest.fixture(scope="module")
def containers(native_built, tmp_path_factory):
    """{"fmi2" | "fmi3": (container FMU, build log)} from each native family's TAPMP.ssp."""
    return {family: build_container(native_built[family]["ssp"], tmp_path_factory.mktemp(f"fmt_{family}"),
                                    family[3]) for family in ("fmi2", "fmi3")}


def run_container(fmu: Path, folder: Path) -> np.ndarray:
    """`fmpy simulate` on the container with its defaults, as docs/other-tools.md types it: rows
    of NAMES at t_0 ... t_n (fmpy writes the shortest round-trip text of each double)."""
    out = folder / f"{fmu.parent.name}.csv"
    fmpy = Path(sys.executable).with_name("fmpy")
    proc = subprocess.run([str(fmpy), "simulate", str(fmu), "--stop-time", repr(STOP), "--output-interval", repr(STEP),
                           "--output-variables", *CONTAINER_NAMES, "--output-file", str(out)],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    header = [n.strip('"') for n in out.read_text().splitlines()[0].split(",")]
    data = np.loadtxt(out, delimiter=",", skiprows=1)
    assert data.shape[0] == round(STOP / STEP) + 1
    return data[:, [header.index(n) for n in CONTAINER_NAMES]]


def wired_by_hand(ssp: Path, folder: Path, initialization: str) -> np.ndarray:
    """The three FMI 2.0 FMUs of ``ssp`` in FMPy, connected as its SSD says, with their defaults
    (no parameter set), stepped Jacobi-wise (all from t on the values of t) at STEP up to STOP;
    rows of NAMES at t_0 ... t_n. ``initialization``: "container" (one FMU after the other in the
    SSP's order, each on the link values so far, 0 before any) or "propagated" (the
    orchestrator's: every output read in Initialization Mode, then the inputs set in dependency
    order)."""
    units, links = ssp_fmi2_units(ssp, folder)
    assert tuple(units) == ORDER
    value = {}  # (element, output) -> the link's value

    def set_inputs(name):
        slave, refs, _ = units[name]
        for a, output, b, inp in links:
            if b == name:
                slave.setReal([refs[inp]], [value.get((a, output), 0.0)])

    def read(name):
        slave, refs, outputs = units[name]
        value.update(zip(((name, o) for o in outputs), slave.getReal([refs[o] for o in outputs])))

    for slave, _, _ in units.values():
        slave.instantiate()
        slave.setupExperiment(startTime=0.0)
    if initialization == "container":
        for name in ORDER:
            set_inputs(name)
            units[name][0].enterInitializationMode()
            units[name][0].exitInitializationMode()
            read(name)
    else:
        for name in ORDER:
            units[name][0].enterInitializationMode()
            read(name)
        for name in DEPENDENCY_ORDER:
            set_inputs(name)
            units[name][0].exitInitializationMode()
            read(name)
    columns = [tuple(n.split(".")) for n in NAMES]
    rows = [[value[c] for c in columns]]
    for k in range(round(STOP / STEP)):
        for name in ORDER:
            set_inputs(name)
        for name in ORDER:
            units[name][0].doStep(k * STEP, STEP)
        for name in ORDER:
            read(name)
        rows.append([value[c] for c in columns])
    for slave, _, _ in units.values():
        slave.terminate()
        slave.freeInstance()
    return np.array(rows)


@pytest.fixture(scope="module")
def tapmp_run(native_built):
    """`tapmp run` of the paper scenario (first 0.2 s) on the native FMI 2.0 SSP, ordering = jacobi."""
    return orchestrator_rows(native_built["fmi2"]["ssp"], paper_scenario(STOP), NAMES, "jacobi")


def test_the_builder_names_the_loop_it_cuts_at_the_controller(containers):
    for family, (fmu, log) in containers.items():
        assert LOOP_WARNING in log, (family, log)
        assert read_model_description(str(fmu)).fmiVersion == f"{family[3]}.0"


def test_the_fmi2_container_is_the_fmus_wired_by_hand_on_its_conventions_bit_for_bit(
        containers, native_built, tapmp_run, tmp_path, request):
    got = run_container(containers["fmi2"][0], tmp_path)
    hand = wired_by_hand(native_built["fmi2"]["ssp"], tmp_path, "container")
    assert np.array_equal(got, hand), np.abs(got - hand).max(axis=0)
    # its first command is computed on the plant's outputs at 0 (no velocity): ~336 N, not ~15 N
    assert got[0, 3] == pytest.approx(336.0, abs=1.0) and tapmp_run[0, 3] == pytest.approx(15.3, abs=0.1)
    assert np.array_equal(got[1, 3:], tapmp_run[0, 3:])  # the command of t_0 on the propagated values, one step late
    diff = np.abs(got - tapmp_run).max(axis=0)
    assert np.all(diff[:3] <= 5e-6) and diff[3:].max() > 100.0, diff  # m, N; measured 2.9 um, 321 N
    compatibility.record(
        request, tool="FMU Manipulation Toolbox", version=FMT_VERSION, fmi="2.0", interface="CS (container FMU)",
        command="rm -rf results/fmt2 && mkdir -p results/fmt2 && cp build/native/fmi2/TAPMP.ssp results/fmt2/ && "
                "(cd results/fmt2 && ../../.venv/bin/fmucontainer -container TAPMP.ssp:0.0001) && "
                ".venv/bin/fmpy simulate results/fmt2/TAPMP.fmu --stop-time 0.2 --output-interval 0.0001",
        difference=compatibility.difference(
            compatibility.largest(got[:, 3:], tapmp_run[:, 3:]), "N",
            "tapmp run, ordering=jacobi: its first command is computed with the plant's outputs at 0 "
            f"(positions < {math.ceil(diff[:3].max() * 1e6)} um); on that initialization bit for bit"))


def test_the_fmi3_container_is_tapmp_run_gauss_seidel_with_each_command_at_its_sample_instant(
        containers, native_built, tapmp_run, tmp_path, request):
    """The FMI 3.0 controller has Event Mode: the FMI 3.0 container updates it at every t_k on the
    plant's outputs of t_k and hands its command to the plant for the step from t_k, which is
    `tapmp run` with ordering = gauss-seidel (the controller stepped before the plant): the motor
    positions are that run's at every row, bit for bit. The forces are the same doubles one row
    earlier: the container shows at t_k the command computed at t_k, tapmp records it at t_{k+1}
    (the controller's output at the end of the step over which it is held). Against the Jacobi run
    (one more sample of delay) the first command is equal and the rest differ within the force
    chatter (about 20 N); the FMI 2.0 container starts from zeroed links instead (about 336 N)."""
    fmi2, fmi3 = run_container(containers["fmi2"][0], tmp_path), run_container(containers["fmi3"][0], tmp_path)
    gauss_seidel = orchestrator_rows(native_built["fmi3"]["ssp"], paper_scenario(STOP), NAMES, "gauss-seidel")
    assert fmi3.shape == gauss_seidel.shape == tapmp_run.shape
    assert np.array_equal(fmi3[:, :3], gauss_seidel[:, :3])  # positions [m], every row
    assert np.array_equal(fmi3[:-1, 3:], gauss_seidel[1:, 3:]) and np.array_equal(fmi3[0], gauss_seidel[0])
    assert np.abs(fmi3[-1, :3]).min() > 1e-4  # the platform has moved: this compares something
    assert np.array_equal(fmi3[0], tapmp_run[0]) and not np.array_equal(fmi2[0], tapmp_run[0])
    assert 1.0 < float(np.abs(fmi3 - tapmp_run).max()) < 100.0  # the Jacobi run has one more sample of delay
    compatibility.record(
        request, tool="FMU Manipulation Toolbox", version=FMT_VERSION, fmi="3.0", interface="CS (container FMU)",
        command="rm -rf results/fmt3 && mkdir -p results/fmt3 && cp build/native/fmi3/TAPMP.ssp results/fmt3/ && "
                "(cd results/fmt3 && ../../.venv/bin/fmucontainer -container TAPMP.ssp:0.0001 -fmi 3) && "
                ".venv/bin/fmpy simulate results/fmt3/TAPMP.fmu --stop-time 0.2 --output-interval 0.0001",
        difference=compatibility.difference(0.0, "", "tapmp run, ordering=gauss-seidel: positions at every row; "
                                            "each command shown at its sample instant t_k, which tapmp records at "
                                            "t_{k+1}"))


def test_the_fmus_wired_by_hand_with_their_defaults_are_tapmp_run_of_the_paper_scenario(
        native_built, tapmp_run, tmp_path, request):
    """No parameter is set: the FMUs' defaults are the paper's scenario."""
    hand = wired_by_hand(native_built["fmi2"]["ssp"], tmp_path, "propagated")
    assert np.array_equal(hand, tapmp_run), np.abs(hand - tapmp_run).max(axis=0)
    assert np.abs(hand[-1, :3]).min() > 1e-3  # the platform has moved (mm): this compares something
    compatibility.record(
        request, tool="FMPy", version=compatibility.python_version("fmpy"), fmi="2.0", interface="CS",
        command=".venv/bin/python tests/interop/rows/fmpy_wired_by_hand.py build/native/fmi2/TAPMP.ssp",
        difference=compatibility.difference(compatibility.largest(hand, tapmp_run), "",
                                            "tapmp run scenarios/paper_simulation.toml, ordering=jacobi"))
