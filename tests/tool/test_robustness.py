"""The robustness-matched baseline: a PD per mode at SC-DC's peak sensitivity Ms."""

import numpy as np
import pytest

from tests.support.shared import ROOT
from orchestrator.tool import analysis
from orchestrator.tool.baselines import compare_runs, robustness_matched
from orchestrator.tool.robustness import MODES, mode_peaks
from orchestrator.tool.scenario import load


@pytest.mark.parametrize("name", ["paper_simulation", "paper_simulation_calibrated", "paper_experiment_calibrated"])
def test_the_matched_pd_has_scdc_peak_sensitivity_on_every_mode_within_one_percent(name):
    sc = load(ROOT / "scenarios" / f"{name}.toml")
    runs = compare_runs(sc)
    freqs = analysis.frequency_grid(sc.step)
    scdc, pd = mode_peaks(runs["sc-dc"], freqs), mode_peaks(runs["apd-dc-ms-matched"], freqs)
    for mode in MODES:
        assert abs(pd[mode] - scdc[mode]) <= 0.01 * scdc[mode], (mode, pd, scdc)
    m = robustness_matched(sc)
    assert m.note == "" and m.gains.ki_c == m.gains.ki_d == 0.0
    assert runs["apd-dc-ms-matched"].law == "pid-dc"
    if name == "paper_simulation":  # there SC-DC's P and D alone miss its Ms: the tuning moved the P gains
        mm = mode_peaks(runs["apd-dc-mode-matched"], freqs)
        assert max(abs(mm[m_] - scdc[m_]) / scdc[m_] for m_ in MODES) > 0.02


@pytest.mark.slow
def test_the_peaks_equal_those_tapmp_analyze_reports():
    sc = load(ROOT / "scenarios" / "paper_simulation.toml")
    runs = compare_runs(sc)
    freqs = analysis.frequency_grid(sc.step, points=200)
    result = analysis.analyze_runs({k: runs[k] for k in ("sc-dc", "apd-dc-ms-matched")}, freqs)
    for run in ("sc-dc", "apd-dc-ms-matched"):
        peaks = mode_peaks(runs[run], freqs)
        for mode in MODES:
            assert np.isclose(peaks[mode], result[run]["loops"][mode]["Ms"], rtol=1e-9), (run, mode)


@pytest.mark.parametrize("name", ["paper_simulation", "paper_simulation_calibrated", "paper_experiment_calibrated"])
def test_the_full_integral_pid_has_scdc_peak_sensitivity_on_every_mode_within_one_percent(name):
    sc = load(ROOT / "scenarios" / f"{name}.toml")
    runs = compare_runs(sc)
    full = runs["pid-dc-full"].controller
    assert full["ki_c"] == full["ki_d"] > 0.0
    freqs = analysis.frequency_grid(sc.step)
    scdc, pid = mode_peaks(runs["sc-dc"], freqs), mode_peaks(runs["pid-dc-full"], freqs)
    for mode in MODES:
        assert abs(pid[mode] - scdc[mode]) <= 0.01 * scdc[mode], (mode, pid, scdc)


def test_an_unstable_scdc_loop_keeps_the_mode_matched_gains_and_says_why():
    sc = load(ROOT / "scenarios" / "paper_simulation.toml", ['gains="paper_simulation"'])  # Eq. 40 at 0.1 ms
    m = robustness_matched(sc)
    assert m.note.startswith("SC-DC's sampled loop is not stable, spectral radius 39.")
    assert "not tuned" in m.text()


# --- disk margins, the all-loops gain margin, delay margins, the slowest actuator -------------------

def test_the_disk_margin_of_a_sampled_double_integrator_under_deadbeat_pd_is_two_sevenths():
    # x = (p, v), ZOH step h, w = -(kp p + kd v) with kp h^2 = 1, kd h = 3/2 (closed loop z^2, deadbeat):
    # 1 + L = z^2 / (z - 1)^2, so |S - 1/2| = |z^2/2 - 2 z + 1| and its square on the unit circle is
    # 2 cos^2 - 6 cos + 4.25, largest at z = -1: 3.5. alpha = 1/3.5 = 2/7; disk gain (2 + alpha)/(2 - alpha)
    # = 4/3 (lower 3/4), disk phase 2 atan(1/7).
    h = 1e-3
    A = np.array([[1.0, h], [0.0, 1.0]])
    B = np.array([[h * h / 2.0], [h]])
    C = -np.array([[1.0 / h ** 2, 1.5 / h]])
    freqs = analysis.frequency_grid(h, 0.1, None, 50)
    r = analysis.disk_margin(A, B, C, np.zeros((1, 1)), h, freqs)
    assert r["disk_margin"] == pytest.approx(2.0 / 7.0, rel=1e-9)
    assert (r["disk_gm"], r["disk_gm_lower"]) == (pytest.approx(4.0 / 3.0), pytest.approx(0.75))
    assert r["disk_pm_deg"] == pytest.approx(np.degrees(2.0 * np.arctan(1.0 / 7.0)))
    assert r["disk_f_hz"] == pytest.approx(0.5 / h)
    # three such loops side by side: perturbing all three at once costs nothing (decoupled channels),
    # a coupling that mixes them does
    A3, B3, C3 = np.kron(np.eye(3), A), np.kron(np.eye(3), B), np.kron(np.eye(3), C)
    assert analysis.disk_margin(A3, B3, C3, np.zeros((3, 3)), h, freqs)["disk_margin"] == pytest.approx(2.0 / 7.0)
    mix = np.eye(3) + 0.3 * (np.ones((3, 3)) - np.eye(3))
    coupled = analysis.disk_margin(A3, B3, mix @ C3, np.zeros((3, 3)), h, freqs)["disk_margin"]
    single = min(analysis.disk_margin(A3, B3[:, [i]], mix[[i]] @ C3, np.zeros((1, 1)), h, freqs)["disk_margin"]
                 for i in range(3))
    assert coupled < 2.0 / 7.0 and coupled <= single * (1.0 + 1e-9)


def test_the_disk_margin_agrees_with_python_control_for_one_loop():
    import control
    sc = load(ROOT / "scenarios" / "paper_simulation.toml")
    split = analysis.SplitLoop(sc)
    G = split.loop(analysis.break_directions()["diff. Z"])
    freqs = analysis.frequency_grid(sc.step, 1.0, None, 2000)
    ours = analysis.disk_margin(G.A, G.B, G.C, G.D, sc.step, freqs)
    dm, _, _ = control.disk_margins(-control.ss(*G), 2.0 * np.pi * freqs[:-1], skew=0.0)  # python-control: below Nyquist
    assert ours["disk_margin"] <= dm * (1.0 + 1e-9) and ours["disk_margin"] == pytest.approx(dm, rel=1e-3)


def _kt_scaled(sc, k):
    """The scenario with the controller's K_T divided by k: its feedback force (F = u / K_T, the
    feedforward K_T u_d / K_T unchanged) scaled by k on all three motors."""
    g = sc.gain_values()
    return sc.with_changes(gain_overrides=dict(sc.gain_overrides, K_T=[x / k for x in g.K_T]))


@pytest.mark.parametrize("name, law", [("paper_simulation", "sc-dc"), ("paper_simulation", "pid-dc-full"),
                                       ("paper_experiment_calibrated", "sc-dc")])
def test_the_all_loops_gain_margins_are_where_the_checks_spectral_radius_crosses_one(name, law):
    sc = compare_runs(load(ROOT / "scenarios" / f"{name}.toml"))[law]
    r = analysis.all_loops_gain_margin(analysis.SplitLoop(sc))
    def rho(k):
        return check(_kt_scaled(sc, k)).spectral_radius

    k = r["gm_upper"]
    assert k > 1.0 and rho(0.999 * k) < 1.0 < rho(1.001 * k)
    assert r["kt_error_pct"][1] == pytest.approx(100 * (k - 1))
    k = r["gm_lower"]
    if k is None:  # stable down to the search's end
        assert rho(analysis.GAIN_SPAN[0]) < 1.0 and r["kt_error_pct"][0] is None
    else:
        assert k < 1.0 and rho(1.001 * k) < 1.0 < rho(0.999 * k)
        assert r["kt_error_pct"][0] == pytest.approx(100 * (k - 1))


class _Inserted:
    """The loop of ``check`` stepped with something inserted between the controller's force and the
    plant, on a state vector: the loop's state (stability.OneStepMap), then ``extra`` states. The
    plant is stepped by its own RK4 over sub-intervals of the step; ``forces(extra, y)`` gives the
    sub-intervals [(duration [s], force [N])] and the extra states at the next step."""

    def __init__(self, sc, n_extra, forces, extra_scale):
        self.m = OneStepMap(sc, linear=True)
        self.n_extra, self.forces, self.extra_scale = n_extra, forces, extra_scale

    def __call__(self, x):
        m, n = self.m, len(self.m.names)
        out, y = m.split_step(x[:n])
        m.plant.state = [float(v) for v in x[:6]]
        t = m.t
        pieces, extra = self.forces(x[n:], y)
        for dt, F in pieces:
            m.plant.step(t, dt, *(float(f) for f in F))
            t += dt
        out[:6] = m.plant.state
        return np.concatenate([out, extra])

    def radius(self):
        m = self.m
        x0 = m.start_state()
        y0 = m.split_step(x0)[1]
        self.y0 = y0
        x0 = np.concatenate([x0, self.start_extra(y0)])
        scale = np.concatenate([m.scale, np.full(self.n_extra, self.extra_scale)])
        J = np.empty((len(x0), len(x0)))
        for j in range(len(x0)):
            d = np.zeros(len(x0))
            d[j] = scale[j]
            J[:, j] = (self(x0 + d) - self(x0 - d)) / 2.0 / scale
        T = linalg.block_diag(invariant_basis(m), np.eye(self.n_extra))
        return float(max(abs(linalg.eigvals(T.T @ J @ T))))


from scipy import linalg  # noqa: E402
from orchestrator.tool.stability import OneStepMap, check, invariant_basis  # noqa: E402


def _delayed(sc, v, delay):
    """The loop with the force in direction v delayed by ``delay`` [s] (whole steps plus a fraction),
    the plant stepped over the fraction under the older command and the rest under the newer."""
    h = sc.step
    m = int(np.floor(delay / h + 1e-12))
    phi = delay / h - m
    v = np.asarray(v, dtype=float)

    def forces(regs, y):  # regs: v^T y of the last m + 1 samples
        yv = float(v @ y)
        hist = [yv, *regs]
        rest = y - v * yv
        pieces = [(phi * h, rest + v * hist[m + 1])] if phi > 0 else []
        return pieces + [((1.0 - phi) * h, rest + v * hist[m])], np.array(hist[:m + 1])

    ins = _Inserted(sc, m + 1, forces, 1e-3)
    ins.start_extra = lambda y0: np.full(m + 1, float(v @ y0))
    return ins.radius()


@pytest.mark.parametrize("law, loop", [("sc-dc", "diff. Z"), ("sc-dc", "common"), ("apd-dc-ms-matched", "motor 1")])
def test_the_delay_margin_is_where_the_loop_with_the_delay_inserted_loses_stability(law, loop):
    sc = compare_runs(load(ROOT / "scenarios" / "paper_simulation.toml"))[law]
    split = analysis.SplitLoop(sc)
    v = analysis.break_directions()[loop]
    tau = analysis.delay_margin(split, v)
    assert sc.step < tau < 20 * sc.step and tau / sc.step % 1 > 0.01  # whole steps plus a fraction
    assert _delayed(sc, v, 0.999 * tau) < 1.0 < _delayed(sc, v, 1.001 * tau)


def _with_actuator(sc, bandwidth, pieces=64):
    """The loop with a first-order actuator per motor: the plant stepped in ``pieces`` sub-steps,
    each under the exact mean of the actuator's force over it."""
    h = sc.step
    a = 2 * np.pi * bandwidth
    dt = h / pieces

    def forces(act, y):
        out, f = [], act.copy()
        for _ in range(pieces):
            e = np.exp(-a * dt)
            mean = y + (f - y) * (1.0 - e) / (a * dt)
            out.append((dt, mean))
            f = y + (f - y) * e
        return out, f

    ins = _Inserted(sc, 3, forces, 1e-3)
    ins.start_extra = lambda y0: np.array(y0, dtype=float)
    return ins.radius()


@pytest.mark.parametrize("law", ["sc-dc", "apd-dc"])
def test_the_lowest_actuator_bandwidth_is_where_the_loop_with_the_actuator_inserted_loses_stability(law):
    sc = compare_runs(load(ROOT / "scenarios" / "paper_simulation.toml"))[law]
    f = analysis.actuator_bandwidth(analysis.SplitLoop(sc))
    assert 10.0 < f < 0.5 / sc.step * 10
    assert _with_actuator(sc, 0.999 * f) > 1.0 > _with_actuator(sc, 1.001 * f)


def _delayed_all(sc, delay):
    """The loop with every motor's force delayed by ``delay`` [s] (whole steps plus a fraction)."""
    h = sc.step
    m = int(np.floor(delay / h + 1e-12))
    phi = delay / h - m

    def forces(regs, y):  # regs: the forces y of the last m + 1 samples, 3 each
        hist = [np.asarray(y, dtype=float)] + [regs[3 * j:3 * j + 3] for j in range(m + 1)]
        pieces = [(phi * h, hist[m + 1])] if phi > 0 else []
        return pieces + [((1.0 - phi) * h, hist[m])], np.concatenate(hist[:m + 1])

    ins = _Inserted(sc, 3 * (m + 1), forces, 1e-3)
    ins.start_extra = lambda y0: np.tile(np.asarray(y0, dtype=float), m + 1)
    return ins.radius()


@pytest.mark.slow
def test_analyze_reports_the_loop_with_a_delay_and_an_actuator_on_every_motor(tmp_path, capsys):
    from orchestrator.cli import main
    code = main(["analyze", str(ROOT / "scenarios" / "paper_simulation.toml"), "--out", str(tmp_path),
                 "--points", "40", "--delay", "1.3e-4", "--actuator-bandwidth", "600"])
    assert code == 0
    out = capsys.readouterr().out
    assert "with a delay of 0.00013 s on every motor's force and a first-order actuator of 600 Hz on every motor" in out
    runs = compare_runs(load(ROOT / "scenarios" / "paper_simulation.toml"))
    for name in ("sc-dc", "apd-dc"):
        line = next(x for x in out.splitlines() if x.startswith(f"  {name}: "))
        delay = float(line.split("delay ")[1].split()[0])
        actuator = float(line.split("actuator ")[1].split()[0])
        assert delay == pytest.approx(_delayed_all(runs[name], 1.3e-4), abs=2e-6)
        assert actuator == pytest.approx(_with_actuator(runs[name], 600.0), abs=2e-6)
    # SC-DC needs more than 600 Hz (its lowest bandwidth is about 825 Hz); APD-DC does not
    assert "sc-dc: delay" in out and "actuator" in out
    sc_line = next(x for x in out.splitlines() if x.startswith("  sc-dc: "))
    apd_line = next(x for x in out.splitlines() if x.startswith("  apd-dc: "))
    assert sc_line.endswith("(unstable)") and apd_line.endswith("(stable)")


@pytest.mark.parametrize("option, value, allowed", [("--delay", "-1e-4", "a delay >= 0 s"),
                                                    ("--delay", "nan", "a delay >= 0 s"),
                                                    ("--actuator-bandwidth", "-5", "a bandwidth > 0 Hz (finite)"),
                                                    ("--actuator-bandwidth", "inf", "a bandwidth > 0 Hz (finite)")])
def test_a_negative_delay_or_bandwidth_is_one_line_naming_it(tmp_path, capsys, option, value, allowed):
    from orchestrator.cli import main
    assert main(["analyze", str(ROOT / "scenarios" / "paper_simulation.toml"), "--out", str(tmp_path / "a"),
                 f"{option}={value}"]) == 2  # one argument: argparse would read -1e-4 as an option
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"error: {option} = {float(value)!r} is invalid: allowed is {allowed}"]
    assert not (tmp_path / "a").exists()


@pytest.mark.slow
def test_the_robustness_table_gives_the_all_motor_delay_margin_beside_the_one_direction_margin():
    runs = compare_runs(load(ROOT / "scenarios" / "paper_simulation.toml"))
    result = analysis.analyze(runs["sc-dc"], None, points=40, runs={k: runs[k] for k in ("sc-dc", "apd-dc")},
                              figures=False)
    table = analysis.robustness_table(result).splitlines()
    assert "| delay margin [ms] (loop) | delay margin, all motors [ms] |" in table[0]
    assert table[1] == "|---" * 7 + "|" and all(len(x.split("|")) == len(table[0].split("|")) for x in table)
    apd = next(x for x in table if x.startswith("| apd-dc |"))
    scdc = next(x for x in table if x.startswith("| sc-dc |"))
    # one delay on every motor at once destabilizes APD-DC sooner than one in its weakest direction
    assert "| 0.4591 (common) | 0.4551 |" in apd
    assert "| 0.1802 (diff. Z) | 0.1802 |" in scdc
    a = result["runs"]["apd-dc"]
    assert a["all_loops"]["delay_margin_all_s"] < min(x["delay_margin_s"] for x in a["loops"].values())
