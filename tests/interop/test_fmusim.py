"""fmusim, the C simulator of the Modelica Reference-FMUs (../shared/tools/fmusim), runs every
native FMU of both FMI versions with no warning, as fmpy does.

fmusim reports every problem it sees in a modelDescription and every message an FMU logs; with
``--logging-on --log-level warning`` its log file stays empty for our FMUs. It writes 16
significant digits, so its results equal fmpy's simulate_fmu to the last printed digit.
"""

import subprocess
from pathlib import Path

from tests.interop import compatibility
import numpy as np
import pytest
from tests.support.shared import shared
from fmpy import simulate_fmu

from tapmp.interface import CONTROLLER, FMU_NAMES, PLANT

FMUSIM = "tools/fmusim/bin/fmusim"
pytestmark = pytest.mark.needs_shared(FMUSIM)
# inputs held over the run, so that the plant moves and the controller computes something
START = {PLANT: {"F1": 20.0, "F2": 10.0, "F3": 60.0},
         CONTROLLER: {"X_d": 1e-4, "Z_d": -2e-4, "B_d": 0.001, "q1": 1e-5, "q2": 2e-5, "q3": -1e-5}}


def run_fmusim(fmu: Path, folder: Path, start: dict, interval: float = 1e-4) -> tuple[str, np.ndarray]:
    """fmusim as its README shows it, co-simulation for 0.2 s; (its log file, its CSV result)."""
    args = [str(shared(FMUSIM)), "--interface-type", "cs", "--stop-time", "0.2", "--output-interval", repr(interval),
            "--logging-on", "--log-level", "warning", "--log-file", "log.txt", "--output-file", "out.csv"]
    for name, value in start.items():
        args += ["--start-value", name, repr(value)]
    proc = subprocess.run([*args, str(fmu)], cwd=folder, capture_output=True, text=True, timeout=300)
    log = (folder / "log.txt").read_text() if (folder / "log.txt").exists() else ""
    assert proc.returncode == 0, (proc.stdout, proc.stderr, log)
    return log, np.genfromtxt(folder / "out.csv", delimiter=",", names=True)


@pytest.mark.parametrize("model", FMU_NAMES)
@pytest.mark.parametrize("version", ["fmi2", "fmi3"])
def test_fmusim_runs_each_native_fmu_with_no_warning_as_fmpy_does(native_built, version, model, tmp_path, request):
    fmu = native_built[version][model]
    start = START.get(model, {})
    log, result = run_fmusim(fmu, tmp_path, start)
    assert log == ""  # fmusim writes every warning and error here
    ours = simulate_fmu(str(fmu), stop_time=0.2, output_interval=1e-4, start_values=start)
    assert result.dtype.names == ours.dtype.names and len(result) == len(ours) == 2001
    for name in ours.dtype.names:
        assert np.allclose(result[name], ours[name], rtol=1e-15, atol=0), name
    outputs = [n for n in ours.dtype.names if n != "time"]
    assert max(abs(ours[n][-1]) for n in outputs) > 1e-3  # it computed something
    got, expected = (np.array([r[n] for n in outputs]).T for r in (result, ours))
    starts = "".join(f" --start-value {n} {v!r}" for n, v in start.items())
    compatibility.record(
        request, tool="fmusim", version=compatibility.fmusim_version(shared(FMUSIM)), fmi=version[3] + ".0",
        interface="CS", command=f"{compatibility.FMUSIM} --interface-type cs --stop-time 0.2 --output-interval 1e-4{starts} "
                                f"{compatibility.family_path(version, model)}",
        difference=compatibility.difference(compatibility.relative(got, expected), "relative",
                                            "FMPy simulate_fmu (16 printed digits)"))


@pytest.mark.parametrize("version", ["fmi2", "fmi3"])
def test_fmusims_log_shows_what_the_controller_warns_about(native_built, version, tmp_path):
    """The empty logs above are no blind spot: a host step of two sample periods makes the
    controller warn, and fmusim's log has it."""
    log, _ = run_fmusim(native_built[version][CONTROLLER], tmp_path, START[CONTROLLER], interval=2e-4)
    assert "[Warning]" in log and "T_s" in log, log
