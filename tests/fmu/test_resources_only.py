"""The pythonfmu FMUs read nothing outside their resources folder.

FMI 2.0 guarantees an FMU only its ``resources/`` folder at run time, and ``fmpy simulate``
(fmpy.simulate_fmu) unpacks nothing but ``resources/`` and ``binaries/``. Each pythonfmu FMU is
simulated that way and must give the native FMI 2.0 FMU's results bit for bit.
"""

import zipfile

import numpy as np
import pytest
from fmpy import read_model_description, simulate_fmu

from tapmp.interface import CONTROLLER, FMU_NAMES, PLANT

# Inputs held for the stand-alone runs, so the plant and the controller compute something.
START = {PLANT: {"F1": 20.0, "F2": 10.0, "F3": 60.0},
         CONTROLLER: {"X_d": 1e-4, "Z_d": -2e-4, "B_d": 0.001, "q1": 1e-5, "q2": 2e-5, "q3": -1e-5}}


@pytest.mark.parametrize("model", FMU_NAMES)
def test_fmpy_simulate_runs_the_pythonfmu_fmu_unpacking_only_resources_and_binaries(model, built, native_built):
    with zipfile.ZipFile(built[model]) as z:
        assert "modelDescription.xml" in z.namelist()  # present in the archive, yet never read at run time
    start = START.get(model, {})
    ours = simulate_fmu(str(built[model]), stop_time=0.01, output_interval=1e-4, start_values=start)
    native = simulate_fmu(str(native_built["fmi2"][model]), stop_time=0.01, output_interval=1e-4,
                          start_values=start)
    assert len(ours) == len(native) == 101
    assert ours.dtype.names == native.dtype.names
    for name in ours.dtype.names:
        assert np.array_equal(ours[name], native[name]), name
    outputs = [n for n in ours.dtype.names if n != "time"]
    assert max(np.abs(ours[n][-1]) for n in outputs) > 1e-6  # it has computed something


@pytest.mark.parametrize("model", FMU_NAMES)
def test_the_guid_the_binary_checks_is_the_one_of_the_model_description(model, built):
    with zipfile.ZipFile(built[model]) as z:
        copy = z.read("resources/guid.txt").decode()
    assert copy == read_model_description(str(built[model])).guid != ""


@pytest.mark.parametrize("model", FMU_NAMES)
def test_the_fmpy_simulate_command_runs_the_pythonfmu_fmu(model, built, tmp_path):
    import subprocess
    import sys
    proc = subprocess.run([sys.executable, "-m", "fmpy.cli", "simulate", str(built[model]), "--stop-time", "0.01",
                           "--output-interval", "1e-4", "--output-file", "out.csv"], cwd=tmp_path, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    data = np.loadtxt(tmp_path / "out.csv", delimiter=",", skiprows=1)
    assert data.shape[0] == 101 and np.all(np.isfinite(data))
