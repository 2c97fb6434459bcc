"""TAPMP.ssp in Ecos (ecospy), an SSP 1.0 co-simulation engine (needs Debian's libtbb12).

Ecos loads the SSP unchanged. Its fixed-step algorithm is Jacobi-type (every instance
sets its inputs, steps from t to t + h and reads its outputs, in parallel; then the
connections transfer), its time accumulates (t += h) and it applies parameter values
after fmi2EnterInitializationMode, then iterates get/transfer/set N times in
Initialization Mode before every FMU leaves it. So the orchestrator reproduces it with
ordering = "jacobi" and clock = "accumulated" (connections propagated, the default).
"""

import numpy as np
import pytest
from conftest import COMMANDS, MOTOR_POSITIONS, orchestrator_rows, paper_scenario
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


def test_ecos_is_bit_identical_with_the_orchestrator_jacobi_ordering_on_its_clock(built, ecos_run):
    scenario, ec, times = ecos_run
    ours = orchestrator_rows(built["ssp"], scenario, NAMES, "jacobi", clock="accumulated")
    assert ec.shape == ours.shape == (2001, 9)
    assert np.array_equal(ec, ours), dict(zip(NAMES, np.abs(ec - ours).max(axis=0)))
    assert np.abs(ec[-1, :3]).min() > 1e-3  # the platform has moved (mm), so this compares something


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
