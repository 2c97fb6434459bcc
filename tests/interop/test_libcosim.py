"""TAPMP.ssp in libcosim (libcosimpy), the Open Simulation Platform's co-simulation library.

libcosim loads the SSP unchanged, instantiates the three FMUs in-process and steps them
on its worker threads (so the FMUs' GIL handling is exercised). Its fixed-step master is
Jacobi-type: all FMUs step from t to t + h on the inputs of t, then the outputs are
transferred. In Initialization Mode it iterates get/transfer/set N times (N = number of
FMUs) before every FMU leaves initialization, which for this loop (no direct
feedthrough) gives the same initial values as the orchestrator's propagation in
dependency order. Its clock counts integer nanoseconds: t_k = k * 100000 ns / 1e9 and
h_k = t_{k+1} - t_k, which differ from k * 1e-4 in the last bit for ~30 % of k; the
orchestrator's clock = "nanoseconds" reproduces that.
"""

from tests.interop import compatibility
import numpy as np
import pytest
from tests.support.runs import COMMANDS, MOTOR_POSITIONS, orchestrator_rows, paper_scenario
from libcosimpy.CosimEnums import CosimVariableType
from libcosimpy.CosimExecution import CosimExecution
from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
from libcosimpy.CosimObserver import CosimObserver

NAMES = MOTOR_POSITIONS + COMMANDS


def run_libcosim(ssp, scenario, names):
    """libcosim's values of ``names`` after each of the scenario's steps (t_1 ... t_n).

    The step size is given in nanoseconds: libcosimpy converts it with int(), so 1e-4
    would become 0 and the execution would not be created. The scenario's parameters
    are set as initial values (applied by libcosim before Initialization Mode).
    """
    log_output_level(CosimLogLevel.WARNING)
    step_ns = round(scenario.step * 1e9)
    execution = CosimExecution.from_ssp_file(str(ssp), step_size=step_ns)
    observer = CosimObserver.create_last_value()
    execution.add_observer(observer)
    index = {s.name.decode(): s.index for s in execution.slave_infos()}
    variables = {element: {v.name.decode(): v for v in execution.slave_variables(i)}
                 for element, i in index.items()}
    for element, params in scenario.parameters().items():
        for name, value in params.items():
            var = variables[element][name]
            if var.type == CosimVariableType.INTEGER.value:
                assert execution.integer_initial_value(index[element], var.reference, int(value))
            else:
                assert execution.real_initial_value(index[element], var.reference, float(value))
    reads = []  # (slave index, [value references], [positions in a row])
    for element in dict.fromkeys(n.split(".")[0] for n in names):
        cols = [k for k, n in enumerate(names) if n.split(".")[0] == element]
        reads.append((index[element], [variables[element][names[k].split(".")[1]].reference for k in cols],
                      cols))
    rows = np.zeros((scenario.n_steps, len(names)))
    for k in range(scenario.n_steps):
        assert execution.step(1)
        for slave, refs, cols in reads:
            rows[k, cols] = observer.last_real_values(slave, refs)
    assert execution.status().current_time == scenario.n_steps * step_ns
    return rows


@pytest.fixture(scope="module")
def libcosim_run(built):
    scenario = paper_scenario()
    return scenario, run_libcosim(built["ssp"], scenario, NAMES)


def test_libcosim_equals_the_orchestrator_jacobi_ordering_on_every_motor_position(built, libcosim_run):
    scenario, lc = libcosim_run
    ours = orchestrator_rows(built["ssp"], scenario, NAMES, "jacobi")[1:]
    assert lc.shape == ours.shape == (2000, 9)
    diff = np.abs(lc - ours).max(axis=0)
    assert np.all(diff[:6] <= 1e-12), dict(zip(NAMES, diff))  # measured: <= 9e-15 m
    assert np.all(diff[3:6] == 0.0)  # the encoder-quantized positions are identical
    assert np.abs(lc[-1, :3]).min() > 1e-3  # the platform has moved (mm), so this compares something


def test_libcosim_is_bit_identical_with_its_nanosecond_clock(built, libcosim_run, request):
    scenario, lc = libcosim_run
    ours = orchestrator_rows(built["ssp"], scenario, NAMES, "jacobi", clock="nanoseconds")[1:]
    assert np.array_equal(lc, ours)
    # ... while the orchestrator's default clock (t0 + k h) differs in the last bits of the
    # commands: the controller's backward difference amplifies the time rounding.
    exact = orchestrator_rows(built["ssp"], scenario, COMMANDS, "jacobi")[1:]
    assert 0.0 < np.abs(lc[:, 6:] - exact).max() < 1e-9  # N (measured 7e-11 N of ~20 N)
    compatibility.record(
        request, tool="libcosim", version=compatibility.python_version("libcosimpy"), fmi="2.0",
        interface="SSP 1.0, CS", command=compatibility.python_c("from libcosimpy.CosimExecution import CosimExecution; e = CosimExecution.from_ssp_file('build/TAPMP.ssp', step_size=100000); print(e.step(2000))"),
        difference=compatibility.difference(compatibility.largest(lc, ours), "",
                                            "tapmp run, ordering=jacobi, clock=nanoseconds"))


def test_gauss_seidel_differs_from_libcosim_by_the_extra_sample_of_delay(built, libcosim_run):
    """Gauss-Seidel lets the plant integrate the command computed from the measurement at t;
    libcosim (Jacobi) uses the command of t - h. Over 0.2 s of the paper scenario that moves
    the motors by up to ~0.1 um (one encoder count is 0.1 um) and the commands by up to 20 N."""
    scenario, lc = libcosim_run
    gs = orchestrator_rows(built["ssp"], scenario, NAMES, "gauss-seidel")[1:]
    diff = np.abs(lc - gs).max(axis=0)
    assert np.all((diff[:3] > 1e-8) & (diff[:3] < 2e-7)), diff  # measured 8e-8 ... 9.4e-8 m
    assert np.all(diff[6:] > 1.0), diff                          # measured 13 ... 20 N
