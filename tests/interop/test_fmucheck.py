"""The FMI Compliance Checker (../shared/tools/fmuCheck) on the closed-loop container FMU
TAPMP_ClosedLoop.fmu (the three pythonfmu FMUs inside fmpy's container runtime; the FMUs
themselves are checked in tests/fmu/test_native_hosts.py): no warning or error, and the values it
records are fmpy's (fmuCheck writes 17 significant digits)."""

from tests.interop import compatibility
import numpy as np
import pytest
from fmpy import simulate_fmu
from tests.fmu.test_native_hosts import run_fmu_check

from orchestrator.builder.container import CONTAINER

pytestmark = pytest.mark.needs_shared("tools/fmuCheck/fmuCheck.linux64")


def test_fmu_compliance_checker_passes_the_container_fmu_with_fmpys_results(built, tmp_path, request):
    proc, log, csv = run_fmu_check(built[CONTAINER], tmp_path)
    summary = log[log.find("FMU check summary:"):]
    assert proc.returncode == 0, summary or log
    assert "FMU reported:\n\t0 warning(s) and error(s)" in summary, log
    assert "Checker reported:\n\t0 Warning(s)\n\t0 Error(s)" in summary, log
    with open(csv) as f:
        header = [h.strip('"') for h in f.readline().strip().split(",")]
    data = np.loadtxt(csv, delimiter=",", skiprows=1, ndmin=2)
    ours = simulate_fmu(str(built[CONTAINER]), stop_time=0.01, output_interval=1e-4)
    assert data.shape[0] == len(ours) == 101
    assert header == list(ours.dtype.names) and len(header) == 40  # time and the 39 outputs
    assert np.allclose(data[:, 0], ours["time"], rtol=0, atol=1e-15)  # fmuCheck accumulates t += h
    for i, name in enumerate(header[1:], start=1):
        assert np.array_equal(data[:, i], ours[name]), name
    assert np.abs(ours["controller.F1"]).max() > 1.0
    compatibility.record(request, tool="fmuCheck", version=compatibility.readme_version("fmuCheck"), fmi="2.0",
                         interface="CS", command=f"{compatibility.FMUCHECK} -k cs -h 1e-4 -s 0.01 build/{CONTAINER}.fmu",
                         difference=compatibility.difference(0.0, "", "FMPy simulate_fmu"))  # array_equal above
