"""The native FMUs (C, no Python at run time) in third-party masters.

* libcosim (libcosimpy) and Ecos (ecospy) load the native FMI 2.0 TAPMP.ssp unchanged and
  give the orchestrator's results on their conventions, exactly as tests/interop/test_libcosim.py
  and tests/interop/test_ecos.py show for the pythonfmu SSP (their run helpers are reused here):
  Jacobi ordering, libcosim's integer-nanosecond clock, Ecos's accumulated clock.
* FMPy's simulate_fmu simulates each native FMI 3.0 FMU on its own.
"""

from tests.interop import compatibility
import numpy as np
import pytest
from tests.support.runs import COMMANDS, MOTOR_POSITIONS, orchestrator_rows, paper_scenario
from fmpy import simulate_fmu
from tests.interop.test_ecos import run_ecos
from tests.interop.test_libcosim import run_libcosim

from tapmp.interface import CONTROLLER, FMU_NAMES, PLANT, TRAJECTORY, VARIABLES

NAMES = MOTOR_POSITIONS + COMMANDS


def test_libcosim_runs_the_native_ssp_bit_identical_to_the_orchestrator_on_its_nanosecond_clock(native_built, request):
    ssp = native_built["fmi2"]["ssp"]
    scenario = paper_scenario()
    lc = run_libcosim(ssp, scenario, NAMES)
    ours = orchestrator_rows(ssp, scenario, NAMES, "jacobi", clock="nanoseconds")[1:]
    assert lc.shape == ours.shape == (2000, 9)
    assert np.array_equal(lc, ours), dict(zip(NAMES, np.abs(lc - ours).max(axis=0)))
    assert np.abs(lc[-1, :3]).min() > 1e-3  # the platform has moved (mm), so this compares something
    # on the orchestrator's exact clock (t0 + k h) only the time rounding differs, as with pythonfmu
    exact = orchestrator_rows(ssp, scenario, NAMES, "jacobi")[1:]
    diff = np.abs(lc - exact).max(axis=0)
    assert np.all(diff[:6] <= 1e-12) and np.all(diff[3:6] == 0.0), dict(zip(NAMES, diff))
    compatibility.record(
        request, tool="libcosim", version=compatibility.python_version("libcosimpy"), fmi="2.0",
        interface="SSP 1.0, CS", command=compatibility.python_c("from libcosimpy.CosimExecution import CosimExecution; e = CosimExecution.from_ssp_file('build/native/fmi2/TAPMP.ssp', step_size=100000); print(e.step(2000))"),
        difference=compatibility.difference(compatibility.largest(lc, ours), "",
                                            "tapmp run, ordering=jacobi, clock=nanoseconds"))


def test_ecos_runs_the_native_ssp_bit_identical_to_the_orchestrator_on_its_accumulated_clock(native_built, request):
    ssp = native_built["fmi2"]["ssp"]
    scenario = paper_scenario()
    ec, times = run_ecos(ssp, scenario, NAMES)
    ours = orchestrator_rows(ssp, scenario, NAMES, "jacobi", clock="accumulated")
    assert ec.shape == ours.shape == (2001, 9)
    assert np.array_equal(ec, ours), dict(zip(NAMES, np.abs(ec - ours).max(axis=0)))
    assert np.array_equal(times, np.cumsum([0.0] + [scenario.step] * scenario.n_steps))
    assert np.abs(ec[-1, :3]).min() > 1e-3
    compatibility.record(
        request, tool="Ecos", version=compatibility.python_version("ecospy"), fmi="2.0", interface="SSP 1.0, CS",
        command=compatibility.python_c("from ecospy import EcosSimulation; s = EcosSimulation(ssp_path='build/native/fmi2/TAPMP.ssp', step_size=1e-4); s.init(0.0); s.step(2000); print(s.get_real('plant::q1_true')); s.terminate(); s.free()"),
        difference=compatibility.difference(compatibility.largest(ec, ours), "",
                                            "tapmp run, ordering=jacobi, clock=accumulated"))


START_VALUES = {PLANT: {"F1": 20.0, "F2": 10.0, "F3": 60.0},
                CONTROLLER: {"X_d": 1e-4, "Z_d": -2e-4, "B_d": 0.001, "q1": 1e-5, "q2": 2e-5, "q3": -1e-5},
                TRAJECTORY: {}}


@pytest.mark.parametrize("model", FMU_NAMES)
def test_fmpy_simulate_fmu_runs_each_native_fmi3_fmu_for_10_ms_with_finite_outputs(native_built, model):
    fmu = native_built["fmi3"][model]
    result = simulate_fmu(str(fmu), stop_time=0.01, start_values=START_VALUES[model])
    outputs = [v.name for v in VARIABLES[model] if v.causality == "output"]
    assert list(result.dtype.names) == ["time", *outputs]
    assert len(result) == 101 and result["time"][-1] == pytest.approx(0.01)  # output interval = its 1e-4 step
    data = np.array([result[n] for n in outputs])
    assert np.all(np.isfinite(data))
    assert np.all(np.ptp(data[:3], axis=1) > 0.0)  # the first three outputs change: it ran
