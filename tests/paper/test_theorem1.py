"""The paper's Theorem 1 does not hold: a counterexample with positive gains, checked two ways."""

import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import expm

from orchestrator.paper import theorem1 as t1
from tapmp.params import GAIN_PRESETS

ROOT = Path(__file__).resolve().parents[2]
COUNTER = t1.COUNTEREXAMPLE


def test_every_gain_of_the_counterexample_is_positive():
    assert all(v > 0 for values in COUNTER.values() for v in values)


def test_sc_dc_error_dynamics_grow_at_18_9_per_second_while_apd_dc_decays():
    assert math.isclose(t1.max_real_part(COUNTER, "sc-dc"), 18.9, rel_tol=0.01)
    assert t1.max_real_part(COUNTER, "apd-dc") < -10.0


def test_the_error_dynamics_matrix_is_the_pid_form_divided_by_the_joint_mass_matrix():
    # hand-derived: common mode of SC-DC is P = Lambda_v D = 2, V = Lambda_v = 0.01 (u units),
    # so on (1,1,1) the error obeys m_c e'' = -(0.01 e' + 2 e) / K_T with m_c = 1^T M_q 1 / 3
    A = t1.error_dynamics(COUNTER, "sc-dc")
    Mq = t1.joint_mass_matrix()
    ones = np.ones(3)
    m_c = ones @ Mq @ ones / 3.0
    x = np.concatenate([np.zeros(3), ones, np.zeros(3)])  # e = (1, 1, 1), no integral, no rate
    dd = (A @ x)[6:]
    # L (1,1,1) = 0: no coupling term, only the common stiffness acts
    expected = -np.linalg.solve(Mq, ones * 2.0 / 4.1e-5)
    assert np.allclose(dd, expected, rtol=1e-12)
    assert m_c > 0


def test_the_papers_lyapunov_function_grows_along_the_unstable_mode():
    A = t1.error_dynamics(COUNTER, "sc-dc")
    w, v = np.linalg.eig(A)
    x0 = np.real(v[:, np.argmax(w.real)])
    values = [t1.lyapunov_v(expm(A * t) @ x0, COUNTER) for t in np.linspace(0.0, 0.2, 201)]
    assert values[-1] > 100.0 * values[0]  # V' <= 0 (Eq. 34) is false on this trajectory
    assert any(b > a for a, b in zip(values, values[1:]))


def test_eq_31_holds_for_uniform_gains_and_fails_for_the_papers_gains():
    rng = np.random.default_rng(7)
    for _ in range(20):
        state = [rng.normal(size=3) for _ in range(3)]
        lhs, rhs = t1.eq31_sides(*state, COUNTER)
        assert math.isclose(lhs, rhs, rel_tol=1e-9, abs_tol=1e-9)
    misses = 0
    for _ in range(20):
        state = [rng.normal(size=3) for _ in range(3)]
        lhs, rhs = t1.eq31_sides(*state, GAIN_PRESETS["paper_simulation"])
        misses += not math.isclose(lhs, rhs, rel_tol=1e-6)
    assert misses == 20


def _check(tmp_path, law):
    scenario = tmp_path / "theorem1.toml"
    scenario.write_text('name = "theorem1"\nstop_time = 0.01\nstep = 1e-6\n[gain_overrides]\n'
                        + "".join(f"{k} = {v[0]!r}\n" for k, v in COUNTER.items()))
    return subprocess.run([sys.executable, "-m", "orchestrator", "check", str(scenario), "--set", f'law="{law}"'],
                          capture_output=True, text=True, cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)})


@pytest.mark.slow
def test_tapmp_check_at_a_fine_step_agrees_with_the_continuous_eigenvalues(tmp_path):
    sc = _check(tmp_path, "sc-dc")
    assert sc.returncode == 1, sc.stdout + sc.stderr
    assert "unstable: spectral radius 1.0000" in sc.stdout
    rho = float(sc.stdout.split("spectral radius ")[1].split()[0])
    # growth per second of the sampled loop's worst mode against the continuous-time eigenvalue
    assert math.isclose(math.log(rho) / 1e-6, t1.max_real_part(COUNTER, "sc-dc"), rel_tol=0.03)
    apd = _check(tmp_path, "apd-dc")
    assert apd.returncode == 0, apd.stdout + apd.stderr
    assert apd.stdout.startswith("theorem1: stable:")


@pytest.mark.parametrize("gain, holds", [("b", True), ("D", False), ("Lambda_p", False)])
def test_eq31_survives_a_per_motor_b_but_not_a_per_motor_d_or_lambda_p(gain, holds):
    from orchestrator.paper.theorem1 import COUNTEREXAMPLE, eq31_sides
    rng = np.random.default_rng(7)
    state = [rng.normal(size=3) for _ in range(3)]
    gains = {k: list(v) for k, v in COUNTEREXAMPLE.items()}
    gains[gain] = [x * f for x, f in zip(gains[gain], (1.0, 1.5, 0.7))]
    lhs, rhs = eq31_sides(*state, gains)
    assert (abs(lhs - rhs) <= 1e-9 * abs(lhs)) == holds, (lhs, rhs)


def test_tapmp_theorem1_prints_the_counterexample_unstable_for_sc_dc_and_stable_for_apd_dc(capsys):
    from orchestrator.cli import main
    assert main(["theorem1"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines == t1.summary_lines()
    assert lines[0].startswith("sc-dc: largest real part +") and lines[0].endswith("unstable")
    assert lines[1].startswith("apd-dc: largest real part -") and lines[1].endswith(", stable")
