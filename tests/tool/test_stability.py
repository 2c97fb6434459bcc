"""Stability pre-check: the verdict and the spectral radius agree with what the loop does."""

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from orchestrator.cli import main
from orchestrator.tool.scenario import load
from orchestrator.tool.stability import MARGIN, OneStepMap, check, loop_models
from tapmp.closed_loop import simulate
from tapmp.errors import KinematicDomainError
from tapmp.kinematics import inverse

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "scenarios" / "paper_simulation.toml"

EQ40 = 'gains="paper_simulation"'


def tracking_errors(scenario, n_steps, linear=False, perturb=0.0):
    """Max |q_d - q_true| over the motors [m] at each communication point of the plain loop,
    and the step at which the plant left the workspace (None if it did not)."""
    plant, ctrl, traj = loop_models(scenario, linear)
    plant.state[0] += perturb
    rows = []

    def record(t, ref, F, q, q_true):
        q_d = inverse(ref[0], ref[1], ref[2], ctrl.p.L_1)
        rows.append([q_d[i] - q_true[i] for i in range(3)])
    try:
        simulate(plant, ctrl, traj, scenario.start_time, n_steps, scenario.step, scenario.ordering, record)
        return np.array(rows), None
    except KinematicDomainError:
        return np.array(rows), len(rows)


@pytest.mark.parametrize("ordering", ["gauss-seidel", "jacobi"])
def test_paper_eq40_gains_are_unstable_and_the_unsaturated_run_diverges_at_the_predicted_rate(ordering):
    scenario = load(PAPER, [EQ40, f'ordering="{ordering}"', "plant.force_limit=0"])
    report = check(scenario)
    assert report.verdict == "unstable" and not report.stable
    assert report.spectral_radius > 5.0
    errors, failed_at = tracking_errors(scenario, 200)
    assert failed_at is not None and failed_at < 20  # leaves the workspace within 2 ms
    size = np.abs(errors).max(axis=1)
    growth = (size[-1] / size[-5]) ** 0.25  # per step over the last four steps before it left
    assert report.spectral_radius / 2.0 < growth < 2.0 * report.spectral_radius


def test_paper_eq40_gains_with_the_force_limit_chatter_instead_of_settling():
    unstable = load(PAPER, [EQ40, "stop_time=0.2"])
    stable = load(PAPER, ["stop_time=0.2"])
    assert not check(unstable).stable and check(stable).stable
    late_unstable = np.abs(tracking_errors(unstable, unstable.n_steps)[0][-500:]).mean()
    late_stable = np.abs(tracking_errors(stable, stable.n_steps)[0][-500:]).mean()
    assert late_unstable > 2e-6   # several micrometres of chatter at the 600 N limit
    assert late_stable < 0.5e-6   # sub-micrometre with the default gains
    assert late_unstable > 10 * late_stable


def loop_states(scenario, perturb):
    """Plant state and integral of c at each communication point of the linearized plain loop,
    with the start X perturbed by ``perturb`` [m]."""
    plant, ctrl, traj = loop_models(scenario, linear=True)
    plant.state[0] += perturb
    rows = []
    simulate(plant, ctrl, traj, scenario.start_time, scenario.n_steps, scenario.step, scenario.ordering,
             lambda *_: rows.append([*plant.state, *ctrl.integral]))
    return np.array(rows)


@pytest.mark.parametrize("ordering", ["gauss-seidel", "jacobi"])
@pytest.mark.parametrize("law, window, tolerance", [
    # SC-DC: from step 1000 on the slowest mode alone is left; 1e-6 on rho (2.6e-4 of 1 - rho) would
    # catch the 43 % error in 1 - rho an earlier window (500-1000, Jacobi: 0.99451) gives.
    ("sc-dc", (1000, 1500), 1e-6),
    # APD-DC: 1 - rho = 0.054, the perturbation reaches round-off by step 400; 3e-3 is 6 % of 1 - rho.
    ("apd-dc", (100, 300), 3e-3)])
def test_default_gains_are_stable_and_a_perturbation_decays_at_the_spectral_radius(law, window, tolerance, ordering):
    scenario = load(PAPER, [f'law="{law}"', f'ordering="{ordering}"', f"stop_time={0.16 if law == 'sc-dc' else 0.1}"])
    report = check(scenario)
    assert report.verdict == "stable" and report.spectral_radius < 1.0 - MARGIN
    scale = np.array([1e-8] * 3 + [1e-6] * 3 + [1e-10] * 3)  # m or rad, m/s or rad/s, m s
    dev = np.linalg.norm((loop_states(scenario, 1e-6) - loop_states(scenario, 0.0)) / scale, axis=1)
    a, b = window  # once the slowest mode dominates (and before round-off does)
    assert dev[b] < 0.05 * dev[1]
    assert (dev[b] / dev[a]) ** (1 / (b - a)) == pytest.approx(report.spectral_radius, abs=tolerance)
    errors, failed_at = tracking_errors(scenario, scenario.n_steps)  # the full nonlinear run stays put
    assert failed_at is None and np.abs(errors).max() < 1e-6


@pytest.mark.parametrize("ordering", ["gauss-seidel", "jacobi"])
def test_one_step_map_is_the_simulated_loop_step_for_step(ordering):
    scenario = load(PAPER, [f'ordering="{ordering}"', "stop_time=0.01"])
    m = OneStepMap(scenario, linear=False)
    x = m.start_state()
    plant, ctrl, traj = loop_models(scenario)
    states = []
    simulate(plant, ctrl, traj, scenario.start_time, scenario.n_steps, scenario.step, ordering,
             lambda *row: states.append(list(plant.state)))
    for k in range(scenario.n_steps):
        x = m.at(scenario.start_time + k * scenario.step)(x)
        # equal up to the last bit of t0 + (k + 1) h versus t0 + k h + h in the reference
        assert list(x[:6]) == pytest.approx(states[k + 1], rel=1e-12, abs=1e-15)


def test_the_conserved_sum_of_the_integrals_is_the_only_unit_eigenvalue_removed():
    scenario = load(PAPER)
    m = OneStepMap(scenario)
    full = np.linalg.eigvals(m.jacobian(m.start_state()))
    assert np.min(np.abs(full - 1.0)) < 1e-8           # exact 1: sum of integrals of c is conserved
    report = check(scenario)
    assert len(report.eigenvalues) == len(full) - 1
    assert max(abs(z) for z in report.eigenvalues) < 1.0 - 1e-3
    assert report.states[6:9] == ["integral_c1", "integral_c2", "integral_c3"]
    assert report.states[9:] == ["q1_prev", "q2_prev", "q3_prev"]


def test_jacobi_adds_the_held_command_to_the_state_and_apd_drops_the_integral():
    jacobi = check(load(PAPER, ['ordering="jacobi"']))
    apd = check(load(PAPER, ['law="apd-dc"']))
    assert jacobi.states[-3:] == ["F1_held", "F2_held", "F3_held"] and len(jacobi.states) == 15
    assert not any(s.startswith("integral") for s in apd.states) and len(apd.states) == 9


def test_check_command_prints_the_verdict_and_exits_1_when_unstable(capsys):
    assert main(["check", str(PAPER)]) == 0
    out = capsys.readouterr().out
    assert "stable: spectral radius 0.99" in out
    assert main(["check", str(PAPER), "--set", EQ40]) == 1
    out = capsys.readouterr().out
    assert "unstable: spectral radius 39." in out and "grows" in out


@pytest.mark.slow
def test_run_warns_on_one_stderr_line_before_running_an_unstable_scenario(built, tmp_path):
    cmd = [sys.executable, "-m", "orchestrator", "run", str(PAPER), "--set", EQ40, "--set", "stop_time=0.002",
           "--ssp", str(built["ssp"]), "--out", str(tmp_path / "run"), "--no-progress"]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0
    warnings = [line for line in proc.stderr.splitlines() if line.startswith("warning:")]
    assert len(warnings) == 1 and "unstable" in warnings[0] and "spectral radius 39.197457" in warnings[0]
    stable = subprocess.run(cmd[:5] + cmd[7:-2] + [str(tmp_path / "stable"), "--no-progress"], capture_output=True, text=True, timeout=120)
    assert stable.returncode == 0 and "warning" not in stable.stderr
    assert math.isfinite(check(load(PAPER)).time_constant)


# --- PID-DC (law 2) -----------------------------------------------------------------------------

def _modal_image_overrides(scenario):
    """[controller] kp_c .. ki_d set to the modal image of the scenario's (uniform) SC-DC gains."""
    from tapmp.control import ModalGains
    m = ModalGains.matching_scdc(scenario.gain_values())
    return [f"controller.{n}={v!r}" for n, v in m._asdict().items()]


@pytest.mark.parametrize("ordering", ("gauss-seidel", "jacobi"))
@pytest.mark.parametrize("gains", ("default", "uniform_fast"))
def test_pid_dc_with_the_modal_image_has_the_spectral_radius_of_scdc(ordering, gains):
    """Uniform gains: PID-DC with kp_c = Lambda_v D, kp_d = Lambda_v D + 3 (Lambda_v b + Lambda_p),
    kv = Lambda_v, ki_c = 0, ki_d = 3 Lambda_v D b is SC-DC written in e, so the linearized
    discrete loops have the same spectrum (to the finite differences' error)."""
    extra = ([] if gains == "default" else
             ["gain_overrides.Lambda_v=2.0", "gain_overrides.D=400.0", "gain_overrides.b=20.0",
              "gain_overrides.Lambda_p=600.0"])
    sc = load(PAPER, [f'ordering="{ordering}"', *extra])
    pid = load(PAPER, [f'ordering="{ordering}"', 'law="pid-dc"', *extra, *_modal_image_overrides(sc)])
    r_sc, r_pid = check(sc), check(pid)
    assert r_pid.law == "pid-dc" and "integral_e1" in r_pid.states
    assert r_pid.spectral_radius == pytest.approx(r_sc.spectral_radius, abs=1e-9)
    assert r_pid.verdict == r_sc.verdict
    # the whole spectrum, not just its radius (sorted by magnitude, then angle)
    key = lambda z: (round(abs(z), 7), round(np.angle(z), 5))  # noqa: E731
    assert np.allclose(sorted(r_pid.eigenvalues, key=key), sorted(r_sc.eigenvalues, key=key), atol=1e-7)


def test_pid_dc_check_refuses_an_unstable_gain_set_and_handles_every_integral_structure():
    """A differential P gain far beyond what 0.1 ms sampling allows is unstable (as SC-DC with the
    Eq. 40 gains); with a common integral (ki_c > 0) all three integral states feed back, with no
    integral gain at all there is no integral state, and both are judged."""
    unstable = check(load(PAPER, ['law="pid-dc"', "controller.kv_d=500.0"]))
    assert unstable.verdict == "unstable" and unstable.spectral_radius > 1.0
    with_common = check(load(PAPER, ['law="pid-dc"', "controller.ki_c=2000.0"]))
    assert with_common.verdict == "stable" and [s for s in with_common.states if s.startswith("integral_e")] == [
        "integral_e1", "integral_e2", "integral_e3"]
    no_integral = check(load(PAPER, ['law="pid-dc"', "controller.ki_c=0.0", "controller.ki_d=0.0"]))
    assert not any(s.startswith("integral") for s in no_integral.states) and no_integral.verdict == "stable"


def test_stability_check_includes_the_attraction_and_the_mismatch():
    """The attraction's negative stiffness (-2 F_a / g_a per gap) and a mass mismatch change the
    linearized loop. The attraction is internal, so it acts on the differential modes only, whose
    stiffness with the default gains is kp_d / K_T = 1278 / 4.1e-5 = 3.1e7 N/m: -2 * 1 / 0.01 =
    -200 N/m leaves the loop stable, -2 * 1e5 / 1e-3 = -2e8 N/m overpowers it (unstable)."""
    base = check(load(PAPER))
    weak = check(load(PAPER, ["plant.attraction_force=1.0", "plant.attraction_gap=0.01"]))
    strong = check(load(PAPER, ["plant.attraction_force=1e5", "plant.attraction_gap=0.001"]))
    assert weak.spectral_radius != base.spectral_radius and weak.verdict == "stable"
    assert strong.verdict == "unstable"
    mism = check(load(PAPER, ["mismatch.m_1=1.5", "mismatch.m_3=1.5"]))
    assert mism.spectral_radius != base.spectral_radius


def test_the_cached_pre_check_is_the_checks_report_keyed_by_what_the_check_reads():
    from orchestrator.tool.stability import cache_key, cached_check
    sc = load(PAPER, ["stop_time=0.5", "gain_overrides.D=450"])
    report = cached_check(sc)
    assert report.to_dict() == check(sc).to_dict()
    # a case that differs only in what the check does not read shares the report
    assert cache_key(load(PAPER, ["stop_time=0.2", "gain_overrides.D=450"])) == cache_key(sc)
    for other in (["gain_overrides.D=900"], ["gain_overrides.D=450", "plant.c_v1=30"],
                  ["gain_overrides.D=450", "step=2e-4"], ["gain_overrides.D=450", 'ordering="jacobi"']):
        assert cache_key(load(PAPER, ["stop_time=0.5", *other])) != cache_key(sc), other
    # the caller gets its own copy
    report.eigenvalues.clear()
    assert cached_check(sc).eigenvalues == check(sc).eigenvalues != []
