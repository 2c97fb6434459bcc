"""The master in FMI 3.0 Event Mode: the controller samples at every instant t0 + k T_s whatever
the macro step, and a run on its grid is today's run bit for bit."""

import numpy as np
import pytest

from orchestrator.engine.master import CoSimulation, CoSimulationError, RunOptions
from orchestrator.tool.roles import ROLES
from orchestrator.tool.scenario import load
from tests.support.native_fmi3_runs import FORCES, T_S, fmi3, run  # noqa: F401 (fmi3 is a fixture)
from tests.support.runs import PAPER

pytestmark = pytest.mark.slow  # builds the FMI 3.0 FMUs and runs closed loops


@pytest.mark.parametrize("ordering", ["gauss-seidel", "jacobi"])
def test_event_mode_on_the_sample_grid_is_todays_gauss_seidel_run_bit_for_bit(fmi3, ordering):
    today, columns, _ = run(fmi3["ssp"], T_S, 500, "gauss-seidel", stepper="python")
    events, _, n = run(fmi3["ssp"], T_S, 500, ordering, event_mode=True)
    assert n == 500  # the instant t = 0 and every one up to 0.0499 s; the one at 0.05 s is due next
    # the row at t0 holds the command of the sample at t0 (Event Mode after initialization)
    np.testing.assert_array_equal(events[1:], today[1:])


def test_event_mode_with_a_1_ms_macro_step_samples_as_the_0_1_ms_run(fmi3):
    fine, columns, n_fine = run(fmi3["ssp"], T_S, 500, event_mode=True)
    coarse, _, n_coarse = run(fmi3["ssp"], 1e-3, 50, event_mode=True)
    assert n_coarse == n_fine == 500  # the same samples
    np.testing.assert_allclose(coarse[:, 0], fine[::10, 0], rtol=0, atol=1e-15)  # t0 + k 1 ms, t0 + k 0.1 ms
    idx = [columns.index(c) for c in FORCES]
    # the same forces; the plant's sub-steps between events are t_k+1 - t_k in floating point
    # (9.999999999999996e-05 s where the 0.1 ms run steps 1e-4 s): measured 1.04e-12 relative
    np.testing.assert_allclose(coarse[:, idx], fine[::10, idx], rtol=1e-11, atol=0)
    np.testing.assert_allclose(coarse[1:], fine[10::10], rtol=1e-9, atol=1e-12)


def test_without_event_mode_a_1_ms_macro_step_skips_samples(fmi3):
    """What event mode fixes: the controller (T_s = 0.1 ms) samples only every 1 ms."""
    fine, columns, _ = run(fmi3["ssp"], T_S, 500)
    coarse, _, _ = run(fmi3["ssp"], 1e-3, 50)
    idx = [columns.index(c) for c in FORCES]
    assert np.abs(coarse[1:, idx] - fine[10::10, idx]).max() > 1.0


def test_event_mode_without_an_fmu_with_event_mode_is_refused(native_fmi2_ssp):
    with pytest.raises(CoSimulationError, match=r"event_mode = true is invalid for SSP file .*: no FMU in it has "
                       r"Event Mode: allowed is an SSP with an FMI 3.0 FMU with hasEventMode=\"true\""):
        run(native_fmi2_ssp, T_S, 1, event_mode=True)


def advance(ssp, step, n, stepper):
    """Rows after each of n macro steps in event mode through CoSimulation.advance, and whether the
    compiled core ran."""
    scenario = load(PAPER, ["stop_time=0.05"])
    with CoSimulation(ssp, scenario.parameters(), RunOptions(start_time=0.0, step_size=step, event_mode=True,
                                                             stepper=stepper, roles=ROLES)) as sim:
        rows = np.zeros((n, len(sim.columns)))
        sim.advance(rows)
        return rows, sim._core is not None


def test_event_mode_with_the_compiled_core_gives_the_python_loops_rows(fmi3):
    compiled, core = advance(fmi3["ssp"], 1e-3, 20, "compiled")
    python, _ = advance(fmi3["ssp"], 1e-3, 20, "python")
    assert core
    np.testing.assert_array_equal(compiled, python)


@pytest.fixture(scope="module")
def native_fmi2_ssp(tmp_path_factory):
    from orchestrator.builder.build_native import build_native
    return build_native(tmp_path_factory.mktemp("native2"), families=("fmi2",), log=lambda *_: None,
                        windows=False)["fmi2"]["ssp"]
