"""Point-to-point moves: the step, ramp and jerk-limited S-curve profiles of the trajectory (Python
model, native FMI 2.0 and 3.0 FMUs, pythonfmu FMU), the move metrics, and bad input."""

import math
import re

import numpy as np
import pytest
from fmpy import extract, simulate_fmu
from fmpy.fmi1 import FMICallException

from orchestrator.cli import main
from orchestrator.tool import metrics
from orchestrator.tool.metrics import MoveSpec, compute
from orchestrator.tool.scenario import ScenarioError, load
from tapmp.errors import ModelInputError
from tapmp.interface import TRAJECTORY
from tapmp.kinematics import inverse
from tapmp.trajectory import TrajectoryParams, move_duration, move_plan, reference

from tests.support.shared import ROOT

P2P = ROOT / "scenarios" / "point_to_point.toml"
DEG = math.pi / 180.0
OUTPUTS = ["X_d", "Z_d", "B_d", "dX_d", "dZ_d", "dB_d", "ddX_d", "ddZ_d", "ddB_d", "q1_d", "q2_d", "q3_d"]

# S-curves that take every branch of the planner: with a constant-velocity phase, without one but
# at the acceleration limit, without either, moving backwards, with an axis at rest.
MOVES = {
    "cruise": TrajectoryParams(profile=3, X_b=0.01, B_b=5 * DEG, t_move=0.01, v_max_X=0.05, a_max_X=1.0,
                               j_max_X=50.0, v_max_B=0.5, a_max_B=5.0, j_max_B=250.0),
    "no cruise": TrajectoryParams(profile=3, X_a=0.002, X_b=-0.003, Z_b=0.001, t_move=0.02),
    "tiny": TrajectoryParams(profile=3, X_b=2e-6, Z_a=-1e-3, Z_b=-1e-3 + 5e-7, B_b=-1e-4, t_move=0.0),
    "v limit before a": TrajectoryParams(profile=3, X_b=0.02, v_max_X=0.01, a_max_X=5.0, j_max_X=10.0),
}


def limits(tp, kind):
    return np.array([getattr(tp, f"{kind}_max_{a}") for a in "XZB"])


@pytest.mark.parametrize("name", MOVES)
def test_scurve_is_continuous_within_its_limits_and_ends_exactly_at_pose_b(name):
    tp = MOVES[name].validated()
    T = move_duration(tp)
    dt = T / 20000
    t = tp.t_move + np.arange(-100, 20101) * dt
    r = np.array([reference(x, tp) for x in t])
    q, v, a = r[:, 0:3], r[:, 3:6], r[:, 6:9]
    vmax, amax, jmax = limits(tp, "v"), limits(tp, "a"), limits(tp, "j")
    slack = 1.0 + 1e-9
    # continuity: no step larger than the limit of the next derivative allows over dt
    assert np.all(np.abs(np.diff(q, axis=0)) <= vmax * dt * slack + 1e-18)
    assert np.all(np.abs(np.diff(v, axis=0)) <= amax * dt * slack + 1e-18)
    assert np.all(np.abs(np.diff(a, axis=0)) <= jmax * dt * slack + 1e-15)  # jerk within its limit
    assert np.all(np.abs(v) <= vmax * slack) and np.all(np.abs(a) <= amax * slack)
    # at every phase boundary the left and right limits agree
    for p in move_plan(tp):
        for tb in (p.Tj, p.Ta - p.Tj, p.Ta, p.Ta + p.Tv, p.T - p.Ta + p.Tj, p.T - p.Tj):
            left = np.array(reference(tp.t_move + tb * (1 - 1e-12), tp))
            right = np.array(reference(tp.t_move + tb * (1 + 1e-12) + 1e-300, tp))
            assert np.all(np.abs(left - right)[:9] <= 1e-9 * np.concatenate([np.maximum(1e-6, abs(
                np.array([tp.X_b - tp.X_a, tp.Z_b - tp.Z_a, tp.B_b - tp.B_a]))), vmax, amax])), (tb, left, right)
    # velocity and acceleration are the derivatives of position and velocity
    mid = t[100:-100:97]
    h = dt * 1e-3
    for x in mid:
        rp, rm, r0 = (np.array(reference(y, tp)) for y in (x + h, x - h, x))
        assert np.allclose((rp[:3] - rm[:3]) / (2 * h), r0[3:6], rtol=1e-6, atol=1e-9 * vmax.max())
        assert np.allclose((rp[3:6] - rm[3:6]) / (2 * h), r0[6:9], rtol=1e-5, atol=1e-3 * amax.max())
    # exactly pose A before the move and pose B from its end on, at rest
    end = tp.t_move + T
    assert reference(tp.t_move, tp)[:3] == (tp.X_a, tp.Z_a, tp.B_a)
    for x in (end, end + 1e-9, end + 10.0):
        assert reference(x, tp) == (tp.X_b, tp.Z_b, tp.B_b, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    # the axes end together; the slowest one runs at one of its limits
    assert all(p.T == pytest.approx(T, rel=1e-12) for p in move_plan(tp) if p.D)


def test_ramp_and_step_profiles():
    tp = TrajectoryParams(profile=2, X_b=0.01, B_b=0.02, t_move=0.1, v_max_X=0.1, v_max_B=0.1)
    assert move_duration(tp) == pytest.approx(0.2)  # B needs 0.02 / 0.1 = 0.2 s, X follows at 0.05 m/s
    r = reference(0.2, tp)
    assert r[0] == pytest.approx(0.005) and r[2] == pytest.approx(0.01)
    assert r[3:6] == pytest.approx((0.05, 0.0, 0.1)) and r[6:9] == (0.0, 0.0, 0.0)
    assert reference(0.3, tp)[:6] == (0.01, 0.0, 0.02, 0.0, 0.0, 0.0)
    step = tp._replace(profile=1)
    assert move_duration(step) == 0.0
    assert reference(0.1 - 1e-12, step) == (0.0,) * 9
    assert reference(0.1, step) == (0.01, 0.0, 0.02, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


def test_the_circle_is_untouched_by_the_move_parameters():
    base = TrajectoryParams()
    other = base._replace(X_b=0.3, v_max_X=7.0, t_move=1.0)
    for t in (0.0, 0.37, 1.9):
        assert reference(t, other) == reference(t, base)


@pytest.fixture(scope="module")
def native_trajectory(tmp_path_factory):
    from orchestrator.builder.build_native import build_native_fmu
    out = {}
    for family in ("fmi2", "fmi3"):
        folder = tmp_path_factory.mktemp(f"traj_{family}")
        out[family] = build_native_fmu(TRAJECTORY, family, folder, windows=False)
    return out


@pytest.mark.slow
@pytest.mark.parametrize("name", ["cruise", "no cruise", "tiny"])
def test_python_native_fmi2_fmi3_and_pythonfmu_give_the_same_move(name, native_trajectory, built, tmp_path):
    tp = MOVES[name]
    start = {k: v for k, v in tp._asdict().items()}
    stop = tp.t_move + move_duration(tp) + 0.01
    h = 1e-4
    n = int(round(stop / h))
    expected = []
    for k in range(n + 1):
        r = reference(k * h, tp)
        expected.append((*r, *inverse(r[0], r[1], r[2], 0.09)))
    expected = np.array(expected)
    paths = {"fmi2": native_trajectory["fmi2"], "fmi3": native_trajectory["fmi3"], "python": built[TRAJECTORY]}
    for family, path in paths.items():
        res = simulate_fmu(extract(str(path), str(tmp_path / family)), start_time=0.0, stop_time=n * h,
                           step_size=h, output_interval=h,
                           start_values=start, output=OUTPUTS)
        got = np.array([[row[o] for o in OUTPUTS] for row in res])
        assert got.shape == expected.shape, family
        assert np.max(np.abs(got - expected)) <= 1e-12, family
        assert tuple(got[-1, :3]) == (tp.X_b, tp.Z_b, tp.B_b), family  # the end pose exactly


def hand_built_run():
    """A ramp X move from 0 to 10 mm between t = 0.1 s and 0.2 s (0.1 m/s), followed by the
    plant 5 ms late, then a decaying overshoot 2 um exp(-(t - 0.205 s) / 10 ms); Z and B rest."""
    tp = TrajectoryParams(profile=2, X_b=0.01, t_move=0.1, v_max_X=0.1)
    t = np.arange(0, 4001) / 1e4

    def ramp(x):
        return np.clip(0.1 * (x - 0.1), 0.0, 0.01)

    X_d = ramp(t)
    X = ramp(t - 0.005) + np.where(t >= 0.205, 2e-6 * np.exp(-(t - 0.205) / 0.01), 0.0)
    zero = np.zeros_like(t)
    q_d = np.array([inverse(x, 0.0, 0.0, 0.09) for x in X_d])
    q = np.array([inverse(x, 0.0, 0.0, 0.09) for x in X])
    columns = ["time", "trajectory.X_d", "trajectory.Z_d", "trajectory.B_d", "plant.X", "plant.Z", "plant.B",
               *(f"trajectory.q{i}_d" for i in (1, 2, 3)), *(f"plant.q{i}_true" for i in (1, 2, 3))]
    data = np.column_stack([t, X_d, zero, zero, X, zero, zero, q_d, q])
    return tp, columns, data


def test_move_metrics_of_a_hand_built_signal():
    tp, columns, data = hand_built_run()
    spec = MoveSpec(tp, 0.09, (1e-6, 1e-7))
    assert (spec.t0, spec.t1) == (0.1, 0.2)
    m = compute(columns, data, move=spec)["move"]
    X, Z = m["channels"]["X"], m["channels"]["Z"]
    # 10 % and 90 % of 10 mm are passed at 0.115 s and 0.195 s (the 5 ms late ramp)
    assert X["rise_time_s"] == pytest.approx(0.08, abs=1e-12)
    assert X["overshoot"] == pytest.approx(2.0, rel=1e-12)               # um
    assert X["overshoot_percent"] == pytest.approx(2e-6 / 0.01 * 100, rel=1e-12)
    # 2 um exp(-tau / 10 ms) <= 1 um from tau = 10 ms ln 2 = 6.93 ms, i.e. the sample 0.2120 s;
    # <= 0.1 um from 10 ms ln 20 = 29.96 ms, the sample 0.2350 s; measured from the end 0.2 s
    assert X["settling_time_s"]["1e-06"] == pytest.approx(0.0120, abs=1e-12)
    assert X["settling_time_s"]["1e-07"] == pytest.approx(0.0350, abs=1e-12)
    # while moving the error is at most v x 5 ms = 500 um; the whole ramp is at constant velocity:
    # samples 0.1000 ... 0.1050 s have errors 0, 10, ..., 500 um, the 950 after 500 um
    assert X["peak_error_moving"] == pytest.approx(500.0, rel=1e-9)
    assert X["cruise_error_max"] == pytest.approx(500.0, rel=1e-9)
    assert X["cruise_error_mean"] == pytest.approx((1275 * 10.0 + 950 * 500.0) / 1001, rel=1e-9)
    assert Z["rise_time_s"] is None and Z["overshoot"] == 0.0 and Z["settling_time_s"]["1e-07"] == 0.0
    # streamed in blocks of any size: the same numbers
    stats = metrics.ErrorStatistics(columns, 0.0, move=spec)
    for k in range(0, len(data), 777):
        stats.add(data[k:k + 777])
    assert stats.result()["move"] == m
    # cut before the tail has decayed into the 0.1 um band: not settled
    short = compute(columns, data[:2300], move=spec)["move"]["channels"]["X"]["settling_time_s"]
    assert short == {"1e-06": pytest.approx(0.0120, abs=1e-12), "1e-07": None}


def test_point_to_point_scenario_is_stable_and_does_not_saturate(native_built, tmp_path, capsys):
    assert main(["check", str(P2P)]) == 0
    assert "stable: spectral radius 0.996172" in capsys.readouterr().out
    out = tmp_path / "run"
    assert main(["run", str(P2P), "--out", str(out), "--no-progress", "--ssp", str(native_built["fmi2"]["ssp"])]) == 0
    import json
    m = json.loads((out / "metrics.json").read_text())
    assert m["saturation_fraction"] == [0.0, 0.0, 0.0]
    mv = m["move"]
    assert mv["profile"] == "s-curve" and mv["t_end_s"] == pytest.approx(0.3045329, abs=1e-6)
    X = mv["channels"]["X"]
    assert X["distance"] == 0.01 and 0.1 < X["rise_time_s"] < 0.2
    assert 0.0 < X["peak_error_moving"] < 1.0          # um: sub-micrometre while moving
    assert mv["channels"]["B"]["distance"] == pytest.approx(5 * DEG)


@pytest.mark.parametrize("setting,message", [
    ("trajectory.v_max_X=0.0", "trajectory.v_max_X = 0.0 is invalid: allowed is a number in [1e-12, 1e+09]"),
    ("trajectory.a_max_B=-2.0", "trajectory.a_max_B = -2.0 is invalid: allowed is a number in [1e-12, 1e+09]"),
    ("trajectory.j_max_Z=inf", "trajectory.j_max_Z = inf is invalid: allowed is a number in [1e-12, 1e+09]"),
    ("trajectory.j_max_X=nan", "trajectory.j_max_X = nan is invalid: allowed is a number in [1e-12, 1e+09]"),
    ("trajectory.profile=7", "trajectory.profile = 7 is invalid: allowed is 0 (circle and sinusoid), 1 (step), "
                             "2 (ramp) or 3 (S-curve)"),
    ("stop_time=0.3", "stop_time = 0.3 is invalid: the s-curve move from t_move = 0.01 s ends at t = 0.304533 s: "
                      "allowed is a stop_time after the move's end"),
    ("trajectory.v_max_B=0.01", "stop_time = 0.5 is invalid: the s-curve move from t_move = 0.01 s ends at t = "
                                "8.7"),
    ("settling_bands=[0.0]", "settling_bands[0] = 0.0 is invalid: allowed is a finite number > 0"),
    ("settling_bands=[1e-6, -1e-7]", "settling_bands[1] = -1e-07 is invalid: allowed is a finite number > 0"),
    ("settling_bands=[]", "settling_bands = [] is invalid: allowed is a non-empty list of numbers > 0"),
])
def test_bad_move_input_is_one_line_and_exit_2(tmp_path, capsys, setting, message):
    with pytest.raises(ScenarioError, match="^" + re.escape(message)):
        load(P2P, [setting])
    code = main(["run", str(P2P), "--set", setting, "--out", str(tmp_path / "r"), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("error: " + message) and err.count("\n") == 1, err


def test_bad_limits_in_the_model():
    with pytest.raises(ModelInputError, match=r"^v_max_Z = 0.0 is invalid: allowed is a number in \[1e-12, 1e\+09\]$"):
        TrajectoryParams(profile=3, v_max_Z=0.0).validated()
    with pytest.raises(ModelInputError, match=r"^B_b = 1.6 is invalid: allowed is a number in \[-1.5, 1.5\]$"):
        TrajectoryParams(profile=3, B_b=1.6).validated()


@pytest.mark.slow
@pytest.mark.parametrize("family", ["fmi2", "fmi3", "python"])
@pytest.mark.parametrize("name,value", [("v_max_X", 0.0), ("a_max_B", -1.0), ("j_max_Z", math.inf)])
def test_an_fmu_refuses_a_bad_limit_with_an_error_and_a_message(family, name, value, native_trajectory, built,
                                                                tmp_path):
    path = built[TRAJECTORY] if family == "python" else native_trajectory[family]
    messages = []

    def logger(*args):
        messages.append(args[-1].decode() if isinstance(args[-1], bytes) else str(args[-1]))

    with pytest.raises(FMICallException) as err:
        simulate_fmu(extract(str(path), str(tmp_path / family)), start_time=0.0, stop_time=0.01, step_size=1e-4, output_interval=1e-4,
                     start_values={"profile": 3, name: value}, logger=logger, debug_logging=True)
    assert err.value.status >= 3
    assert any(name in m and "invalid" in m for m in messages), messages
