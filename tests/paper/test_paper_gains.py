"""The paper's gains at fine steps (orchestrator.paper.paper_gains), short horizons."""

import math
import random
from pathlib import Path

import numpy as np
import pytest

from orchestrator.tool import stability
from orchestrator.paper.paper_gains import (paper_gains_table, paper_scenario, reading_b, run_paper_gains,
                                                  run_scenario)
from orchestrator.tool.scenario import load
from tapmp.closed_loop import simulate
from tapmp.control import Gains
from tapmp.kinematics import S3, forward, rotation_column
from tapmp.params import GAIN_PRESETS, PAPER_MODEL

REPO = Path(__file__).resolve().parents[2]


def test_reading_b_is_force_equal_k_t_u_d_plus_feedback():
    """Reading B's controller (Lambda and nominal masses times K_T) outputs F = K_T u_d +
    Lambda_v n + Lambda_p c, i.e. the command u of the unchanged law: compared on 300
    random states (pose, rates, reference, integral, previous sample) to 1e-12."""
    rng = random.Random(7)
    for law in ("sc-dc", "apd-dc"):
        ctrl_a = paper_scenario("Eq. 40-41", law, 1e-5, 0.01, "A").plain_models()[1]
        ctrl_b = paper_scenario("Eq. 40-41", law, 1e-5, 0.01, "B").plain_models()[1]
        for _ in range(150):
            ref = [rng.uniform(-0.01, 0.01), rng.uniform(-0.02, 0.0), rng.uniform(-0.08, 0.08),
                   *(rng.uniform(-0.05, 0.05) for _ in range(3)), *(rng.uniform(-1, 1) for _ in range(3))]
            q = [rng.uniform(-0.01, 0.01) for _ in range(3)]
            q[1] = 0.5 * (q[0] + q[2]) + rng.uniform(-1e-3, 1e-3)  # inside the kinematic domain
            dq = [rng.uniform(-0.05, 0.05) for _ in range(3)]
            integral = [rng.uniform(-1e-6, 1e-6) for _ in range(3)]
            q_prev = [x - 1e-5 * v for x, v in zip(q, dq)]
            out = []
            for c in (ctrl_a, ctrl_b):
                c.integral, c.q_prev = list(integral), tuple(q_prev)
                out.append(c.sample(0.0, 1e-5, ref, q, dq))
            u_a, F_b = out[0][1], out[1][0]
            scale = max(abs(x) for x in u_a) + 1e-300
            assert max(abs(a - b) for a, b in zip(u_a, F_b)) <= 1e-12 * scale


def test_reading_b_refuses_k_t_that_differs_per_motor():
    g = Gains.from_preset({**GAIN_PRESETS["paper_simulation"], "K_T": (4.1e-5, 4e-5, 4.1e-5)})
    with pytest.raises(ValueError, match=r"K_T = \(4.1e-05, 4e-05, 4.1e-05\) is invalid for reading B"):
        reading_b(g, {})


def test_bad_arguments_are_named():
    with pytest.raises(ValueError, match="reading = 'C' is invalid: allowed are A, B"):
        run_paper_gains(readings=("C",))
    with pytest.raises(ValueError, match="plant = 'ideal' is invalid: allowed are encoder, exact"):
        run_paper_gains(plants=("ideal",))
    with pytest.raises(ValueError, match="workers = 0 is invalid"):
        run_paper_gains(workers=0)


@pytest.mark.slow
def test_eq40_at_1us_is_stable_with_nanometre_errors_and_chatters_at_10us():
    """Reading A, Eq. 40-41, exact measurement: at 1 us both laws are stable (rho < 1, no
    sample at the force limit) with tracking MAE below 10 nm over 20 ms; at 10 us the loop
    is unstable (rho about 2 per step) and, held by the 600 N saturation, stays bounded but
    chatters at the limit (> 1 % of samples); the run says so."""
    rows = run_paper_gains(steps=(1e-6,), stop_time=0.02, readings=("A",), cases=("Eq. 40-41",),
                           plants=("exact",))
    for r in rows:
        assert r["stable"] and r["status"] == "stable" and r["spectral_radius"] < 1.0
        assert max(r["saturation_fraction"]) == 0.0
        assert max(r["tracking_mae_um"]) < 0.01 and max(r["sync_mae_um"]) < 0.01
        assert r["diverged_at"] is None and r["samples"] == 20001
    rows = run_paper_gains(steps=(1e-5,), stop_time=0.02, readings=("A",), cases=("Eq. 40-41",),
                           plants=("exact",))
    for r in rows:
        assert not r["stable"] and r["status"] == "chatters at the force limit"
        assert 1.5 < r["spectral_radius"] < 3.0
        assert max(r["saturation_fraction"]) > 0.5
        assert r["diverged_at"] is None and max(r["tracking_mae_um"]) < 100.0   # bounded


def test_eq40_at_the_servo_cycle_is_reported_unstable_as_the_check_says():
    """0.1 ms, reading A, the scenario's plant: the row is not stable (chatters at the
    600 N limit) and its spectral radius is the one stability.check gives for
    scenarios/paper_simulation.toml with gains = "paper_simulation" (39.2 SC-DC, 38.6
    APD-DC); without the force limit the plant leaves the envelope within 2 ms."""
    rows = run_paper_gains(steps=(1e-4,), stop_time=0.02, readings=("A",), cases=("Eq. 40-41",),
                           plants=("encoder",))
    for r in rows:
        sc = load(REPO / "scenarios/paper_simulation.toml", ['gains="paper_simulation"', f'law="{r["law"]}"'])
        rho = stability.check(sc).spectral_radius
        assert rho > 30.0
        assert r["spectral_radius"] == pytest.approx(rho, rel=1e-9)
        assert not r["stable"] and r["status"] == "chatters at the force limit"
        assert min(r["saturation_fraction"]) > 0.9
        free = paper_scenario("Eq. 40-41", r["law"], 1e-4, 0.02, "A")
        free = free.with_changes(plant={**free.plant, "force_limit": 0.0})
        out = run_scenario(free)
        assert out["status"] == "diverged" and out["diverged_at"] <= 2e-3


def _static_error_estimate(k_p, k_pull, m_p, g, K_T, L1):
    """Hand derivation of reading B's static error e = q_d - q under gravity (APD-DC, de = 0).

    Equilibrium of the movers: J^T f = G = (0, m_p g, 0) (Eq. 13-14) with f the net motor
    force; rows of J^T: f1 + f2 + f3 = 0 (X), S3 (f1 - f3) = m_p g (Z), a1 f1 + a3 f3 = 0 (B)
    with (a1, a3) = rotation_column(B). The command is F = K_T u_d + k_p e with u_d = f (the
    feedforward is the same statics at the measured pose), the pulling adds k_pull P e with
    P the path Laplacian of the movers, so (diag(k_p) + k_pull P) e = (1 - K_T) f.
    Simple estimate: e_i = f_i / k_p,i at B = 0 (f1 = -f3 = m_p g sqrt(3) / 2, f2 = 0).
    Refined: the full linear system with f at the settled B (fixed point, 5 iterations).
    """
    fZ = m_p * g / S3
    simple = np.array([0.5 * fZ / k_p[0], 0.0, -0.5 * fZ / k_p[2]])
    P = np.array([[1.0, -1.0, 0.0], [-1.0, 2.0, -1.0], [0.0, -1.0, 1.0]])
    e = simple.copy()
    for _ in range(5):
        B = forward(*(-e), L1)[2]   # q = q_d - e with q_d = 0 at the home pose
        a1, a3 = rotation_column(B, L1)
        f1 = fZ * a3 / (a1 + a3)    # from S3 (f1 - f3) = m_p g and a1 f1 + a3 f3 = 0
        f3 = -fZ * a1 / (a1 + a3)
        f = np.array([f1, -(f1 + f3), f3])
        e = np.linalg.solve(np.diag(k_p) + k_pull * P, (1.0 - K_T) * f)
    return simple, e


@pytest.mark.slow
def test_reading_b_static_error_under_gravity_is_m_g_over_k_p():
    """Reading B, APD-DC with Eq. 41 (k_p = 8000, 8000, 8850 N/m, k_v = 150, 158.5, 108.5 N s/m),
    the reference held at the home pose, exact measurement, 10 us, 1.6 s (the slowest mode
    decays in about 0.3 s): the feedback holds
    the platform's 18 N of weight, 31.1 N between motors 1 and 3, with millimetre errors.
    Simple estimate e_1 = 15.57 / 8000 = 1.95 mm, e_3 = -15.57 / 8850 = -1.76 mm: within 5 %
    (pulling, 200 N/m, adds about 2.5 % of stiffness). Refined estimate (pulling and the
    settled tilt): within 0.2 %, the rest being the decaying transient."""
    sc = paper_scenario("Eq. 40-41", "apd-dc", 1e-5, 1.6, "B", "exact")
    sc = sc.with_changes(trajectory={**sc.trajectory, "f_xz": 0.0, "f_B": 0.0})
    plant, ctrl, traj = sc.plain_models()
    simulate(plant, ctrl, traj, 0.0, sc.n_steps, sc.step)
    e = -np.array(plant.joint_positions())   # q_d = (0, 0, 0): the home pose
    kp = GAIN_PRESETS["paper_simulation"]["Lambda_p"]
    simple, refined = _static_error_estimate(kp, sc.plant.get("k_pull", 200.0), PAPER_MODEL.m_p, PAPER_MODEL.g,
                                             4.1e-5, PAPER_MODEL.L_1)
    assert simple[0] == pytest.approx(1.947e-3, rel=1e-3) and simple[2] == pytest.approx(-1.760e-3, rel=1e-3)
    assert e[0] == pytest.approx(simple[0], rel=0.05) and e[2] == pytest.approx(simple[2], rel=0.05)
    assert abs(e[1]) < 0.05 * abs(e[0])
    assert e == pytest.approx(refined, rel=2e-3, abs=2e-3 * abs(refined[0]))


def test_table_lists_every_row():
    rows = run_paper_gains(steps=(1e-4,), stop_time=0.01, cases=("Eq. 42-43",), plants=("exact",))
    assert [(r["reading"], r["law"]) for r in rows] == [("A", "sc-dc"), ("A", "apd-dc"), ("B", "sc-dc"),
                                                         ("B", "apd-dc")]
    text = paper_gains_table(rows)
    lines = text.splitlines()
    assert len(lines) == 2 + 4
    assert lines[2].startswith("| Eq. 42-43 | exact | A | SC-DC | 100 us | chatters at the force limit |")
    assert all(not math.isnan(r["wall_s"]) for r in rows)


def test_tapmp_paper_gains_refuses_an_unknown_case_or_workers_in_one_line(capsys):
    from orchestrator.cli import main
    assert main(["paper-gains", "--cases", "Eq. 40"]) == 2
    assert capsys.readouterr().err == ("error: --cases = 'Eq. 40' is invalid: allowed are Eq. 40-41, Eq. 42-43; "
                                       "did you mean Eq. 40-41 or Eq. 42-43?\n")
    assert main(["paper-gains", "--workers", "0"]) == 2
    assert capsys.readouterr().err == "error: --workers = 0 is invalid: allowed is an integer >= 1\n"
