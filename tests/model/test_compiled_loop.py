"""The compiled FMI-free loop (tapmp.closed_loop.run, tapmp/c/tapmp_loop.c) against the readable
Python loop (tapmp.closed_loop.simulate): the same doubles, bit for bit, at every communication
point, on every law, ordering and controller clock, with the plant's non-idealities, at the
paper's gains at 1 us; the same error at the same step, and the models left in the same state."""

import numpy as np
import pytest

from orchestrator.paper.paper_gains import paper_scenario
from tapmp.closed_loop import COLUMNS, run, simulate
from tapmp.control import APDDC, AW_BACK, AW_CLAMP, PIDDC, SCDC, VELOCITY_DIFFERENCE, VELOCITY_INPUT, ControllerModel, Gains
from tapmp.errors import KinematicDomainError, ModelInputError
from tapmp.params import GAIN_PRESETS, PAPER_MODEL
from tapmp.plant import PlantConfig, PlantModel
from tapmp.trajectory import TrajectoryParams

H = 1e-4
# the columns simulate's record gets, in the order of COLUMNS without q_d (run's own column)
SIMULATE_COLUMNS = [i for i, c in enumerate(COLUMNS) if not c.startswith("q_d")]


def models(law=SCDC, velocity_source=VELOCITY_DIFFERENCE, T_s=H, t0=0.0, force_limit=0.0,
           config=PlantConfig(), traj=TrajectoryParams(), gains="default"):
    """A fresh (plant, controller, trajectory) of the paper's model."""
    plant = PlantModel(PAPER_MODEL, config)
    ctrl = ControllerModel(PAPER_MODEL, Gains.from_preset(GAIN_PRESETS[gains]), law, velocity_source,
                           force_limit, T_s=T_s, t0=t0)
    return plant, ctrl, traj


def python_rows(make, t0, n, h, ordering):
    """simulate's communication points as rows, and the models after it (or the error it raised)."""
    plant, ctrl, traj = make()
    rows = []
    error = None
    try:
        simulate(plant, ctrl, traj, t0, n, h, ordering,
                 lambda t, ref, F, q, q_true: rows.append((t, *ref, *F, *q, *q_true, *plant.state)))
    except ModelInputError as err:
        error = err
    return np.array(rows), error, (plant, ctrl)


def compiled_rows(make, t0, n, h, ordering, block=1000):
    """run's communication points (without q_d), and the models after it (or the error it raised)."""
    plant, ctrl, traj = make()
    blocks = []
    error = None
    try:
        run(plant, ctrl, traj, t0, n, h, ordering, blocks.append, block=block)
    except ModelInputError as err:
        error = err
    return np.concatenate(blocks)[:, SIMULATE_COLUMNS], error, (plant, ctrl)


def state(plant, ctrl):
    """Everything either loop leaves in the models."""
    return (plant.state, plant.sample, ctrl.integral, ctrl.q_prev, ctrl.k_last, ctrl.warned)


def assert_same(make, t0, n, h, ordering, block=1000):
    a, err_a, models_a = python_rows(make, t0, n, h, ordering)
    b, err_b, models_b = compiled_rows(make, t0, n, h, ordering, block)
    assert a.shape == b.shape
    assert np.array_equal(a.view(np.int64), b.view(np.int64)), "not the same doubles"
    assert repr(err_a) == repr(err_b)
    assert repr(state(*models_a)) == repr(state(*models_b))
    return a, err_a


NOISY = PlantConfig(noise_rms=5e-8, noise_seed=3, cogging_amplitude=4.0, attraction_force=20.0,
                    disturbance_force1=30.0, disturbance_time=0.02, substeps=2)


@pytest.mark.parametrize("ordering", ["gauss-seidel", "jacobi"])
@pytest.mark.parametrize("law", [SCDC, APDDC, PIDDC])
@pytest.mark.parametrize("velocity_source", [VELOCITY_DIFFERENCE, VELOCITY_INPUT])
def test_compiled_loop_equals_python_loop_bit_for_bit_on_every_law_and_ordering(law, ordering, velocity_source):
    """Every law x ordering x velocity source, with noise, cogging, attraction, a force step,
    two RK4 substeps and a command limit: 500 steps, the same doubles at every point."""
    assert_same(lambda: models(law, velocity_source, force_limit=300.0, config=NOISY), 0.0, 500, H, ordering,
                block=64)


@pytest.mark.parametrize("anti_windup", [AW_CLAMP, AW_BACK])
@pytest.mark.parametrize("law", ["sc-dc", "pid-dc"])
def test_compiled_loop_equals_python_loop_with_the_anti_windup_at_the_force_limit(law, anti_windup):
    """The step of scenarios/windup_step.toml (at the 600 N limit for tens of ms, PID-DC with ki_c = ki_d):
    1,000 steps, the same doubles at every point."""
    from orchestrator.tool.scenario import load
    from tests.support.shared import ROOT
    sc = load(ROOT / "scenarios" / "windup_step.toml", [f'law="{law}"', f"controller.anti_windup={anti_windup}",
                                                        "controller.ki_c=48600.0"])
    assert_same(sc.plain_models, sc.start_time, 1000, sc.step, sc.ordering, block=64)


@pytest.mark.parametrize("T_s, h, t0", [(3 * H, H, 0.0),     # holds between samples
                                         (2.5 * H, H, 0.0),   # instants off the host's grid: skipped
                                         (H, 2 * H, 0.0),     # the host steps over instants
                                         (H, H, 0.37)])       # a start time that is not 0
@pytest.mark.parametrize("ordering", ["gauss-seidel", "jacobi"])
def test_compiled_loop_equals_python_loop_on_every_clock(T_s, h, t0, ordering):
    """The controller's own clock (sample, hold, skipped instants and their one warning) runs
    the same in C: the same doubles and the same clock state after 400 steps."""
    a, _ = assert_same(lambda: models(PIDDC, T_s=T_s, t0=t0), t0, 400, h, ordering, block=37)
    assert len(a) == 401


@pytest.mark.parametrize("law", ["sc-dc", "apd-dc"])
def test_compiled_loop_equals_python_loop_at_the_paper_gains_at_1_us(law):
    """The paper's simulation gains (Eq. 40-41, reading A) at 1 us for 0.01 s: 10,000 steps."""
    sc = paper_scenario("Eq. 40-41", law, 1e-6, 0.01)
    a, err = assert_same(sc.plain_models, sc.start_time, sc.n_steps, sc.step, sc.ordering, block=4096)
    assert err is None and len(a) == sc.n_steps + 1 == 10001


@pytest.mark.parametrize("ordering", ["gauss-seidel", "jacobi"])
def test_a_diverging_loop_stops_with_the_same_error_at_the_same_step(ordering):
    """A platform spinning at 1000 rad/s under a command limited to 1 N leaves |B| < pi/2 after
    about 20 steps: both loops raise KinematicDomainError at the same time with the same text,
    after the same rows, and leave the models in the same state (blocks of 8 rows: the error
    falls inside the third block)."""
    def spinning():
        plant = PlantModel(PAPER_MODEL, PlantConfig(force_limit=0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 1000.0))
        return plant, models(APDDC, force_limit=1.0)[1], TrajectoryParams()

    a, err = assert_same(spinning, 0.0, 3000, H, ordering, block=8)
    assert isinstance(err, KinematicDomainError) and err.time == a[-1, 0] + H
    assert 16 < len(a) < 3001


def test_rows_hold_the_reference_s_q_d():
    """run's q_d columns are the inverse kinematics of its reference columns (q_d = IK(x_d))."""
    from tapmp.kinematics import inverse
    plant, ctrl, traj = models()
    blocks = []
    run(plant, ctrl, traj, 0.0, 50, H, record_rows=blocks.append)
    rows = np.concatenate(blocks)
    for row in rows[::7]:
        assert tuple(row[10:13]) == inverse(row[1], row[2], row[3], PAPER_MODEL.L_1)
