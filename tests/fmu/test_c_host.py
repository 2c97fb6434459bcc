"""The FMUs in a host process without Python: a small C program (tests/fmu/c_host/fmi2_host.c),
compiled here by the project's toolchain (zig cc), loads the FMU binary, steps it and must match FMPy exactly."""

import os
import subprocess
from pathlib import Path

import pytest

from tapmp.interface import CONTROLLER, PLANT
from tests.support.c_hosts import compile_c_host, unzip_fmu

pytestmark = pytest.mark.slow  # compiles a C host and runs the FMU in it

HOST_SOURCE = Path(__file__).parent / "c_host" / "fmi2_host.c"
RUNS = 20  # an exit-time crash showed up in about half of the runs with pythonfmu's binary


@pytest.fixture(scope="module")
def host(tmp_path_factory):
    return compile_c_host(HOST_SOURCE, tmp_path_factory.mktemp("c_host") / "fmi2_host")


def run_host(host, fmu_dir, model, steps, inputs, outputs, env=None):
    """Run the C host with a clean environment (no PYTHONPATH, no virtualenv)."""
    args = [str(host), str(fmu_dir), model, str(steps), "1e-4",
            *(f"{vr}={value!r}" for vr, value in inputs.items()), "--", *map(str, outputs)]
    return subprocess.run(args, capture_output=True, text=True, timeout=120,
                          env={"PATH": os.environ["PATH"], **(env or {})})


def test_plant_fmu_steps_in_a_c_host_like_in_fmpy_and_exits_cleanly_every_time(built, load_fmu, host, tmp_path):
    fmu = load_fmu(built[PLANT])
    forces = {"F1": 5.0, "F2": 20.0, "F3": -3.0}
    outs = ("q1", "q1_true", "q2_true", "q3_true", "X", "Z", "B", "dB")
    fmu.init(**forces)
    for k in range(100):
        fmu.slave.doStep(k * 1e-4, 1e-4)
    expected = fmu.get(*outs)
    fmu_dir = unzip_fmu(built[PLANT], tmp_path / "plant")
    inputs = {fmu.vr[n]: v for n, v in forces.items()}
    codes = []
    for _ in range(RUNS):
        proc = run_host(host, fmu_dir, PLANT, 100, inputs, [fmu.vr[n] for n in outs])
        codes.append(proc.returncode)
        if proc.returncode == 0:
            assert [float(x) for x in proc.stdout.split()] == expected
    assert codes == [0] * RUNS, proc.stderr


def test_controller_fmu_steps_in_a_c_host_like_in_fmpy(built, load_fmu, host, tmp_path):
    fmu = load_fmu(built[CONTROLLER])
    inputs = {"X_d": 1e-4, "Z_d": -2e-4, "B_d": 0.001, "dX_d": 0.02, "q1": 1e-5, "q2": 2e-5, "q3": -1e-5}
    outs = ("F1", "F2", "F3", "u1", "e1", "es2")
    fmu.init(**inputs)
    for k in range(100):
        fmu.slave.doStep(k * 1e-4, 1e-4)
    expected = fmu.get(*outs)
    proc = run_host(host, unzip_fmu(built[CONTROLLER], tmp_path / "ctrl"), CONTROLLER, 100,
                    {fmu.vr[n]: v for n, v in inputs.items()}, [fmu.vr[n] for n in outs])
    assert proc.returncode == 0, proc.stderr
    assert [float(x) for x in proc.stdout.split()] == expected


def test_c_host_without_a_usable_libpython_gets_a_clear_instantiate_error(built, host, tmp_path):
    fmu_dir = unzip_fmu(built[PLANT], tmp_path / "plant")
    proc = run_host(host, fmu_dir, PLANT, 1, {}, [], env={"TAPMP_LIBPYTHON": "/nonexistent/libpython3.so"})
    assert proc.returncode == 1
    assert "cannot load libpython '/nonexistent/libpython3.so' (set TAPMP_LIBPYTHON)" in proc.stderr
    assert "fmi2Instantiate failed" in proc.stderr
