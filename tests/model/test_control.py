"""Control laws: SC-DC (Eq. 15-26), APD-DC (Eq. 38-39), PID-DC (modal PID) and the discrete controller."""

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

import numpy as np

from tapmp.control import APDDC, PIDDC, SCDC, ControllerModel, Gains, ModalGains, sync_deviation
from tests.support.control_reference import apd_command, feedforward, pid_command, scdc_command, sync_errors
from tapmp.errors import ModelInputError
from tapmp.kinematics import inverse, joint_velocity
from tapmp.params import DEFAULT_MODAL_GAINS, PAPER_MODEL, gain_preset, scdc_modal_image
from tapmp.plant import IDEAL, PlantModel
from tapmp.trajectory import TrajectoryParams, reference

G = Gains((2.0, 3.0, 4.0), (0.5, 0.6, 0.7), (10.0, 20.0, 30.0), (100.0, 200.0, 300.0), (1e-4, 2e-4, 5e-5))
errs = st.floats(-1e-3, 1e-3)


@given(errs, errs, errs)
def test_synchronization_error_and_its_deviation_sum_to_zero(e1, e2, e3):
    es = sync_errors(e1, e2, e3)
    assert sum(es) == pytest.approx(0.0, abs=1e-18)
    assert sum(sync_deviation(*es)) == pytest.approx(0.0, abs=1e-18)


def test_sync_errors_and_deviation_by_hand():
    # e = (3, 1, -2) um: es = (2, 3, -5) um (Eq. 18); c = (2+5, 3-2, -5-3) = (7, 1, -8) um (Eq. 21)
    es = sync_errors(3e-6, 1e-6, -2e-6)
    assert es == pytest.approx((2e-6, 3e-6, -5e-6))
    assert sync_deviation(*es) == pytest.approx((7e-6, 1e-6, -8e-6))


def test_scdc_command_by_hand():
    e, de, c, integ, u_d = (1e-6, 2e-6, 3e-6), (1e-3, 0.0, -1e-3), (7e-6, 1e-6, -8e-6), (1e-7, 0.0, 2e-7), (10.0, 20.0, 30.0)
    # motor 1: e_c = 1e-6 + 10*1e-7 = 2e-6; de_c = 1e-3 + 10*7e-6 = 1.07e-3; n = 1.07e-3 + 100*2e-6 = 1.27e-3
    #          u = 1e-4*10 + 0.5*1.27e-3 + 2*7e-6 = 1e-3 + 6.35e-4 + 1.4e-5 = 1.649e-3
    # motor 2: e_c = 2e-6; de_c = 0 + 20*1e-6 = 2e-5; n = 2e-5 + 200*2e-6 = 4.2e-4
    #          u = 2e-4*20 + 0.6*4.2e-4 + 3*1e-6 = 4e-3 + 2.52e-4 + 3e-6 = 4.255e-3
    # motor 3: e_c = 3e-6 + 30*2e-7 = 9e-6; de_c = -1e-3 + 30*(-8e-6) = -1.24e-3; n = -1.24e-3 + 300*9e-6 = 1.46e-3
    #          u = 5e-5*30 + 0.7*1.46e-3 + 4*(-8e-6) = 1.5e-3 + 1.022e-3 - 3.2e-5 = 2.49e-3
    assert scdc_command(e, de, c, integ, u_d, G) == pytest.approx((1.649e-3, 4.255e-3, 2.49e-3), rel=1e-12)


def test_apd_command_is_eq38():
    e, de, u_d = (1e-6, 2e-6, 3e-6), (1e-3, 0.0, -1e-3), (10.0, 20.0, 30.0)
    # u_i = K_T u_d + k_v de + k_p e
    expected = (1e-3 + 0.5e-3 + 2e-6, 4e-3 + 0.0 + 6e-6, 1.5e-3 - 0.7e-3 + 12e-6)
    assert apd_command(e, de, u_d, G) == pytest.approx(expected, rel=1e-12)


def test_scdc_with_zero_coupling_reduces_to_pd_on_e():
    # b = 0, Lambda_p = 0: u = K_T u_d + Lambda_v (de + D e) -- APD-DC with k_p = Lambda_v D.
    g0 = G._replace(b=(0.0,) * 3, Lambda_p=(0.0,) * 3)
    e, de, u_d = (1e-6, -2e-6, 3e-6), (1e-3, 2e-3, -1e-3), (1.0, 2.0, 3.0)
    matched = G._replace(Lambda_p=tuple(v * d for v, d in zip(G.Lambda_v, G.D)))
    assert scdc_command(e, de, (5e-6, 1e-6, -6e-6), (1.0, 1.0, 1.0), u_d, g0) == \
        pytest.approx(apd_command(e, de, u_d, matched), rel=1e-12)


def _controller(law=SCDC, velocity_source=0, gains=G, modal=ModalGains()):
    return ControllerModel(PAPER_MODEL, gains, law, velocity_source, modal=modal)


def test_integral_of_c_is_a_right_rectangle_sum_over_samples():
    ctl = _controller()
    ref = (0.0,) * 9
    h = 1e-4
    q_seq = [(1e-6, 0.0, 0.0), (2e-6, 0.0, -1e-6), (0.0, 3e-6, 0.0)]
    expected = [0.0, 0.0, 0.0]
    for q in q_seq:
        e = tuple(-x for x in q)
        c = sync_deviation(*sync_errors(*e))
        expected = [expected[i] + h * c[i] for i in range(3)]
        ctl.sample(0.0, h, ref, q, (0.0, 0.0, 0.0))
        assert ctl.integral == pytest.approx(expected, rel=1e-12, abs=1e-20)
    assert ctl.q_prev == q_seq[-1]


def test_velocity_is_the_backward_difference_after_the_first_sample():
    ctl = _controller(gains=G._replace(Lambda_p=(0.0,) * 3, b=(0.0,) * 3, D=(0.0,) * 3))
    ref = (0.0,) * 9
    ctl.sample(0.0, 1e-4, ref, (0.0, 0.0, 0.0), (5.0, 5.0, 5.0))  # first sample uses dq inputs
    F, u, e, es = ctl.sample(1e-4, 1e-4, ref, (1e-6, 1e-6, 1e-6), (5.0, 5.0, 5.0))
    ud = feedforward((1e-6,) * 3, (1e-2,) * 3, (0.0,) * 3, (0.0,) * 3, PAPER_MODEL)
    # de = 0 - (1e-6 / 1e-4) = -1e-2 m/s, independent of the dq inputs
    assert u == pytest.approx(tuple(G.K_T[i] * ud[i] + G.Lambda_v[i] * -1e-2 for i in range(3)), rel=1e-12)
    assert F == pytest.approx(tuple(u[i] / G.K_T[i] for i in range(3)), rel=1e-15)


def test_law_1_is_apd_dc_with_the_same_feedforward():
    ref = reference(0.3, TrajectoryParams())
    q, dq = (1e-3, 2e-3, 1.5e-3), (0.01, 0.02, 0.0)
    ctl = _controller(law=APDDC, velocity_source=1)
    F, u, e, es = ctl.sample(0.3, 1e-4, ref, q, dq)
    qd = inverse(*ref[:3], PAPER_MODEL.L_1)
    dqd = joint_velocity(ref[2], *ref[3:6], PAPER_MODEL.L_1)
    e_hand = tuple(qd[i] - q[i] for i in range(3))
    de_hand = tuple(dqd[i] - dq[i] for i in range(3))
    ud = feedforward(q, dq, ref[3:6], ref[6:9], PAPER_MODEL)
    assert e == pytest.approx(e_hand, rel=1e-12)
    assert u == pytest.approx(apd_command(e_hand, de_hand, ud, G), rel=1e-12)


@pytest.mark.parametrize("t", [0.0, 0.37, 1.1, 2.0])
def test_feedforward_is_the_exact_inverse_of_the_plant_dynamics(t):
    """Model on the trajectory, feedback gains 0: F = u_d / K_T gives the plant xdd = xdd_d."""
    gains = Gains((0.0,) * 3, (0.0,) * 3, (0.0,) * 3, (0.0,) * 3, (4.1e-5,) * 3)
    ref = reference(t, TrajectoryParams())
    plant = PlantModel(PAPER_MODEL, IDEAL, ref[:3], ref[3:6])
    ctl = ControllerModel(PAPER_MODEL, gains, SCDC, velocity_source=1)
    F = ctl.sample(t, 1e-4, ref, plant.joint_positions(), plant.joint_velocities(), advance=False)[0]
    xdd = plant.derivatives(plant.state, *F)[3:]
    for got, want in zip(xdd, ref[6:9]):
        assert got == pytest.approx(want, rel=1e-9, abs=1e-12)


@pytest.mark.parametrize("kwargs,match", [
    ({"gains": G._replace(K_T=(0.0, 1e-5, 1e-5))}, r"K_T1 = 0.0 is invalid: allowed is a number in \[1e-12, 1e\+12\]"),
    ({"gains": G._replace(Lambda_v=(1.0, -1.0, 1.0))}, r"Lambda_v2 = -1.0 is invalid: allowed is a number in \[0, 1e\+12\]"),
    ({"law": 3}, r"law = 3 is invalid: allowed is 0 \(SC-DC\), 1 \(APD-DC\) or 2 \(PID-DC\)"),
    ({"modal": ModalGains(ki_d=-1.0)}, r"ki_d = -1.0 is invalid: allowed is a number in \[0, 1e\+15\]"),
    ({"modal": ModalGains(kp_c=math.inf)}, r"kp_c = inf is invalid"),
    ({"velocity_source": 3}, r"velocity_source = 3 is invalid"),
])
def test_invalid_controller_settings_are_named(kwargs, match):
    with pytest.raises(ModelInputError, match=match):
        _controller(**kwargs)


def test_non_finite_input_and_bad_pose_are_named_with_the_time():
    ctl = _controller()
    with pytest.raises(ModelInputError, match=r"q2 = nan at t = 0.25 s"):
        ctl.sample(0.25, 1e-4, (0.0,) * 9, (0.0, math.nan, 0.0), (0.0,) * 3)
    with pytest.raises(ModelInputError, match=r"allowed is \|value\| < 1"):
        ctl.sample(0.25, 1e-4, (0.0,) * 9, (0.0, 0.06, 0.0), (0.0,) * 3)


def test_presets_hold_the_paper_gains():
    assert gain_preset("paper_simulation")["Lambda_v"] == (150.0, 158.5, 108.5)  # Eq. 40
    assert gain_preset("paper_experiment")["K_T"] == (3e-5, 3e-5, 3e-5)          # Eq. 42
    with pytest.raises(ValueError, match="allowed are default, paper_experiment, paper_simulation"):
        gain_preset("fast")


# --- PID-DC (law 2): modal PID on e -----------------------------------------------------

M = ModalGains(kp_c=10.0, kv_c=1.0, ki_c=100.0, kp_d=40.0, kv_d=2.0, ki_d=1000.0)


def test_pid_command_by_hand():
    # e = (3, 0, 0) um: mean 1 um, deviations (2, -1, -1) um
    # K_P e = 10 * 1 + 40 * (2, -1, -1) = (90, -30, -30) [u per um]
    # de = (0, 0, 3) mm/s: mean 1, deviations (-1, -1, 2): K_V de = 1 * 1 + 2 * dev = (-1, -1, 5) [u per mm/s]
    # int e = (1, 1, 1) nm s: common only: K_I = 100 * 1 nm s = 1e-7 each
    e, de, ie, u_d, K_T = (3e-6, 0.0, 0.0), (0.0, 0.0, 3e-3), (1e-9, 1e-9, 1e-9), (10.0, 20.0, 30.0), G.K_T
    expected = (1e-3 + 90e-6 - 1e-3 + 1e-7, 4e-3 - 30e-6 - 1e-3 + 1e-7, 1.5e-3 - 30e-6 + 5e-3 + 1e-7)
    assert pid_command(e, de, ie, u_d, M, K_T) == pytest.approx(expected, rel=1e-12)


def test_pid_gain_matrices_are_k_c_on_the_common_and_k_d_on_the_differential_modes():
    """K = k_c 1 1^T / 3 + k_d (I - 1 1^T / 3) as matrices, applied to random vectors."""
    rng = np.random.default_rng(7)
    ones = np.ones((3, 3)) / 3.0
    K = {k: getattr(M, f"{k}_c") * ones + getattr(M, f"{k}_d") * (np.eye(3) - ones) for k in ("kp", "kv", "ki")}
    for _ in range(100):
        e, de, ie = rng.normal(0, 1e-6, 3), rng.normal(0, 1e-3, 3), rng.normal(0, 1e-7, 3)
        want = K["kp"] @ e + K["kv"] @ de + K["ki"] @ ie
        got = pid_command(tuple(e), tuple(de), tuple(ie), (0.0,) * 3, M, G.K_T)
        assert got == pytest.approx(tuple(want), rel=1e-12, abs=1e-22)


def test_pid_dc_with_the_modal_image_reproduces_scdc_for_uniform_gains_on_random_states():
    """The modal identity: SC-DC = K_T u_d + Lambda_v de + [Lambda_v D I + (Lambda_v b +
    Lambda_p) L] e + Lambda_v D b L int(e), L = 3 I - 1 1^T; so with c = L e and int(c) = L int(e),
    scdc_command equals pid_command with kp_c = Lambda_v D, kp_d = Lambda_v D + 3 (Lambda_v b +
    Lambda_p), kv = Lambda_v, ki_c = 0, ki_d = 3 Lambda_v D b."""
    rng = np.random.default_rng(14)
    L = 3.0 * np.eye(3) - np.ones((3, 3))
    worst = 0.0
    for _ in range(2000):
        lp, lv, b, D, kt = (float(np.exp(rng.uniform(np.log(lo), np.log(hi)))) for lo, hi in
                            ((1.0, 1e4), (0.01, 200.0), (1e-4, 100.0), (10.0, 1e3), (1e-5, 1e-4)))
        g = Gains((lp,) * 3, (lv,) * 3, (b,) * 3, (D,) * 3, (kt,) * 3)
        e, de, ie = rng.normal(0, 1e-5, 3), rng.normal(0, 1e-3, 3), rng.normal(0, 1e-6, 3)
        u_d = tuple(rng.normal(0, 50.0, 3))
        c, ic = L @ e, L @ ie
        u_sc = scdc_command(tuple(e), tuple(de), tuple(c), tuple(ic), u_d, g)
        u_pid = pid_command(tuple(e), tuple(de), tuple(ie), u_d, ModalGains.matching_scdc(g), g.K_T)
        # relative to the size of the terms summed (|K_T u_d| + |Lambda_v n| + |Lambda_p c|): u itself
        # may cancel to far less than its terms, and no ordering of the sum can do better than that
        n = de + b * c + D * (e + b * ic)
        scale = np.abs(kt * np.array(u_d)) + np.abs(lv * n) + np.abs(lp * c)
        worst = max(worst, float(np.max(np.abs(np.array(u_sc) - np.array(u_pid)) / scale)))
    assert worst < 1e-12


def test_modal_image_of_the_default_preset_is_the_pid_dc_default():
    # Lambda_v 0.36, D 900, Lambda_p 300, b 50: kp_c = 324, kp_d = 324 + 3 (18 + 300) = 1278,
    # kv = 0.36, ki_c = 0, ki_d = 3 * 0.36 * 900 * 50 = 48600 (common mode 324, differential 1278, in u/m)
    assert tuple(ModalGains()) == pytest.approx((324.0, 0.36, 0.0, 1278.0, 0.36, 48600.0), rel=1e-12)
    assert ModalGains() == ModalGains(**DEFAULT_MODAL_GAINS)
    with pytest.raises(ValueError, match=r"Lambda_p = \(1.0, 2.0, 1.0\) is not uniform"):
        scdc_modal_image({"Lambda_p": (1.0, 2.0, 1.0), "Lambda_v": (1.0,) * 3, "b": (1.0,) * 3, "D": (1.0,) * 3})


def test_pid_dc_controller_integrates_e_and_follows_scdc_sample_by_sample():
    """Same inputs, default gains: law 2 with the modal image gives SC-DC's commands to round-off,
    and its integral is the right-rectangle sum of e (SC-DC's is L times it)."""
    g = Gains.from_preset(gain_preset("default"))
    sc = ControllerModel(PAPER_MODEL, g, SCDC)
    pid = ControllerModel(PAPER_MODEL, g, PIDDC, modal=ModalGains.matching_scdc(g))
    rng = np.random.default_rng(3)
    h, ie = 1e-4, np.zeros(3)
    L = 3.0 * np.eye(3) - np.ones((3, 3))
    for k in range(50):
        t = k * h
        ref = reference(t, TrajectoryParams())
        q = np.array(inverse(*ref[:3], PAPER_MODEL.L_1)) + rng.normal(0, 2e-6, 3)
        F_sc, u_sc, e, _ = sc.sample(t, h, ref, tuple(q), (0.0,) * 3)
        F_pid, u_pid, e2, _ = pid.sample(t, h, ref, tuple(q), (0.0,) * 3)
        ie = ie + h * np.array(e)
        assert e2 == e
        assert pid.integral == pytest.approx(list(ie), rel=1e-12, abs=1e-24)
        assert sc.integral == pytest.approx(list(L @ ie), rel=1e-9, abs=1e-22)
        assert F_pid == pytest.approx(F_sc, rel=1e-10)
