"""FMU Manipulation Toolbox's FMI 3.0 container of plant + clocked controller + trajectory
(native/fmi3/TAPMP_Clocked.ssp), run by FMPy: the container does not schedule a periodic input clock.

Its builder (fmu-manipulation-toolbox 2.0) feeds an input clock only from another FMU's output clock, or
from the importer for a countdown clock of an LS-BUS FMU; the controller's periodic clock sample_clock is
neither, so the builder reports it unconnected and cannot expose the outputs it clocks (F1..F3): the
plant's force inputs are linked to nothing and stay 0. At run time the container instantiates the
controller with Event Mode but never activates its clock, so the controller never samples and says so
once. Pinned here; the clocked controller runs in the tapmp master and in a C host instead
(tests/engine/master/test_master_clocks.py, tests/fmu/test_controller_clocked_c_host.py)."""

import shutil
import subprocess
import sys
from pathlib import Path

from tests.interop import compatibility
import numpy as np
import pytest

pytestmark = pytest.mark.slow  # builds the FMI 3.0 FMUs, the container, and runs FMPy as a child process

STEP = 1e-4
STOP = 0.01
FMT_VERSION = compatibility.python_version("fmu-manipulation-toolbox")
FORCES = tuple(f"tapmp_controllerclocked.F{i}" for i in (1, 2, 3))  # the container's locals of the links


@pytest.fixture(scope="module")
def container(tmp_path_factory):
    """`fmucontainer -container TAPMP_Clocked.ssp:0.0001 -fmi 3`: (the container FMU, the builder's log)."""
    from orchestrator.builder.build_native import build_native
    fmi3 = build_native(tmp_path_factory.mktemp("native"), families=("fmi3",), log=lambda *_: None,
                        windows=False)["fmi3"]
    folder = tmp_path_factory.mktemp("fmt_clocked")
    shutil.copy(fmi3["clocked_ssp"], folder / "TAPMP_Clocked.ssp")
    program = Path(sys.executable).with_name("fmucontainer")
    proc = subprocess.run([str(program), "-container", "TAPMP_Clocked.ssp:0.0001", "-fmi", "3"], cwd=folder,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return folder / "TAPMP_Clocked.fmu", proc.stdout + proc.stderr


def test_the_container_builder_cannot_feed_the_periodic_input_clock_nor_expose_its_outputs(container):
    _, log = container
    errors = [line.split("|", 1)[1].strip() for line in log.splitlines() if line.startswith("ERROR")]
    assert errors == ["Input 'Port TAPMP_ControllerClocked.fmu/sample_clock' is not connected",
                      *(f"Cannot expose clocked output: Port TAPMP_ControllerClocked.fmu/F{i}" for i in (1, 2, 3))]


def test_fmpy_runs_the_container_with_the_clock_never_ticking_and_no_forces(container, tmp_path, request):
    fmu, _ = container
    out = tmp_path / "out.csv"
    fmpy = Path(sys.executable).with_name("fmpy")
    proc = subprocess.run([str(fmpy), "simulate", str(fmu), "--stop-time", repr(STOP), "--output-interval",
                           repr(STEP), "--output-variables", *FORCES, "--output-file", str(out)],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    warnings = [line for line in (proc.stdout + proc.stderr).splitlines() if "sample_clock" in line]
    assert warnings == [
        "[WARNING] TAPMP_ControllerClocked.fmu: the input clock sample_clock (interval T_s = 0.0001 s) did not "
        "tick at t = 0.0 s: the controller holds its command until the host activates the clock (fmi3SetClock "
        "in Event Mode, then fmi3UpdateDiscreteStates) at an instant t0 + k T_s; doStep reached t = 0.0001 s"]
    data = np.loadtxt(out, delimiter=",", skiprows=1)
    assert data.shape == (round(STOP / STEP) + 1, 1 + len(FORCES))
    assert np.all(data[:, 1:] == 0.0)  # the links of the forces are never written
    compatibility.record(
        request, tool="FMU Manipulation Toolbox", version=FMT_VERSION, fmi="3.0",
        interface="CS (container FMU), input clock",
        command="rm -rf results/fmt3_clocked && mkdir -p results/fmt3_clocked && cp build/native/fmi3/TAPMP_Clocked.ssp results/fmt3_clocked/ && "
                "(cd results/fmt3_clocked && ../../.venv/bin/fmucontainer -container TAPMP_Clocked.ssp:0.0001 -fmi 3) && "
                ".venv/bin/fmpy simulate results/fmt3_clocked/TAPMP_Clocked.fmu --stop-time 0.01 --output-interval 0.0001",
        result="builds and runs, but never ticks the periodic input clock and cannot pass on the clocked forces "
               "(builder: 'Cannot expose clocked output')",
        difference="not comparable: forces 0 throughout, the controller never samples")
