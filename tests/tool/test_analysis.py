"""`tapmp analyze`: the sampled loop broken at the plant input, its margins and frequency
responses, checked against the stability pre-check's eigenvalues, a textbook loop derived by
hand, and co-simulations through the native FMUs driven by a sinusoidal force disturbance."""

import json
import math

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
from scipy import linalg
from scipy.optimize import brentq

from orchestrator.cli import main
from orchestrator.tool.analysis import (BREAK_POINTS, SplitLoop, analyze, break_directions, frequency_grid,
                                               margins)
from orchestrator.tool.scenario import ScenarioError, load
from orchestrator.tool.stability import OneStepMap, invariant_basis, check

from tests.support.runs import PAPER

# The paper scenario without the nonlinear parts, resting at the home pose: the loop the
# linearization describes exactly, for the co-simulation comparison.
LINEAR = ["plant.encoder_resolution=0.0", "plant.F_c1=0.0", "plant.F_c2=0.0", "plant.F_c3=0.0",
          "plant.force_limit=0.0", "trajectory.radius=0.0", "trajectory.Z_c=0.0", "trajectory.B_amplitude=0.0",
          "trajectory.f_xz=0.0", "trajectory.f_B=0.0"]


def scaled_radius(scenario, v, k: float) -> float:
    """Spectral radius of the loop whose plant-input force in direction v is scaled by k about the
    operating force F0 (the command at the linearization point: F = F0 + P (F_ctrl - F0)), from the
    stability pre-check's own one-step map, Jacobian, invariant subspace and eigenvalues."""
    m = OneStepMap(scenario, linear=True)
    step = m.plant.step
    x0 = m.start_state()
    seen = []
    m.plant.step = lambda t, h, *F: (seen.append(np.array(F)), step(t, h, *F))[1]
    m(x0)
    F0 = seen[0]
    P = np.eye(3) + (k - 1.0) * np.outer(v, v)
    m.plant.step = lambda t, h, *F: step(t, h, *(F0 + P @ (np.array(F) - F0)))
    T = invariant_basis(m)
    return float(max(abs(linalg.eigvals(T.T @ m.jacobian(x0) @ T))))


@pytest.mark.slow
@pytest.mark.parametrize("law,ordering", [("sc-dc", "gauss-seidel"), ("apd-dc", "gauss-seidel"), ("sc-dc", "jacobi")])
def test_gain_margin_of_every_break_point_is_where_the_spectral_radius_crosses_one(law, ordering):
    sc = load(PAPER, [f'law="{law}"', f'ordering="{ordering}"'])
    split = SplitLoop(sc)
    assert check(sc).spectral_radius == pytest.approx(max(abs(linalg.eigvals(split.closed_loop()))), abs=1e-8)
    for name, v in break_directions().items():
        r = margins(-split.loop(v), sc.step)
        assert 1.0 < r["gm"] < math.inf, name
        assert scaled_radius(sc, v, r["gm"] * (1.0 - 1e-3)) < 1.0 < scaled_radius(sc, v, r["gm"] * (1.0 + 1e-3)), name
        if r["gm_lower"] is not None:  # a loop that goes unstable when its gain drops (the integral of c)
            g = r["gm_lower"]
            assert scaled_radius(sc, v, g * (1.0 + 1e-3)) < 1.0 < scaled_radius(sc, v, g * (1.0 - 1e-3)), name


@pytest.mark.slow
def test_margins_of_a_sampled_double_integrator_under_pd_match_the_hand_derivation():
    # Plant 1/(m s^2) behind a zero-order hold: P(z) = h^2 (z + 1) / (2 m (z - 1)^2). Controller
    # kp + kd (1 - 1/z) / h (backward difference), no extra delay. With alpha = kp h + kd,
    # L(z) = h (z + 1)(alpha z - kd) / (2 m z (z - 1)^2). On z = exp(j 2x):
    # L = -K(x) (alpha e^{-jx} - kd e^{-j3x}), K(x) = h cos(x) / (4 m sin(x)^2) > 0.
    # Im L = 0  <=>  kd sin(3x) = alpha sin(x)  <=>  sin(x)^2 = (2 - kp h / kd) / 4, where
    # L = -K 2 kd cos(x), so GM = 2 m sin(x)^2 / (h kd cos(x)^2) at f = 2x / (2 pi h).
    # PM = arg(alpha e^{-jx} - kd e^{-j3x}) at |L| = 1.
    import control
    m, h, kp, kd = 2.0, 1e-3, 2.0e4, 300.0
    alpha = kp * h + kd
    L = control.tf([h / (2 * m) * alpha, h / (2 * m) * (alpha - kd), -h / (2 * m) * kd], [1.0, -2.0, 1.0, 0.0], h)
    x_pc = math.asin(math.sqrt((2.0 - kp * h / kd) / 4.0))
    gm = 2 * m * math.sin(x_pc) ** 2 / (h * kd * math.cos(x_pc) ** 2)

    def w(x):
        return alpha * np.exp(-1j * x) - kd * np.exp(-3j * x)

    def mag(x):
        return h * math.cos(x) / (4 * m * math.sin(x) ** 2) * abs(w(x))

    x_gc = brentq(lambda x: mag(x) - 1.0, 1e-6, x_pc, xtol=1e-15)
    pm = math.degrees(np.angle(w(x_gc)))
    r = margins(L, h)
    assert r["gm"] == pytest.approx(gm, rel=1e-6)
    assert r["f_pc_hz"] == pytest.approx(2 * x_pc / (2 * math.pi * h), rel=1e-6)
    assert r["pm_deg"] == pytest.approx(pm, rel=1e-6)
    assert r["f_gc_hz"] == pytest.approx(2 * x_gc / (2 * math.pi * h), rel=1e-6)
    assert r["gm_lower"] is None
    assert 5.0 < gm < 50.0 and 20.0 < pm < 80.0  # a loop with real margins, not a degenerate case


@pytest.fixture(scope="module")
def native_fmi2(tmp_path_factory):
    from orchestrator.builder.build_native import build_native
    return build_native(tmp_path_factory.mktemp("native_an"), families=("fmi2",), log=lambda *_: None,
                        windows=False)["fmi2"]


class Unit:
    """One native FMU instance through fmpy, parameters by name."""

    def __init__(self, path, tmp, name):
        self.md = read_model_description(str(path))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.types = {v.name: v.type for v in self.md.modelVariables}
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=extract(str(path), str(tmp / name)),
                             modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=name)
        self.fmu.instantiate()

    def set(self, values):
        for k, v in values.items():
            if self.types[k] == "Integer":
                self.fmu.setInteger([self.vr[k]], [int(v)])
            elif self.types[k] == "Boolean":
                self.fmu.setBoolean([self.vr[k]], [bool(v)])
            else:
                self.fmu.setReal([self.vr[k]], [float(v)])

    def get(self, names):
        return np.array(self.fmu.getReal([self.vr[n] for n in names]))


def cosimulate(paths, scenario, v, f, amplitude, n_settle, n_measure, tmp):
    """Gauss-Seidel co-simulation of the three native FMUs with the force d = amplitude
    sin(2 pi f t) v added to the controller's command at the plant input; returns the
    recorded (time, d, total plant force along v, tracking error along v) of the last n_measure
    steps (e = q_d - q_true of the FMUs' outputs)."""
    par = scenario.parameters()
    units = {e: Unit(paths[m], tmp, e) for e, m in (("trajectory", "TAPMP_Trajectory"),
                                                     ("controller", "TAPMP_Controller"), ("plant", "TAPMP_Plant"))}
    for e, u in units.items():
        u.set(par[e])
        u.fmu.setupExperiment(startTime=scenario.start_time)
        u.fmu.enterInitializationMode()
    refs = ["X_d", "Z_d", "B_d", "dX_d", "dZ_d", "dB_d", "ddX_d", "ddZ_d", "ddB_d"]
    qs = [f"q{i}" for i in (1, 2, 3)]
    dqs = [f"dq{i}" for i in (1, 2, 3)]
    tr, ct, pl = units["trajectory"], units["controller"], units["plant"]

    def connect():
        ct.set(dict(zip(refs, tr.get(refs))))
        ct.set(dict(zip(qs + dqs, pl.get(qs + dqs))))

    connect()
    for u in units.values():
        u.fmu.exitInitializationMode()
    h, t = scenario.step, scenario.start_time
    rows = []
    for k in range(n_settle + n_measure):
        t = scenario.start_time + k * h
        connect()
        ct.fmu.doStep(t, h)
        d = amplitude * math.sin(2 * math.pi * f * t)
        F = ct.get(["F1", "F2", "F3"]) + d * v
        pl.set({"F1": F[0], "F2": F[1], "F3": F[2]})
        if k >= n_settle:  # e at t: recorded before the step, with the plant's state at t
            e = tr.get(["q1_d", "q2_d", "q3_d"]) - pl.get(["q1_true", "q2_true", "q3_true"])
            rows.append((t, d, float(v @ F), float(v @ e)))
        pl.fmu.doStep(t, h)
        tr.fmu.doStep(t, h)
    for u in units.values():
        u.fmu.terminate()
        u.fmu.freeInstance()
    return np.array(rows)


def phasor(t, x, f):
    """Complex amplitude of x at f (x ~ Re(X e^{j 2 pi f t}) + offset), over whole periods."""
    c, s = np.cos(2 * math.pi * f * t), np.sin(2 * math.pi * f * t)
    a, b, _ = np.linalg.lstsq(np.stack([c, s, np.ones_like(t)], axis=1), x, rcond=None)[0]
    return a - 1j * b


@pytest.mark.slow
@pytest.mark.parametrize("point,f", [("motor 1", 20.0), ("diff. B", 200.0), ("common", 1000.0),
                                     ("diff. Z", 50.0)])
def test_frequency_response_equals_a_cosimulation_through_the_fmus(native_fmi2, tmp_path, point, f):
    sc = load(PAPER, LINEAR)
    v = break_directions()[point]
    result = analyze(sc, None, f_min=f, f_max=f * 1.001, points=2, runs={"sc-dc": sc})
    loop = result["runs"]["sc-dc"]["loops"][point]["response"]
    S, E = loop["S"][0], loop["e_per_d"][0]
    per = round(1.0 / (f * sc.step))  # steps per period (whole)
    n_measure = per * max(1, round(0.05 * f))
    rows = cosimulate(native_fmi2, sc, v, f, 1.0, 3000, n_measure, tmp_path)
    t, d, w, e = rows.T
    D = phasor(t, d, f)
    S_sim, E_sim = phasor(t, w, f) / D, phasor(t, e, f) / D
    assert abs(S_sim - S) <= 0.02 * abs(S), (S_sim, S)
    assert abs(E_sim - E) <= 0.02 * abs(E), (E_sim, E)


@pytest.mark.slow
def test_analyze_writes_json_figures_and_prints_the_table(tmp_path, capsys):
    out = tmp_path / "an"
    code = main(["analyze", str(PAPER), "--out", str(out), "--points", "60", "--f-min", "1", "--responses"])
    assert code == 0
    text = capsys.readouterr().out
    assert "| sc-dc | diff. B |" in text and "| sc-dc-lp0 | common |" in text
    data = json.loads((out / "analysis.json").read_text())
    assert data["frequency_grid"] == {"from_hz": 1.0, "to_hz": pytest.approx(5000.0), "points": 60,
                                      "spacing": "logarithmic"}
    assert set(data["runs"]) == {"sc-dc", "apd-dc", "apd-dc-matched", "apd-dc-diff-stiffness", "apd-dc-mode-matched",
                                 "apd-dc-ms-matched", "pid-dc-mode-matched", "pid-dc-full", "sc-dc-b0", "sc-dc-lp0"}
    scdc = data["runs"]["sc-dc"]
    assert set(scdc["loops"]) == set(BREAK_POINTS)
    import csv
    with open(out / "frequency_response.csv") as f:
        rows = list(csv.reader(f))
    assert len(rows) == 61 and len(rows[0]) == 1 + 10 * 6 * 4 * 2
    col = rows[0].index("sc-dc|common|L|mag")
    # the magnitude of L crosses 1 at the reported gain crossover
    f = np.array([float(r[0]) for r in rows[1:]])
    mag = np.array([float(r[col]) for r in rows[1:]])
    k = np.nonzero(mag < 1.0)[0][0]
    assert f[k - 1] < scdc["loops"]["common"]["f_gc_hz"] <= f[k]
    # SC-DC equals its mode-matched PID form for uniform gains: the same margins
    for b in BREAK_POINTS:
        assert data["runs"]["pid-dc-mode-matched"]["loops"][b]["gm"] == pytest.approx(scdc["loops"][b]["gm"], rel=1e-6)
    for name in ("analysis_loop_modes.png", "analysis_loop_motors.png", "analysis_sensitivity_modes.png",
                 "analysis_disturbance.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # every closed-loop pole: f_n >= 0 and a damping in [-1, 1]; the spectral radius as check's
    assert all(p["f_n_hz"] >= 0 and -1.0 <= p["zeta"] <= 1.0 for p in scdc["poles"])
    assert scdc["spectral_radius"] == pytest.approx(check(load(PAPER)).spectral_radius, abs=1e-8)
    # the robustness table: one row per run with the numbers of analysis.json
    a = scdc["all_loops"]
    row = next(x for x in text.splitlines() if x.startswith("| sc-dc | ") and "x (" in x)
    assert f"{a['disk_margin']:.3f} ({a['disk_gm_db']:.2f}, {a['disk_pm_deg']:.1f})" in row
    assert f"{a['gm_upper']:.3g}x ({a['kt_error_pct'][1]:+.0f} %)" in row
    assert f"| {a['actuator_bandwidth_hz']:.4g} |" in row
    assert all(0 < scdc["loops"][b]["delay_margin_s"] < 1e-2 for b in BREAK_POINTS)


@pytest.mark.parametrize("args,message", [
    (["--f-max", "6000"], "error: --f-max = 6000.0 is invalid: allowed is a frequency in (0, 5000] Hz"),
    (["--f-min", "0"], "error: --f-min = 0.0 is invalid: allowed is a frequency in (0, 5000] Hz"),
    (["--f-min", "-1"], "error: --f-min = -1.0 is invalid: allowed is a frequency in (0, 5000] Hz"),
    (["--f-max", "nan"], "error: --f-max = nan is invalid: allowed is a frequency in (0, 5000] Hz"),
    (["--f-min", "100", "--f-max", "10"], "error: --f-min = 100.0 is invalid: allowed is a frequency below"),
    (["--points", "1"], "error: --points = 1 is invalid: allowed is an integer from 2 to 100000"),
    (["--points", "99999999999999999999"], "error: --points = 99999999999999999999 is invalid: allowed is an integer "
                                          "from 2 to 100000"),
])
def test_a_bad_frequency_grid_is_one_line_and_exit_2(tmp_path, capsys, args, message):
    code = main(["analyze", str(PAPER), "--out", str(tmp_path / "x"), *args])
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith(message) and err.count("\n") == 1, err
    assert not (tmp_path / "x").exists()


def test_frequency_grid_reaches_nyquist_exactly():
    f = frequency_grid(1e-4, 1.0, None, 5)
    assert f[0] == 1.0 and f[-1] == pytest.approx(5000.0, rel=1e-15)
    with pytest.raises(ScenarioError):
        frequency_grid(1e-4, 1.0, 5000.1, 5)


@pytest.mark.slow
def test_an_unstable_loop_gets_no_margins():
    sc = load(PAPER, ['gains="paper_simulation"'])  # Eq. 40 at 0.1 ms: unstable (docs/stability.md)
    r = analyze(sc, None, f_min=1.0, points=5, runs={"sc-dc": sc})["runs"]["sc-dc"]
    assert r["verdict"] == "unstable" and r["spectral_radius"] == pytest.approx(check(sc).spectral_radius, rel=1e-6)
    assert all(x["gm"] is None and x["pm_deg"] is None and x["Ms"] is None for x in r["loops"].values())
