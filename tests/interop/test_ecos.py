"""TAPMP.ssp in Ecos (ecospy), an SSP 1.0 co-simulation engine (needs Debian's libtbb12).

Ecos loads the SSP unchanged. Its fixed-step algorithm is Jacobi-type (every instance
sets its inputs, steps from t to t + h and reads its outputs, in parallel; then the
connections transfer), its time accumulates (t += h) and it applies parameter values
after fmi2EnterInitializationMode, then iterates get/transfer/set N times in
Initialization Mode before every FMU leaves it. So the orchestrator reproduces it with
ordering = "jacobi" and clock = "accumulated" (connections propagated, the default).
"""

import os
from pathlib import Path

from tests.interop import compatibility
import numpy as np
import pytest
from tests.support.runs import COMMANDS, MOTOR_POSITIONS, orchestrator_rows, paper_scenario
from ecospy import EcosSimulation

NAMES = MOTOR_POSITIONS + COMMANDS
INTEGER_PARAMETERS = {"law", "velocity_source", "substeps"}


def run_ecos(ssp, scenario, names):
    """Ecos's values of ``names`` at t_0 ... t_n and its times.

    The scenario's parameters are set before init(); Ecos applies them in
    Initialization Mode. Ecos names variables "element::variable".
    """
    sim = EcosSimulation(ssp_path=str(ssp), step_size=scenario.step)
    try:
        for element, params in scenario.parameters().items():
            for name, value in params.items():
                if name in INTEGER_PARAMETERS:
                    sim.set_integer(f"{element}::{name}", int(value))
                else:
                    sim.set_real(f"{element}::{name}", float(value))
        assert sim.init(scenario.start_time)
        ids = [n.replace(".", "::", 1) for n in names]
        rows, times = [[sim.get_real(i) for i in ids]], [sim.get_time()]
        for _ in range(scenario.n_steps):
            sim.step()
            rows.append([sim.get_real(i) for i in ids])
            times.append(sim.get_time())
        sim.terminate()
    finally:
        sim.free()
    return np.array(rows), np.array(times)


@pytest.fixture(scope="module")
def ecos_run(built):
    scenario = paper_scenario()
    return (scenario, *run_ecos(built["ssp"], scenario, NAMES))


def test_ecos_is_bit_identical_with_the_orchestrator_jacobi_ordering_on_its_clock(built, ecos_run, request):
    scenario, ec, times = ecos_run
    ours = orchestrator_rows(built["ssp"], scenario, NAMES, "jacobi", clock="accumulated")
    assert ec.shape == ours.shape == (2001, 9)
    assert np.array_equal(ec, ours), dict(zip(NAMES, np.abs(ec - ours).max(axis=0)))
    assert np.abs(ec[-1, :3]).min() > 1e-3  # the platform has moved (mm), so this compares something
    compatibility.record(
        request, tool="Ecos", version=compatibility.python_version("ecospy"), fmi="2.0", interface="SSP 1.0, CS",
        command=compatibility.python_c("from ecospy import EcosSimulation; s = EcosSimulation(ssp_path='build/TAPMP.ssp', step_size=1e-4); s.init(0.0); s.step(2000); print(s.get_real('plant::q1_true')); s.terminate(); s.free()"),
        difference=compatibility.difference(compatibility.largest(ec, ours), "",
                                            "tapmp run, ordering=jacobi, clock=accumulated"))


def test_ecos_time_accumulates(ecos_run):
    scenario, _, times = ecos_run
    acc = np.cumsum([0.0] + [scenario.step] * scenario.n_steps)  # t += h, left to right
    assert np.array_equal(times, acc)
    assert times[-1] != 0.2 and times[-1] == pytest.approx(0.2, abs=1e-13)


def test_ecos_equals_the_default_orchestrator_to_the_rounding_of_time(built, ecos_run):
    """On the orchestrator's exact clock (t0 + k h) the only difference is the time rounding,
    which the controller's backward difference amplifies to ~1e-12 m within 0.2 s; the
    encoder-quantized positions, which the controller sees, stay identical."""
    scenario, ec, _ = ecos_run
    ours = orchestrator_rows(built["ssp"], scenario, NAMES, "jacobi")
    diff = np.abs(ec - ours).max(axis=0)
    assert np.all(diff[3:6] == 0.0)
    assert np.all(diff[:3] < 1e-11), diff  # m; measured 5e-13 ... 1.4e-12


def test_ecos_differs_from_gauss_seidel_by_the_extra_sample_of_delay(built, ecos_run):
    scenario, ec, _ = ecos_run
    gs = orchestrator_rows(built["ssp"], scenario, NAMES, "gauss-seidel", clock="accumulated")
    diff = np.abs(ec - gs).max(axis=0)
    assert np.all((diff[:3] > 1e-8) & (diff[:3] < 2e-7)), diff  # m; measured 8e-8 ... 9.4e-8


def test_ecos_executable_runs_the_ssp_in_a_process_without_python(built, tmp_path):
    """Ecos's own `ecos simulate` (C++, no Python in the process): the FMUs start the
    interpreter named in their python-env.txt. Its CSV has 6 decimals, so the commands
    (tens of N) are compared to 5e-7 N, which tells the orderings apart (GS: 20 N)."""
    import shutil
    import stat
    import subprocess

    import ecospy
    binaries = Path(ecospy.__file__).parent / "binaries"
    exe = tmp_path / "ecos"  # the wheel installs it without the executable bit
    shutil.copy(binaries / "ecos", exe)
    exe.chmod(exe.stat().st_mode | stat.S_IXUSR)
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTHON")}
    env["LD_LIBRARY_PATH"] = str(binaries)
    proc = subprocess.run([str(exe), "simulate", "--path", str(built["ssp"]), "--stepSize", "1e-4",
                           "--stopTime", "0.2", "--noParallel"], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    with open(tmp_path / "TAPMP.csv") as f:
        header = [h.strip().split("[")[0].replace("::", ".") for h in f.readline().split(",")]
    data = np.loadtxt(tmp_path / "TAPMP.csv", delimiter=",", skiprows=1)
    names = ("controller.F1", "controller.F2", "controller.F3")
    assert data.shape[0] == 2001 and data[-1, header.index("time")] == pytest.approx(0.2)  # t_0 ... t_2000
    got = data[:, [header.index(n) for n in names]]
    default = paper_scenario().with_changes(start_on_trajectory=False, trajectory={}, plant={},
                                            controller={})
    ours = orchestrator_rows(built["ssp"], default, names, "jacobi", clock="accumulated")
    assert np.abs(got - ours).max() <= 5.1e-7, np.abs(got - ours).max()
    assert np.abs(ours).max() > 10.0  # N: the commands of the paper's run (measured 28 N), so this compares something
    gs = orchestrator_rows(built["ssp"], default, names, "gauss-seidel", clock="accumulated")
    assert np.abs(got - gs).max() > 1.0
