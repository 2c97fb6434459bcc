"""The drive FMU TAPMP_Drive (fmu_plant/drive.c) through fmpy, in FMI 2.0 and 3.0: equal to an independent
numpy/scipy implementation of its equations, its delay exact in samples, its current loop's step response the
analytic second-order one, its out-of-range settings refused with a log message, its modelDescriptions valid,
and with pass-through settings the closed loop's rows equal to those without it, bit for bit."""

import math

import numpy as np
import pytest
import scipy.linalg
from fmpy import simulate_fmu
from fmpy.validation import validate_fmu

import ctoolchain as toolchain
from tapmp.interface import DRIVE_VARS, allowed_text
from tapmp.models import DRIVE

pytestmark = pytest.mark.slow  # builds the native FMUs

H = 1e-4  # the servo step [s]
FAMILIES = ("fmi2", "fmi3")
SETTINGS = {v.name: v for v in DRIVE_VARS if v.causality == "parameter"}


@pytest.fixture(scope="module")
def native(tmp_path_factory):
    """{family: {model name, "ssp" or "TAPMP_Drive_ssp": path}}: the native FMUs for this host."""
    from orchestrator.builder.build_native import build_native
    return build_native(tmp_path_factory.mktemp("native"), log=lambda *_: None, platforms=(toolchain.HOST,))


def fmu_outputs(path, commands, **settings) -> np.ndarray:
    """The drive FMU's forces F1..F3 after each step of H [s] when it receives ``commands`` (rows of
    F_cmd1..F_cmd3 [N], row k at t_k = k H, held over the step from t_k), with ``settings``."""
    n = len(commands)
    signals = np.array([(k * H, *row) for k, row in enumerate(commands)],
                       dtype=[("time", float)] + [(f"F_cmd{i}", float) for i in (1, 2, 3)])
    res = simulate_fmu(str(path), start_time=0.0, stop_time=n * H, step_size=H, output_interval=H,
                       input=signals, output=["F1", "F2", "F3"], start_values=settings, validate=False)
    assert len(res) == n + 1
    return np.array([[res[f"F{i}"][k] for i in (1, 2, 3)] for k in range(1, n + 1)])


def reference_outputs(commands, delay_samples=1, current_bandwidth=2000.0, current_damping=0.7,
                      force_constant_error=(0.0, 0.0, 0.0), force_limit=600.0) -> np.ndarray:
    """The drive's equations written independently of drive.c: the state (y [N], dy/dt [N/s]) of
    y'' = wn^2 (s - y) - 2 zeta wn y' advanced by scipy's matrix exponential of A h, the input s held over
    the step (Bd = A^-1 (Ad - I) B), the output the mean of y over the step by the closed-form integral
    (1/h) C A^-1 [(Ad - I) x + (A^-1 (Ad - I) - h I) B s]; at rest on the first command before the start."""
    u = np.asarray(commands, dtype=float)
    gain = 1.0 + np.asarray(force_constant_error)
    limit = (lambda c: np.clip(c, -force_limit, force_limit)) if force_limit > 0 else (lambda c: c)
    delayed = np.vstack([np.repeat(u[:1], delay_samples, axis=0), u])[:len(u)]  # c_k = u_(k-d), u_(<0) = u_0
    s = limit(delayed)
    if current_bandwidth == 0.0:
        return gain * s
    wn = 2 * math.pi * current_bandwidth
    A = np.array([[0.0, 1.0], [-wn**2, -2 * current_damping * wn]])
    B = np.array([0.0, wn**2])
    Ad = scipy.linalg.expm(A * H)
    Ai = np.linalg.inv(A)
    Bd = Ai @ (Ad - np.eye(2)) @ B
    Mx = (Ai @ (Ad - np.eye(2)))[0] / H                        # mean of y from the state
    Ms = (Ai @ (Ai @ (Ad - np.eye(2)) - H * np.eye(2)) @ B)[0] / H  # ... and from the held input
    out = np.empty_like(s)
    for i in range(3):
        x = np.array([limit(u[0, i]), 0.0])
        for k in range(len(u)):
            out[k, i] = gain[i] * (Mx @ x + Ms * s[k, i])
            x = Ad @ x + Bd * s[k, i]
    return out


def commands(n=400, seed=7) -> np.ndarray:
    """Seeded commands [N] of three motors: steps and a sinusoid, some beyond a 300 N limit."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * H
    steps = np.repeat(rng.uniform(-450.0, 450.0, size=(n // 50, 3)), 50, axis=0)
    return steps + 80.0 * np.sin(2 * math.pi * 230.0 * t)[:, None]


@pytest.mark.parametrize("family", FAMILIES)
@pytest.mark.parametrize("delay", [0, 1, 2, 3])
def test_the_drive_equals_an_independent_implementation_of_its_equations(native, family, delay):
    u = commands()
    settings = dict(delay_samples=delay, current_bandwidth=1500.0, current_damping=0.6,
                    force_constant_error=(0.05, -0.03, 0.1), force_limit=300.0)
    got = fmu_outputs(native[family][DRIVE], u, **{k: v for k, v in settings.items() if k != "force_constant_error"},
                      **{f"force_constant_error{i}": e for i, e in enumerate(settings["force_constant_error"], 1)})
    expected = reference_outputs(u, **settings)
    assert np.any(np.abs(expected) > 300.0)  # a force-constant error of +10 % beyond the 300 N limit: all applied
    # both are exact solutions of the same equations, computed differently (scaling and squaring of a 4 x 4
    # exponential against scipy's expm and a closed-form integral): they differ by rounding, about 1e-15 of
    # the forces per operation over a few hundred operations
    assert np.max(np.abs(got - expected)) <= 1e-9 * np.max(np.abs(expected))


@pytest.mark.parametrize("family", FAMILIES)
@pytest.mark.parametrize("delay", [0, 1, 2, 3])
def test_with_an_ideal_current_loop_the_force_is_the_command_delayed_by_whole_samples(native, family, delay):
    u = commands(200, seed=delay)
    got = fmu_outputs(native[family][DRIVE], u, delay_samples=delay, current_bandwidth=0.0, force_limit=0.0)
    assert np.array_equal(got[delay:], u[:len(u) - delay])
    assert np.array_equal(got[:delay], np.repeat(u[:1], delay, axis=0))  # at rest on the first command before


def analytic_step_mean(k: int, amplitude: float, fn: float, zeta: float) -> float:
    """The mean over [k H, (k + 1) H] of the underdamped second-order step response
    y(t) = A (1 - e^(-zeta wn t) (cos wd t + zeta / sqrt(1 - zeta^2) sin wd t)), from its closed-form
    integral A (t - 2 zeta / wn + e^(-zeta wn t) ((2 zeta / wn) cos wd t + ((2 zeta^2 - 1) / wd) sin wd t))."""
    wn = 2 * math.pi * fn
    wd = wn * math.sqrt(1 - zeta**2)

    def integral(t):
        return t - 2 * zeta / wn + math.exp(-zeta * wn * t) * (2 * zeta / wn * math.cos(wd * t)
                                                               + (2 * zeta**2 - 1) / wd * math.sin(wd * t))
    return amplitude * (integral((k + 1) * H) - integral(k * H)) / H


@pytest.mark.parametrize("family", FAMILIES)
@pytest.mark.parametrize("fn, zeta", [(2000.0, 0.7), (500.0, 0.3)])
def test_the_current_loops_step_response_is_the_analytic_second_order_one(native, family, fn, zeta):
    amplitude, n = 100.0, 80
    u = np.vstack([np.zeros((1, 3)), np.full((n, 3), amplitude)])  # at rest on 0 N, the step at t = H
    got = fmu_outputs(native[family][DRIVE], u, delay_samples=0, current_bandwidth=fn, current_damping=zeta,
                      force_limit=0.0)
    expected = np.array([0.0] + [analytic_step_mean(k, amplitude, fn, zeta) for k in range(n)])
    assert got[0].tolist() == [0.0, 0.0, 0.0]
    if zeta < 0.5:
        assert expected.max() > 1.2 * amplitude  # the light damping overshoots: the response has its shape
    # exact discretization against the closed form: they differ only by rounding (see above)
    assert np.max(np.abs(got - expected[:, None])) <= 1e-10 * amplitude


def outside(v):
    """A value just outside the range of ``v``: above an Integer's max, just below a Real's min."""
    return int(v.max) + 1 if v.type == "Integer" else v.min - 0.01 * max(1.0, abs(v.min))


@pytest.mark.parametrize("family", FAMILIES)
@pytest.mark.parametrize("name", list(SETTINGS))
def test_a_drive_setting_outside_its_range_is_refused_with_an_error_and_a_log_message(native, family, name):
    v = SETTINGS[name]
    value = outside(v)
    messages = []

    def logger(*args):  # FMI 2.0 and 3.0 loggers differ in their leading arguments
        if args[-3] >= 3:
            messages.append(args[-1].decode())
    with pytest.raises(Exception):
        simulate_fmu(str(native[family][DRIVE]), start_values={name: value}, stop_time=H, output_interval=H,
                     logger=logger, validate=False)
    assert any(f"{name} = {value!r} is invalid: allowed is {allowed_text(v)}" in m for m in messages), messages


@pytest.mark.parametrize("family", FAMILIES)
def test_the_drive_fmu_and_its_ssp_are_valid(native, family):
    from fmpy.ssp.ssd import read_ssd
    assert validate_fmu(str(native[family][DRIVE])) == []
    ssd = read_ssd(str(native[family][f"{DRIVE}_ssp"]))  # validated against the SSP 1.0 schema
    assert [e.name for e in ssd.system.elements] == ["trajectory", "controller", "drive", "plant"]
    wires = {(c.startElement, c.startConnector, c.endElement, c.endConnector) for c in ssd.system.connections}
    for i in (1, 2, 3):
        assert ("controller", f"F{i}", "drive", f"F_cmd{i}") in wires and ("drive", f"F{i}", "plant", f"F{i}") in wires
        assert ("controller", f"F{i}", "plant", f"F{i}") not in wires


COLUMNS = [f"plant.{n}" for n in ("q1", "q2", "q3", "q1_true", "q2_true", "q3_true", "X", "Z", "B")] + \
    [f"controller.F{i}" for i in (1, 2, 3)]


@pytest.mark.parametrize("family", FAMILIES)
def test_a_pass_through_drive_gives_the_rows_of_the_loop_without_it_bit_for_bit(native, family):
    from orchestrator.tool.scenario import DRIVE_ORDER
    from tests.support.runs import orchestrator_rows, paper_scenario
    without = paper_scenario(0.05)
    through = paper_scenario(0.05, "drive.delay_samples=0", "drive.current_bandwidth=0.0",
                             "drive.force_limit=0.0")
    plain = orchestrator_rows(native[family]["ssp"], without, COLUMNS, ordering="gauss-seidel")
    driven = orchestrator_rows(native[family][f"{DRIVE}_ssp"], through, COLUMNS + ["drive.F1"],
                               ordering="gauss-seidel", order=DRIVE_ORDER)
    assert np.array_equal(plain, driven[:, :-1])
    assert np.array_equal(driven[1:, -1], driven[1:, COLUMNS.index("controller.F1")])  # the force is the command
    assert np.max(np.abs(plain[:, 0])) > 1e-3  # the platform moved


@pytest.mark.parametrize("family", FAMILIES)
def test_the_default_drive_delays_the_command_by_one_sample(native, family):
    from orchestrator.tool.scenario import DRIVE_ORDER
    from tests.support.runs import orchestrator_rows, paper_scenario
    sc = paper_scenario(0.01, "drive.current_bandwidth=0.0")  # the default drive with an ideal current loop
    rows = orchestrator_rows(native[family][f"{DRIVE}_ssp"], sc, ["controller.F1", "drive.F1"],
                             ordering="gauss-seidel", order=DRIVE_ORDER)
    assert np.array_equal(rows[2:, 1], rows[1:-1, 0]) and rows[1, 1] == rows[0, 0]


@pytest.mark.parametrize("family", FAMILIES)
def test_the_drive_carries_a_reference_experiment_fmpy_replays_and_its_documentation(native, family, tmp_path):
    import html
    import zipfile

    from fmpy.util import read_csv
    from orchestrator.builder import fmu_extras
    fmu = native[family][DRIVE]
    ref = f"{fmu_extras.LS_REF}/{fmu_extras.SCENARIO}"
    with zipfile.ZipFile(fmu) as z:
        z.extractall(tmp_path)
        page = z.read("documentation/index.html").decode()
        diagram = z.read("documentation/diagram.svg").decode()
    for v in DRIVE_VARS:
        assert f"<code>{v.name}</code>" in page
    assert html.escape("y'' = w_n^2 (s - y) - 2 zeta w_n y'") in page and ">TAPMP_Drive</text>" in diagram
    names, expected = fmu_extras.read_csv((tmp_path / f"{ref}_ref.csv").read_bytes())
    res = simulate_fmu(str(fmu), stop_time=fmu_extras.REFERENCE_STOP, step_size=H, output_interval=H,
                       input=read_csv(str(tmp_path / f"{ref}_in.csv")))
    assert [list(r) for r in res] == expected  # the same doubles
    assert max(abs(x) for row in expected for x in row[1:]) > 1.0  # the stimulus is the controller's commands


@pytest.mark.parametrize("law", ["sc-dc", "apd-dc"])
def test_a_pass_through_drive_reproduces_the_stored_reference_run(native, law):
    """tests/data/reference_run.csv's Gauss-Seidel cases (tests/engine/test_reference_run.py, the same 1e-12 m)
    through TAPMP_Drive.ssp with the drive passing the commands through."""
    from tests.engine.test_reference_run import reference_run, stored
    from tests.support.runs import orchestrator_rows, paper_scenario
    from orchestrator.tool.scenario import DRIVE_ORDER
    sc = paper_scenario(reference_run.STOP, f"law={law!r}", "drive.delay_samples=0", "drive.current_bandwidth=0.0")
    rows = orchestrator_rows(native["fmi2"][f"{DRIVE}_ssp"], sc, ["time", *reference_run.SIGNALS],
                             ordering="gauss-seidel", order=DRIVE_ORDER)[::reference_run.EVERY]
    expected = np.array(stored(law, "gauss-seidel"))
    assert rows.shape == expected.shape == (201, 5)
    assert np.max(np.abs(rows[:, 1:] - expected[:, 1:])) <= 1e-12
    assert np.max(np.abs(expected[:, 1:4])) > 1e-3  # the platform did move
