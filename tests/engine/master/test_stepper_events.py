"""The compiled stepping core in FMI 3.0 Event Mode: the event-mode controller (time events, early
return) and the clocked controller (input clock ticks) stepped from C give the Python loop's rows bit
for bit at any macro step, and every failure inside a macro step the Python loop's error."""

from pathlib import Path

import numpy as np
import pytest

from orchestrator.engine.master import CoSimulation, CoSimulationError, DivergenceError, RunOptions
from orchestrator.engine.master import OutputCheck
from orchestrator.tool.roles import ROLES
from orchestrator.tool.scenario import load

pytestmark = pytest.mark.slow  # builds the FMI 3.0 FMUs and runs closed loops

ROOT = Path(__file__).resolve().parents[3]
PAPER = ROOT / "scenarios" / "paper_simulation.toml"
T_S = 1e-4


@pytest.fixture(scope="module")
def fmi3(tmp_path_factory):
    """The native FMI 3.0 FMUs, their SSP and the SSP with the clocked controller, built for this machine."""
    from orchestrator.builder.build_native import build_native
    return build_native(tmp_path_factory.mktemp("native"), families=("fmi3",), log=lambda *_: None,
                        windows=False)["fmi3"]


def parameters(**controller_and_plant):
    """The paper scenario's parameters, with ``plant_X`` / ``controller_X`` overrides."""
    p = load(PAPER, ["stop_time=0.05"]).parameters()
    for key, value in controller_and_plant.items():
        role, name = key.split("_", 1)
        p[role][name] = value
    return p


def run(ssp, step, n, stepper, ordering="gauss-seidel", blocks=(7,), params=None, check=None, clock="exact"):
    """Rows after each of n macro steps of ``step`` [s] in event mode, advanced in ``blocks`` then the rest,
    with one Python-loop step() between the blocks; the error raised (or None), the rows stored before it,
    the controller's events handled and whether the compiled core ran."""
    rows = None
    with CoSimulation(ssp, params or parameters(), RunOptions(start_time=0.0, step_size=step, ordering=ordering,
                                                              event_mode=True, stepper=stepper, roles=ROLES,
                                                              check=check, clock=clock)) as sim:
        rows = np.full((n, len(sim.columns)), np.nan)
        done, error = 0, None
        try:
            for size in (*blocks, None):
                if size is None:
                    size = n - done
                done += sim.advance(rows[done:done + size])
                if done < n:  # the Python loop takes over for one step, then the core again
                    sim.step()
                    rows[done] = sim.row()
                    done += 1
        except CoSimulationError as err:
            error = err
            done += sim.filled
        return rows[:done], error, sim.units["controller"].n_events, sim._core is not None


@pytest.mark.parametrize("system, step", [("ssp", T_S), ("ssp", 2.5e-4), ("ssp", 1e-3),
                                          ("clocked_ssp", T_S), ("clocked_ssp", 1e-3)])
@pytest.mark.parametrize("ordering", ["gauss-seidel", "jacobi"])
def test_the_compiled_core_in_event_mode_gives_the_python_loops_rows_bit_for_bit(fmi3, system, step, ordering):
    n = round(0.05 / step)
    python, err_p, events_p, core_p = run(fmi3[system], step, n, "python", ordering)
    compiled, err_c, events_c, core_c = run(fmi3[system], step, n, "compiled", ordering)
    assert (core_p, core_c) == (False, True)
    assert err_p is None and err_c is None
    assert events_c == events_p == 500  # every sample instant from t0 up to 0.0499 s, whatever the step
    assert python.shape == compiled.shape == (n, python.shape[1])
    np.testing.assert_array_equal(compiled, python)  # every column, every double


@pytest.mark.parametrize("clock", ["accumulated", "nanoseconds"])
@pytest.mark.parametrize("system, step", [("ssp", 2.5e-4), ("clocked_ssp", 1e-3)])
def test_the_compiled_core_in_event_mode_keeps_the_other_masters_clocks_to_the_bit(fmi3, system, step, clock):
    n = round(0.05 / step)
    python, _, events_p, _ = run(fmi3[system], step, n, "python", clock=clock)
    compiled, _, events_c, core = run(fmi3[system], step, n, "compiled", clock=clock)
    assert core and events_c == events_p == 500
    np.testing.assert_array_equal(compiled, python)


@pytest.mark.parametrize("system", ["ssp", "clocked_ssp"])
@pytest.mark.parametrize("step, n", [(T_S, 400), (1e-3, 40)])
def test_a_failing_update_in_event_handling_gives_the_same_error_and_rows_from_both(fmi3, system, step, n):
    """A controller whose L_1 is half the plant's computes sin(B) > 1 from the measured positions after
    ~36 ms: fmi3UpdateDiscreteStates fails at a sample instant, at t_k with a 0.1 ms step and inside
    the macro step with a 1 ms step."""
    params = parameters(controller_L_1=0.045, plant_B0=0.45)
    python, err_p, _, _ = run(fmi3[system], step, n, "python", params=params)
    compiled, err_c, _, _ = run(fmi3[system], step, n, "compiled", params=params)
    assert type(err_c) is type(err_p) is CoSimulationError
    assert str(err_c) == str(err_p)
    assert str(err_c).startswith("controller: updateDiscreteStates failed at t = 0.036")
    assert "sqrt(3)/(2 L1)*(2 q2 - q1 - q3) = 1.00" in str(err_c) and "is invalid: allowed is |value| < 1" in str(err_c)
    assert (err_c.element, err_c.time) == (err_p.element, err_p.time) == ("controller", err_c.time)
    assert len(compiled) == len(python) > 0
    np.testing.assert_array_equal(compiled, python)


def test_a_failing_doStep_at_an_event_inside_the_macro_step_names_the_sub_step_from_both(fmi3):
    """Gains the plant cannot hold make its state invalid in the first sub-step of a 1 ms macro step,
    which ends at the sample instant 0.1 ms: the error names that sub-step's start, as the Python loop does."""
    params = parameters(plant_force_limit=0.0, **{f"controller_{k}{j}": v for j in "123"
                                                  for k, v in (("K_T", 1e-12), ("Lambda_p", 1e12))})
    python, err_p, _, _ = run(fmi3["ssp"], 1e-3, 5, "python", blocks=(), params=params)
    compiled, err_c, _, _ = run(fmi3["ssp"], 1e-3, 5, "compiled", blocks=(), params=params)
    assert str(err_c) == str(err_p)
    assert str(err_c).startswith("plant: doStep failed at t = 0.0001 s: [ERROR] plant: plant state")
    assert len(compiled) == len(python) == 0


class _Bound(OutputCheck):
    bounds = (("controller.F1", 25.0),)


def test_an_output_breach_at_an_event_inside_the_macro_step_is_the_same_divergence_error(fmi3):
    python, err_p, _, _ = run(fmi3["ssp"], 1e-3, 50, "python", check=_Bound())
    compiled, err_c, _, _ = run(fmi3["ssp"], 1e-3, 50, "compiled", check=_Bound())
    assert type(err_c) is type(err_p) is DivergenceError
    assert str(err_c) == str(err_p)
    assert "controller.F1 = " in str(err_c) and "is outside |controller.F1| <= 25" in str(err_c)
    assert (err_c.element, err_c.time, err_c.signal, err_c.value) == (err_p.element, err_p.time, err_p.signal,
                                                                      err_p.value)
    assert err_c.time == pytest.approx(0.0165, abs=1e-12)  # a sample instant inside the macro step 16 ms to 17 ms
    np.testing.assert_array_equal(compiled, python)


def test_auto_steps_event_mode_in_the_compiled_core(fmi3):
    _, err, events, core = run(fmi3["ssp"], 1e-3, 5, "auto")
    assert err is None and core and events == 50
