"""The controller samples on its own clock t0 + k T_s, whatever the host's steps: every family
(pythonfmu, native FMI 2.0, native FMI 3.0) through fmpy, call by call, and the Python model.

A communication point t is the sample instant k if |t - t0 - k T_s| <= 1e-4 T_s; the controller
samples there once (the time since its previous sample, (k - k_prev) T_s, enters the velocity
estimate and the integral) and holds its outputs at every other communication point.
"""

import math

import numpy as np
import pytest

from tests.support.fmus import call_status
from tests.support.runs import paper_scenario
from tests.support.fmu_host import CONTROLLER_INPUTS, CONTROLLER_OUTPUTS, REF, Host
from tapmp.control import SAMPLE_TOLERANCE, ControllerModel, Gains, sample_index
from tapmp.errors import ModelInputError
from tapmp.interface import CONTROLLER, PLANT, TRAJECTORY
from tapmp.params import PAPER_MODEL, gain_preset

T_S = 1e-4
N = 2000                              # 0.2 s
OMS_END = 0.1999999999999943          # OMSimulator's sum of 2,000 steps of 1e-4 s
SHORT = 0.2 - OMS_END                 # its last step, 5.7e-15 s
FAMILIES = ("python", "fmi2", "fmi3")


@pytest.fixture(scope="module")
def fmus(built, native_built):
    """{family: {model: path}}."""
    return {"python": built, "fmi2": native_built["fmi2"], "fmi3": native_built["fmi3"]}


@pytest.fixture
def host(tmp_path):
    """Factory: host(path) -> Host; every instance is freed after the test."""
    made = []

    def make(path):
        h = Host(path, tmp_path / f"unzip{len(made)}", f"inst{len(made)}")
        made.append(h)
        return h
    yield make
    for h in made:
        h.close()


def _parameters():
    """The paper scenario's parameters by model (the controller's T_s = step = 1e-4 s)."""
    par = paper_scenario(0.2).parameters()
    return {TRAJECTORY: par["trajectory"], CONTROLLER: par["controller"], PLANT: par["plant"]}


def closed_loop(paths, host, n=N, h=T_S, record=None):
    """The closed loop as the tapmp master runs it (Gauss-Seidel: controller, plant, trajectory)
    for n fixed steps t_k = k h; ``record(k, inputs, outputs)`` gets the controller's inputs at
    t_k and its outputs after doStep. Returns the three hosts, in Step Mode at t = n h."""
    par = _parameters()
    traj, ctrl, plant = (host(paths[m]) for m in (TRAJECTORY, CONTROLLER, PLANT))
    for unit, model in ((traj, TRAJECTORY), (ctrl, CONTROLLER), (plant, PLANT)):
        unit.init(par[model])
    for k in range(n):
        t = k * h
        inputs = traj.get(REF) + plant.get(("q1", "q2", "q3", "dq1", "dq2", "dq3"))
        ctrl.set(dict(zip(CONTROLLER_INPUTS, inputs)))
        ctrl.do_step(t, h)
        out = ctrl.get(CONTROLLER_OUTPUTS)
        if record:
            record(k, inputs, out)
        plant.set(dict(zip(("F1", "F2", "F3"), out[:3])))
        plant.do_step(t, h)
        traj.do_step(t, h)
    return traj, ctrl, plant


def test_tolerance_accepts_summed_times_and_rejects_off_grid_points():
    """OMSimulator's summed 0.1999999999999943 s is sample 2000; a point T_s/3 or 2e-4 T_s off the
    grid is none; 1e6 summed steps of 1e-4 s (100 s) stay on the grid."""
    assert sample_index(OMS_END, 0.0, T_S) == 2000
    assert sample_index(0.2 + SHORT, 0.0, T_S) == 2000  # the same instant: never a second sample
    assert sample_index(T_S / 3, 0.0, T_S) is None
    assert sample_index(7 * T_S + 2 * SAMPLE_TOLERANCE * T_S, 0.0, T_S) is None
    assert sample_index(0.35 + 7 * T_S, 0.35, T_S) == 7  # the grid starts at the start time
    t = 0.0
    for k in range(1, 1_000_001):
        t += T_S
    assert sample_index(t, 0.0, T_S) == 1_000_000


@pytest.mark.parametrize("family", FAMILIES)
def test_short_step_after_the_closed_loop(fmus, host, family):
    """0.2 s of closed loop, then doStep(0.2 s, 5.7e-15 s): the controller takes its regular
    sample of t = 0.2 s (bit for bit the command a 1e-4 s step computes there, about 20 N,
    where differentiating over the host's step gave -4e12 N), status OK; one more 5.7e-15 s
    step, and OMSimulator's summed end time, hold every output."""
    _, ctrl, _ = closed_loop(fmus[family], host)
    before = ctrl.get_state()
    ctrl.do_step(0.2, T_S)
    regular = ctrl.get(CONTROLLER_OUTPUTS)
    ctrl.set_state(before)
    ctrl.do_step(0.2, SHORT)               # fmpy raises for any status above Warning
    short = ctrl.get(CONTROLLER_OUTPUTS)
    assert short == regular
    assert max(abs(f) for f in short[:3]) < 1e3, short[:3]
    ctrl.do_step(0.2 + SHORT, SHORT)       # the same sample instant again: held
    assert ctrl.get(CONTROLLER_OUTPUTS) == short
    assert ctrl.warnings() == [] and ctrl.errors() == []


def _partition(rng, k):
    """Communication steps covering [k T_s, (k + 1) T_s]: one step, three of T_s/3, or 2-4
    random pieces."""
    kind = rng.integers(3)
    if kind == 0:
        return [T_S]
    if kind == 1:
        return [T_S / 3] * 3
    w = rng.dirichlet(np.ones(rng.integers(2, 5)))
    return list(w * T_S)


@pytest.mark.parametrize("family", FAMILIES)
def test_random_partitions_give_the_fixed_step_commands(fmus, host, family):
    """The fixed-step closed loop's controller inputs, replayed to a fresh controller under random
    partitions of [0, 0.2 s] (steps of T_s, T_s/3 and random pieces, times summed t += h as
    OMSimulator does): at every sample instant the 12 outputs equal the fixed-step run's within
    1e-12 relative; at every other communication point they hold, although the inputs set
    there are another instant's."""
    inputs, outputs = [], []
    closed_loop(fmus[family], host, record=lambda k, i, o: (inputs.append(i), outputs.append(o)))
    par = _parameters()[CONTROLLER]
    for seed in (1, 2):
        rng = np.random.default_rng(seed)
        ctrl = host(fmus[family][CONTROLLER])
        ctrl.init(par)
        t, held, n_points = 0.0, None, 0
        for k in range(N):
            for j, h in enumerate(_partition(rng, k)):
                ctrl.set(dict(zip(CONTROLLER_INPUTS, inputs[k] if j == 0 else inputs[(k + 1) % N])))
                ctrl.do_step(t, h)
                out = ctrl.get(CONTROLLER_OUTPUTS)
                if j == 0:
                    np.testing.assert_allclose(out, outputs[k], rtol=1e-12, atol=0,
                                               err_msg=f"{family}, seed {seed}, sample {k} at t = {t!r}")
                    held = out
                else:
                    assert out == held, (family, seed, k, t)
                t += h
                n_points += 1
        assert n_points > 3000 and abs(t - 0.2) < 1e-14
        assert ctrl.warnings() == [] and ctrl.errors() == []


@pytest.mark.parametrize("family", FAMILIES)
def test_skipped_sample_instants_warn_once(fmus, host, family):
    """A host stepping 2 T_s samples every other instant: one logged warning (even with
    loggingOn = false) naming the interval used, 2e-4 s; every status OK."""
    ctrl = host(fmus[family][CONTROLLER])
    ctrl.init(_parameters()[CONTROLLER])
    ref = {"X_d": 1e-3, "Z_d": 2e-3, "q1": 1e-4, "q2": -2e-4, "q3": 3e-4}
    for k in range(10):
        ctrl.set({**ref, "q1": 1e-4 * (1 + k)})
        ctrl.do_step(2 * k * T_S, 2 * T_S)
    warnings = ctrl.warnings()
    assert len(warnings) == 1, ctrl.messages
    assert "skip sample instants of T_s = 0.0001 s" in warnings[0]
    assert "0.0002 s (2 T_s) after its previous sample" in warnings[0]
    assert "t = 0.0002 s" in warnings[0]
    assert ctrl.errors() == []


@pytest.mark.parametrize("family", FAMILIES)
def test_steps_off_the_grid_warn_once_and_hold(fmus, host, family):
    """A host stepping 1.5 T_s lands on the grid every other step: at t = 1.5 T_s, past the due
    instant T_s, one warning names the instant missed; the outputs hold until t = 3 T_s, which
    samples (no second warning)."""
    ctrl = host(fmus[family][CONTROLLER])
    ctrl.init(_parameters()[CONTROLLER])
    outs = []
    for k in range(6):
        ctrl.set({"X_d": 1e-3, "q1": 1e-5 * (1 + k), "q2": -2e-5, "q3": 3e-5 * k})
        ctrl.do_step(1.5 * k * T_S, 1.5 * T_S)
        outs.append(ctrl.get(CONTROLLER_OUTPUTS))
    assert outs[1] == outs[0] and outs[2] != outs[1] and outs[3] == outs[2] and outs[4] != outs[3]
    warnings = ctrl.warnings()
    assert len(warnings) == 1, ctrl.messages
    assert warnings[0] == ("the host's communication points skip sample instants of T_s = 0.0001 s: none fell on "
                           "the sample instant t = 0.0001 s; at t = 0.00015 s the controller holds its command "
                           "until a communication point falls on its grid t0 + k T_s")
    assert ctrl.errors() == []


def test_python_model_warns_with_the_same_text():
    """tapmp.control.ControllerModel: the same rule and the same warning as the FMUs."""
    ctl = ControllerModel(PAPER_MODEL, Gains.from_preset(gain_preset("default")), T_s=T_S)
    zero = (0.0,) * 9, (0.0,) * 3, (0.0,) * 3
    assert ctl.communication_point(0.0, 2 * T_S, *zero)[1] is None
    out, warning = ctl.communication_point(2 * T_S, 2 * T_S, *zero)
    assert out is not None and "0.0002 s (2 T_s) after its previous sample" in warning
    assert ctl.communication_point(4 * T_S, T_S / 2, *zero)[1] is None   # once only
    assert ctl.communication_point(4.5 * T_S, T_S / 2, *zero) == (None, None)  # off the grid: held


BAD_T_S = [
    (0.0, "T_s = 0.0 is invalid: allowed is a number in [1e-09, 1000]"),
    (-1e-4, "T_s = -0.0001 is invalid: allowed is a number in [1e-09, 1000]"),
    (1e-12, "T_s = 1e-12 is invalid: allowed is a number in [1e-09, 1000]"),
]


@pytest.mark.parametrize("family", FAMILIES)
@pytest.mark.parametrize("value, message", BAD_T_S)
def test_bad_sample_period_is_an_error(fmus, host, family, value, message):
    """T_s zero, negative or below its range: fmi*EnterInitializationMode returns Error and logs
    the variable, the value and what is allowed."""
    ctrl = host(fmus[family][CONTROLLER])
    ctrl.set({"T_s": value})
    assert call_status(ctrl.enter_initialization) == 3
    assert any(m.startswith(message) for m in ctrl.errors()), ctrl.errors()


@pytest.mark.parametrize("family", FAMILIES)
def test_non_finite_sample_period_is_refused_at_set(fmus, host, family):
    ctrl = host(fmus[family][CONTROLLER])
    assert call_status(lambda: ctrl.set({"T_s": math.inf})) == 3
    assert any(m.startswith("T_s = inf at t = 0 s is invalid: allowed is a finite number") for m in ctrl.errors())


@pytest.mark.parametrize("family", FAMILIES)
@pytest.mark.parametrize("h, text", [(-1e-4, "-0.0001"), (math.nan, "nan"), (math.inf, "inf"), (0.0, "0.0")])
def test_bad_host_step_is_an_error(fmus, host, family, h, text):
    """A host step that is not a finite number > 0: doStep returns Error and says so."""
    ctrl = host(fmus[family][CONTROLLER])
    ctrl.init(_parameters()[CONTROLLER])
    assert call_status(lambda: ctrl.do_step(0.0, h)) == 3
    assert any(m.startswith(f"communicationStepSize = {text} is invalid: allowed is a finite number > 0")
               for m in ctrl.errors()), ctrl.errors()


def test_python_model_bad_input():
    g = Gains.from_preset(gain_preset("default"))
    for value in (0.0, -1e-4, math.nan, math.inf):
        with pytest.raises(ModelInputError, match=r"^T_s = .* is invalid: allowed is a number in \[1e-09, 1000\]"):
            ControllerModel(PAPER_MODEL, g, T_s=value)
    ctl = ControllerModel(PAPER_MODEL, g)
    for h in (-1e-4, math.nan, math.inf, 0.0):
        with pytest.raises(ModelInputError, match=r"^communicationStepSize = .* is invalid: allowed is a finite"):
            ctl.communication_point(0.0, h, (0.0,) * 9, (0.0,) * 3, (0.0,) * 3)


def test_scenario_step_is_the_sample_period(native_built):
    """tapmp sets the controller's T_s to the scenario's step, so a run at another step samples
    once per step: the native closed loop at 50 us equals the Python model's FMI-free loop
    (tapmp.closed_loop.simulate, same parameters) within 1e-12 N, and T_s in [controller] is
    refused."""
    from tests.support.runs import COMMANDS, orchestrator_rows
    from orchestrator.tool.scenario import ScenarioError
    from tapmp.closed_loop import simulate

    sc = paper_scenario(0.02, "step=5e-5")
    assert sc.parameters()["controller"]["T_s"] == 5e-5
    rows = orchestrator_rows(native_built["fmi2"]["ssp"], sc, COMMANDS, ordering="gauss-seidel")
    plant, ctrl, traj = sc.plain_models()
    assert ctrl.T_s == 5e-5
    forces = []
    simulate(plant, ctrl, traj, sc.start_time, sc.n_steps, sc.step, record=lambda t, ref, F, q, qt: forces.append(F))
    assert len(rows) == len(forces) == 401
    np.testing.assert_allclose(rows, np.array(forces), rtol=0, atol=1e-12)
    assert all((rows[k] != rows[k + 1]).all() for k in range(1, 400))  # a new command every 50 us
    with pytest.raises(ScenarioError, match=r"^controller.T_s is set by the scenario's step = 0.0001: allowed is "
                                            r"to set step$"):
        paper_scenario(0.2, "controller.T_s=1e-3")


@pytest.mark.parametrize("family", FAMILIES)
def test_fmu_state_holds_the_sample_clock(fmus, host, family):
    """A state saved between sample instants (serialized and read back) replays bit for bit:
    the next instant samples with the same interval, the skipped-instant warning is not
    repeated."""
    ctrl = host(fmus[family][CONTROLLER])
    ctrl.init(_parameters()[CONTROLLER])
    steps = [(0.0, 2 * T_S), (2 * T_S, T_S / 2), (2.5 * T_S, T_S / 2), (3 * T_S, 2 * T_S), (5 * T_S, T_S)]

    def run(part):
        out = []
        for i, (t, h) in enumerate(part):
            ctrl.set({"q1": 1e-5 * (i + 1), "q2": -2e-5 * i, "X_d": 1e-4 * i})
            ctrl.do_step(t, h)
            out.append(ctrl.get(CONTROLLER_OUTPUTS))
        return out
    run(steps[:3])
    state = ctrl.get_state()
    blob = ctrl.fmu.serializeFMUState(state) if ctrl.fmi3 else ctrl.fmu.serializeFMUstate(state)
    first = run(steps[3:])
    restored = ctrl.fmu.deserializeFMUState(blob) if ctrl.fmi3 else ctrl.fmu.deSerializeFMUstate(blob)
    ctrl.set_state(restored)
    assert run(steps[3:]) == first
    assert len(ctrl.warnings()) == 1  # at t = 2 T_s only, not again after the rollback (3 T_s later)
