"""examples/clocked_fmpy_host.py, the FMPy host that ticks the clocked controller's input clock (FMI 3.0
low-level API: Event Mode, setClock, updateDiscreteStates, Step Mode, doStep), run as docs/other-tools.md
types it, gives `tapmp run` of the paper scenario on TAPMP_Clocked.ssp bit for bit: every output of every
element at all 25,001 ticks."""

import csv
import signal
import subprocess
import sys

import numpy as np
import pytest

from orchestrator.cli import main
from tests.interop import compatibility
from tests.support.native_fmi3_runs import fmi3  # noqa: F401 (a fixture)
from tests.support.runs import PAPER
from tests.support.shared import ROOT

EXAMPLE = ROOT / "examples" / "clocked_fmpy_host.py"


def read(path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return rows[0], np.array([[float(x) for x in r] for r in rows[1:]])


def test_the_fmpy_clocked_host_example_equals_tapmp_run_on_the_clocked_ssp_bit_for_bit(fmi3, tmp_path,  # noqa: F811
                                                                                      request):
    ssp = fmi3["clocked_ssp"]
    done = subprocess.run([sys.executable, str(EXAMPLE), str(ssp), "--stop-time", "2.5", "--out",
                           str(tmp_path / "clocked_fmpy.csv")], capture_output=True, text=True, timeout=900,
                          cwd=ROOT)
    assert done.returncode == 0, done.stderr
    assert done.stdout == f"25000 steps, 25001 ticks of the clock: {tmp_path / 'clocked_fmpy.csv'}\n"
    assert main(["run", str(PAPER), "--ssp", str(ssp), "--set", "event_mode=true", "--out",
                 str(tmp_path / "run")]) == 0
    names, rows = read(tmp_path / "clocked_fmpy.csv")
    expected_names, expected = read(tmp_path / "run" / "results.csv")
    assert names == expected_names  # time and every output of every element, in the same order
    assert rows.shape == expected.shape == (25001, len(names))
    np.testing.assert_array_equal(rows, expected)
    forces = [names.index(f"controller.F{i}") for i in (1, 2, 3)]
    assert len(np.unique(rows[:, forces[0]])) > 1000  # the clock ticks: the command changes
    compatibility.record(
        request, tool="FMPy", version=compatibility.python_version("fmpy"), fmi="3.0", interface="CS, input clock",
        command=".venv/bin/python examples/clocked_fmpy_host.py build/native/fmi3/TAPMP_Clocked.ssp --stop-time 2.5 "
                "--out results/clocked_fmpy.csv",
        difference=compatibility.difference(float(np.abs(rows - expected).max()), "",
                                            "tapmp run, event_mode = true (every output, 25,001 ticks)"))


@pytest.mark.needs_shared("tools/OMSimulator/bin/OMSimulator")
def test_omsimulator_refuses_the_clocked_ssp_and_aborts(fmi3, tmp_path, request):  # noqa: F811
    """OMSimulator 3.0.0 knows no FMI 3.0 clocks: it instantiates the clocked controller without Event Mode,
    which the FMU refuses with its message, and aborts without a result file (docs/other-tools.md)."""
    from tests.support.shared import shared
    program = shared("tools/OMSimulator/bin/OMSimulator")
    done = subprocess.run([str(program), "--stopTime=0.01", str(fmi3["clocked_ssp"])], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)
    log = done.stdout + done.stderr
    assert done.returncode == -signal.SIGABRT, log  # a shell reports exit code 134
    assert "warning: Unknown FMI3 base type for var : sample_clock" in log
    assert ("fmi3InstantiateCoSimulation: eventModeUsed = false is invalid: allowed is true (TAPMP_ControllerClocked "
            "has the input clock sample_clock, which ticks only in Event Mode)") in log
    assert "info:    fmi3Instantiate() failed" in log
    assert not list(tmp_path.glob("*_res.*"))
    compatibility.record(
        request, tool="OMSimulator", version=compatibility.omsimulator_version(program), fmi="3.0",
        interface="SSP 1.0, CS, input clock", command=f'{compatibility.OMSIMULATOR} --stopTime=0.01 build/native/fmi3/TAPMP_Clocked.ssp || echo "exit code $?"',
        result="refused: instantiates the clocked controller without Event Mode (the FMU says eventModeUsed = false "
               "is invalid), then aborts (exit code 134, no result file)",
        difference="not comparable: no run; use TAPMP.ssp")


def test_the_fmpy_clocked_host_refuses_a_missing_ssp_in_one_line(tmp_path):
    done = subprocess.run([sys.executable, str(EXAMPLE), str(tmp_path / "none.ssp")], capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr
    assert done.stderr.startswith(f"error: SSP file {tmp_path / 'none.ssp'} does not exist")
