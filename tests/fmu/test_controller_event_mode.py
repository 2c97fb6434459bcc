"""The native FMI 3.0 controller in Event Mode: every sample instant t0 + k T_s is a time event,
doStep returns early there, and the controller samples in fmi3UpdateDiscreteStates, so a host
with any step, or a variable one, gets every sample (FMPy, fmusim, and call by call)."""

import csv
import math
import subprocess
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi3 import FMU3Slave
from fmpy.validation import validate_fmu

from tapmp.interface import CONTROLLER, VARIABLES
from tapmp.control import ControllerModel, Gains
from tapmp.params import PAPER_MODEL, gain_preset

pytestmark = pytest.mark.slow  # builds the FMI 3.0 FMUs (zig cc); fmusim runs as a child process

ROOT = Path(__file__).resolve().parents[2]
FMUSIM = ROOT.parent / "shared" / "tools" / "fmusim" / "bin" / "fmusim"
T_S = 1e-4
STOP = 0.02                       # 200 sample instants after the one at t = 0
OUTPUTS = ("F1", "F2", "F3", "u1", "u2", "u3", "e1", "e2", "e3", "es1", "es2", "es3")


def q_of(t):
    """The measured motor positions [m] fed to the controller at time t [s]: smooth, so that the
    backward difference and the integral see every sample."""
    return (1e-3 * math.sin(300.0 * t), -1e-3 * math.sin(200.0 * t), 5e-4 * math.cos(100.0 * t))


@pytest.fixture(scope="module")
def fmu(tmp_path_factory):
    """The native FMI 3.0 controller, built for this machine."""
    from orchestrator.builder.build_native import build_native
    return build_native(tmp_path_factory.mktemp("native"), families=("fmi3",), log=lambda *_: None,
                        windows=False)["fmi3"]["TAPMP_Controller"]


class Run:
    """One instance driven call by call: the outputs at every communication point (before any
    event there), the samples taken (time, outputs after the event) and the log."""

    def __init__(self, fmu, tmp, event_mode, early_return=True, name="c"):
        self.md = read_model_description(str(fmu))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.slave = FMU3Slave(guid=self.md.guid, unzipDirectory=extract(str(fmu), unzipdir=str(tmp / name)),
                               modelIdentifier="TAPMP_Controller", instanceName=name)
        self.log = []
        self.slave.instantiate(loggingOn=True, eventModeUsed=event_mode, earlyReturnAllowed=early_return,
                               logMessage=lambda env, status, category, message:
                               self.log.append((status, message.decode())))
        self.event_mode = event_mode
        self.points, self.samples = [], []
        self.out_vrs = [self.vr[n] for n in OUTPUTS]

    def inputs(self, t):
        self.slave.setFloat64([self.vr[n] for n in ("q1", "q2", "q3")], list(q_of(t)))

    def outputs(self):
        return tuple(self.slave.getFloat64(self.out_vrs))

    def event(self, t):
        self.slave.enterEventMode()
        self.inputs(t)
        self.update(t)

    def update(self, t):
        before = self.outputs()
        again, _, _, _, defined, next_time = self.slave.updateDiscreteStates()
        assert not again and defined
        self.next_event = next_time
        after = self.outputs()
        if after != before or not self.samples:
            self.samples.append((t, after))
        self.slave.enterStepMode()

    def start(self):
        self.slave.enterInitializationMode(startTime=0.0)
        self.inputs(0.0)
        self.slave.exitInitializationMode()
        if self.event_mode:  # Event Mode after initialization: the sample at t = 0
            self.update(0.0)

    def step_to(self, t, end):
        """doStep from t towards end [s] as FMPy does: an early return ends the step at the event."""
        self.inputs(t)
        event, _, early, last = self.slave.doStep(t, end - t)
        reached = last if early else end
        self.points.append((reached, self.outputs()))
        if self.event_mode and event:
            self.event(reached)
        return reached

    def run(self, grid):
        """The communication points of grid (times [s] after 0), early returns taken."""
        self.start()
        t = 0.0
        for end in grid:
            while t < end and not math.isclose(t, end, rel_tol=0, abs_tol=1e-12):
                t = self.step_to(t, end)
        return self

    def free(self):
        self.slave.terminate()
        self.slave.freeInstance()


def grid(step, stop=STOP):
    n = math.floor(stop / step + 1e-9)
    return [k * step for k in range(1, n + 1)] + ([stop] if not math.isclose(n * step, stop) else [])


def random_partition(seed=1, stop=STOP):
    rng = np.random.default_rng(seed)
    t, points = 0.0, []
    while t < stop:
        t = min(stop, t + rng.uniform(0.1, 9.0) * T_S)
        points.append(t)
    return points


@pytest.fixture(scope="module")
def today(fmu, tmp_path_factory):
    """The run without event mode at host step T_s: the sample of t_k is the output at t_k+1."""
    r = Run(fmu, tmp_path_factory.mktemp("today"), event_mode=False).run(grid(T_S))
    r.free()
    return r


def test_controller_modeldescription_declares_event_mode_and_early_return(fmu):
    md = read_model_description(str(fmu))
    assert md.coSimulation.hasEventMode is True
    assert md.coSimulation.mightReturnEarlyFromDoStep is True
    assert md.coSimulation.canReturnEarlyAfterIntermediateUpdate is False
    assert validate_fmu(str(fmu)) == []


def test_event_mode_at_host_step_T_s_gives_todays_outputs_bit_for_bit(fmu, tmp_path, today):
    r = Run(fmu, tmp_path, event_mode=True).run(grid(T_S))
    assert [t for t, _ in r.samples] == [k * T_S for k in range(len(r.samples))]
    assert len(r.samples) == 201  # t = 0 and the 200 instants after it, the last one at the stop time
    assert r.points == today.points  # before the event at each t_k: the command of t_k-1, as today
    # the command of the sample at t_k, published at t_k in Event Mode, is today's output at t_k+1
    assert [out for _, out in r.samples[:-1]] == [out for _, out in today.points]
    assert r.log == []
    r.free()


@pytest.mark.parametrize("partition", ["2.5 T_s", "7 T_s", "random"])
def test_event_mode_samples_every_instant_whatever_the_host_step(fmu, tmp_path, today, partition):
    points = {"2.5 T_s": grid(2.5 * T_S), "7 T_s": grid(7 * T_S), "random": random_partition()}[partition]
    r = Run(fmu, tmp_path, event_mode=True).run(points)
    times = [t for t, _ in r.samples]
    assert len(times) == 201 and np.allclose(times, [k * T_S for k in range(201)], rtol=0, atol=1e-15)
    assert r.log == []  # no skipped-sample warning, nothing else
    expected = dict((round(t / T_S), out) for t, out in today.points)
    for t, out in r.points:  # at a host point on an instant k: the command of k - 1, as today's
        k = t / T_S
        if abs(k - round(k)) < 1e-6:
            np.testing.assert_allclose(out, expected[round(k)], rtol=1e-12, atol=0)
    for (t, out), (_, ref) in zip(r.samples, today.points):  # the sample of t_k: the T_s run's at t_k+1
        np.testing.assert_allclose(out, ref, rtol=1e-12, atol=0)
    r.free()


def test_event_mode_python_model_samples_as_the_fmu(fmu, tmp_path):
    """ControllerModel.event and next_event_time: the Python model's Event Mode, the same doubles."""
    r = Run(fmu, tmp_path, event_mode=True).run(random_partition(seed=2))
    model = ControllerModel(PAPER_MODEL, Gains.from_preset(gain_preset("default")), T_s=T_S)
    start = [v.start for v in VARIABLES[CONTROLLER] if v.causality == "input"]  # the FMU's unset inputs
    ref, dq = start[:9], start[12:15]
    t, got = 0.0, []
    while t <= STOP + 1e-12:
        assert model.next_event_time() == t
        F, u, e, es = model.event(t, ref, q_of(t), dq)
        got.append((t, (*F, *u, *e, *es)))
        assert model.event(t, ref, q_of(t), dq) is None  # sampled already: held
        t = model.next_event_time()
    assert len(got) == len(r.samples) == 201
    for (t1, a), (t2, b) in zip(got, r.samples):
        assert t1 == pytest.approx(t2, abs=1e-15) and a == b
    r.free()


def test_doStep_past_a_sample_instant_without_early_return_is_refused(fmu, tmp_path):
    r = Run(fmu, tmp_path, event_mode=True, early_return=False)
    r.start()
    with pytest.raises(Exception):
        r.slave.doStep(0.0, 2.5 * T_S)
    assert r.log[-1][1] == ("communicationStepSize = 0.00025 is invalid: allowed is a step that ends at or before "
                            "the next event, t = 0.0001 s (nextEventTime; earlyReturnAllowed is false, so doStep "
                            "cannot stop there; at t = 0.0 s)")
    r.slave.freeInstance()


def test_doStep_with_an_event_pending_is_refused(fmu, tmp_path):
    r = Run(fmu, tmp_path, event_mode=True)
    r.start()
    event, _, early, last = r.slave.doStep(0.0, 2.5 * T_S)
    assert (event, early, last) == (True, True, T_S)
    with pytest.raises(Exception):
        r.slave.doStep(T_S, T_S)
    assert r.log[-1][1] == ("fmi3DoStep at t = 0.0001 s is not allowed: the event at t = 0.0001 s is pending "
                            "(doStep returned eventHandlingNeeded = true): allowed is fmi3EnterEventMode, "
                            "fmi3UpdateDiscreteStates, fmi3EnterStepMode first")
    r.slave.freeInstance()


def test_event_mode_calls_without_eventModeUsed_are_refused(fmu, tmp_path):
    r = Run(fmu, tmp_path, event_mode=False)
    r.start()
    with pytest.raises(Exception):
        r.slave.enterEventMode()
    assert r.log[-1][1] == ("fmi3EnterEventMode is not allowed: the instance was created with eventModeUsed = "
                            "false (allowed: instantiate with eventModeUsed = true)")
    r.slave.freeInstance()


def test_doStep_in_event_mode_is_refused(fmu, tmp_path):
    r = Run(fmu, tmp_path, event_mode=True)
    r.slave.enterInitializationMode(startTime=0.0)
    r.slave.exitInitializationMode()  # now in Event Mode
    with pytest.raises(Exception):
        r.slave.doStep(0.0, T_S)
    assert r.log[-1][1] == ("fmi3DoStep is not allowed in Event Mode: allowed in Step Mode (finish the event first: "
                            "fmi3UpdateDiscreteStates, fmi3EnterStepMode)")
    r.slave.freeInstance()


def _fmpy(fmu, interval, event_mode, inputs):
    return simulate_fmu(str(fmu), stop_time=STOP, output_interval=interval, input=inputs, output=list(OUTPUTS),
                        use_event_mode=event_mode, early_return_allowed=event_mode, fmi_type="CoSimulation")


def _input_signal():
    t = np.linspace(0.0, STOP, 2001)
    signal = np.zeros(len(t), dtype=[("time", float), ("q1", float), ("q2", float), ("q3", float)])
    signal["time"] = t
    signal["q1"], signal["q2"], signal["q3"] = zip(*(q_of(x) for x in t))
    return signal


def _samples(rows):
    """FMPy's rows after each event: the second row at a repeated time."""
    return [tuple(rows[i]) for i in range(1, len(rows)) if rows["time"][i] == rows["time"][i - 1]]


def test_fmpy_simulate_fmu_in_event_mode_samples_every_instant(fmu):
    signal = _input_signal()
    today = _fmpy(fmu, T_S, False, signal)
    at_ts = _fmpy(fmu, T_S, True, signal)
    assert len(_samples(at_ts)) == 200  # every instant after t = 0 (FMPy handles the one at 0 before recording)
    pre = [tuple(r) for i, r in enumerate(at_ts) if i + 1 < len(at_ts) and at_ts["time"][i + 1] == r["time"]]
    assert pre == [tuple(r) for r in today[1:]]  # before each event: today's outputs, bit for bit
    for interval in (2.5 * T_S, 7 * T_S):
        rows = _fmpy(fmu, interval, True, signal)
        samples = _samples(rows)
        assert len(samples) == 200
        by_k = {round(r[0] / T_S): r[1:] for r in _samples(at_ts)}
        for s in samples:
            np.testing.assert_allclose(s[1:], by_k[round(s[0] / T_S)], rtol=1e-12, atol=0)


def _fmusim(fmu, tmp, interval, event_mode):
    """fmusim's rows (time, F1, F2, F3) with constant measured positions (its start values): fmusim
    sets continuous inputs before each doStep only, not in Event Mode (Reference-FMUs v0.0.39), so
    an input file would reach the sample at t_k with the values of the previous communication point."""
    out = tmp / f"out_{interval}_{event_mode}.csv"
    flags = ["--event-mode-used", "--early-return-allowed"] if event_mode else []
    done = subprocess.run([str(FMUSIM), "--interface-type", "cs", "--stop-time", repr(STOP), "--output-interval",
                           repr(interval), *flags, "--start-value", "q1", "0.001", "--start-value", "q2", "-0.001",
                           "--start-value", "q3", "0.0005", "--output-variable", "F1",
                           "--output-variable", "F2", "--output-variable", "F3", "--output-file", str(out), str(fmu)],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    with open(out) as f:
        rows = list(csv.reader(f))[1:]
    return [tuple(float(x) for x in r) for r in rows], done.stdout + done.stderr


@pytest.mark.needs_shared("tools/fmusim/bin/fmusim")
def test_fmusim_in_event_mode_samples_every_instant(fmu, tmp_path):
    today, _ = _fmusim(fmu, tmp_path, T_S, False)
    at_ts, log = _fmusim(fmu, tmp_path, T_S, True)
    assert "Warning" not in log
    pairs = [(at_ts[i], at_ts[i + 1]) for i in range(len(at_ts) - 1) if at_ts[i][0] == at_ts[i + 1][0]]
    assert len(pairs) == 200  # an event at every instant after t = 0
    assert [a[1:] for a, _ in pairs] == [r[1:] for r in today[1:]]  # before each event: today's, bit for bit
    by_k = {round(b[0] / T_S): b[1:] for _, b in pairs}
    for interval in (2.5 * T_S, 7 * T_S):
        rows, log = _fmusim(fmu, tmp_path, interval, True)
        assert "Warning" not in log
        samples = [rows[i + 1] for i in range(len(rows) - 1) if rows[i][0] == rows[i + 1][0]]
        assert len(samples) == 200
        for s in samples:
            np.testing.assert_allclose(s[1:], by_k[round(s[0] / T_S)], rtol=1e-12, atol=0)
