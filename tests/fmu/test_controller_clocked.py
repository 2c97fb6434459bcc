"""The clocked controller (TAPMP_ControllerClocked, FMI 3.0): a periodic input clock `sample_clock` of
interval T_s clocks its outputs; the host activates it in Event Mode at every tick, the controller
samples in fmi3UpdateDiscreteStates and holds its command otherwise. Driven call by call through FMPy's
FMI 3.0 bindings; compared with the Event Mode controller (TAPMP_Controller with eventModeUsed)."""

import math
from ctypes import c_double, c_int, c_uint32, c_uint64
from pathlib import Path
from xml.etree import ElementTree as ET
import zipfile

from tests.interop import compatibility
import numpy as np
import pytest
from tests.support.shared import shared
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi3 import FMU3Slave
from fmpy.validation import validate_fmu

pytestmark = pytest.mark.slow  # builds the FMI 3.0 FMUs (zig cc)

T_S = 1e-4
STOP = 0.02                       # 200 ticks after the one at t = 0
OUTPUTS = ("F1", "F2", "F3", "u1", "u2", "u3", "e1", "e2", "e3", "es1", "es2", "es3")
CLOCKED = "TAPMP_ControllerClocked"


def q_of(t):
    """The measured motor positions [m] at time t [s]: smooth, so that every sample differs."""
    return (1e-3 * math.sin(300.0 * t), -1e-3 * math.sin(200.0 * t), 5e-4 * math.cos(100.0 * t))


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    """The native FMI 3.0 FMUs built for this machine, the clocked controller among them."""
    from orchestrator.builder.build_native import build_native
    return build_native(tmp_path_factory.mktemp("native"), families=("fmi3",), log=lambda *_: None,
                        windows=False)["fmi3"]


class Host:
    """One controller instance driven call by call; `samples` are (t, outputs after the event)."""

    def __init__(self, fmu, tmp, event_mode=True, name="c"):
        self.md = read_model_description(str(fmu))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.log = []
        self.slave = FMU3Slave(guid=self.md.guid, unzipDirectory=extract(str(fmu), unzipdir=str(tmp / name)),
                               modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=name)
        self.slave.instantiate(loggingOn=True, eventModeUsed=event_mode, earlyReturnAllowed=event_mode,
                               logMessage=lambda env, status, category, message:
                               self.log.append((status, message.decode())))
        self.clocked = "sample_clock" in self.vr
        self.samples, self.points = [], []

    def inputs(self, t):
        self.slave.setFloat64([self.vr[n] for n in ("q1", "q2", "q3")], list(q_of(t)))

    def outputs(self):
        return tuple(self.slave.getFloat64([self.vr[n] for n in OUTPUTS]))

    def update(self, t, tick=True):
        """In Event Mode at t: tick the clock (the clocked FMU), inputs, update, outputs, Step Mode."""
        if self.clocked and tick:
            self.slave.setClock([self.vr["sample_clock"]], [True])
        self.inputs(t)
        again, _, _, _, defined, next_time = self.slave.updateDiscreteStates()
        assert not again
        self.next_event = next_time if defined else None
        self.samples.append((t, self.outputs()))
        self.slave.enterStepMode()

    def start(self):
        self.slave.enterInitializationMode(startTime=0.0)
        self.inputs(0.0)
        self.slave.exitInitializationMode()
        self.update(0.0)  # the tick (or time event) at the start time

    def run(self, points):
        """Step through the communication points `points` [s]: the Event Mode controller returns early at
        its time events; the clocked one is stepped to every tick (t0 + k T_s), where the host ticks it."""
        self.start()
        t = 0.0
        ticks = [k * T_S for k in range(1, round(STOP / T_S) + 1)]
        for end in points:
            while t < end - 1e-12:
                target = min([x for x in ticks if x > t + 1e-12] + [end]) if self.clocked else end
                self.inputs(t)
                event, _, early, last = self.slave.doStep(t, target - t)
                t = last if early else target
                self.points.append((t, self.outputs()))
                tick = next((x for x in ticks if abs(t - x) < 1e-12), None) if self.clocked else None
                if tick is not None:
                    t = tick  # the tick's own time k T_s, not a host point an ulp away (the inputs' time)
                if event or tick is not None:
                    self.slave.enterEventMode()
                    self.update(t)
        return self

    def free(self):
        self.slave.terminate()
        self.slave.freeInstance()


def grid(step):
    n = math.floor(STOP / step + 1e-9)
    return [k * step for k in range(1, n + 1)] + ([STOP] if not math.isclose(n * step, STOP) else [])


@pytest.fixture(scope="module")
def event_mode_run(fmus, tmp_path_factory):
    """The Event Mode controller at host step T_s: the reference samples."""
    r = Host(fmus["TAPMP_Controller"], tmp_path_factory.mktemp("events")).run(grid(T_S))
    r.free()
    return r


def test_clocked_modeldescription_declares_a_fixed_periodic_input_clock_clocking_every_output(fmus):
    fmu = fmus[CLOCKED]
    assert validate_fmu(str(fmu)) == []
    md = read_model_description(str(fmu))
    assert md.coSimulation.modelIdentifier == CLOCKED and md.coSimulation.hasEventMode is True
    root = ET.fromstring(zipfile.ZipFile(fmu).read("modelDescription.xml"))
    clocks = root.findall("ModelVariables/Clock")
    assert [c.attrib for c in clocks] == [{
        "name": "sample_clock", "valueReference": str(len(md.modelVariables) - 1), "causality": "input",
        "variability": "discrete", "description": clocks[0].get("description"), "intervalVariability": "fixed",
        "intervalDecimal": "0.0001", "shiftDecimal": "0.0"}]
    vr = clocks[0].get("valueReference")
    outputs = [v for v in root.find("ModelVariables") if v.get("causality") == "output"]
    assert [v.get("name") for v in outputs] == list(OUTPUTS)
    assert all(v.get("clocks") == vr and v.get("variability") == "discrete" for v in outputs)
    inputs = [v for v in root.find("ModelVariables") if v.get("causality") == "input" and v.tag != "Clock"]
    assert inputs and all(v.get("clocks") is None for v in inputs)  # continuous signals, sampled at the tick


@pytest.mark.needs_shared("schemas/fmi3/fmi3ModelDescription.xsd")
def test_clocked_modeldescription_is_valid_against_the_fmi3_schema(fmus):
    from lxml import etree
    xsd = etree.XMLSchema(etree.parse(str(shared("schemas/fmi3/fmi3ModelDescription.xsd"))))
    doc = etree.fromstring(zipfile.ZipFile(fmus[CLOCKED]).read("modelDescription.xml"))
    assert xsd.validate(doc), xsd.error_log


@pytest.mark.parametrize("host_step", [T_S, 2.5 * T_S, 7 * T_S])
def test_ticking_the_clock_at_every_T_s_gives_the_event_mode_forces_bit_for_bit(fmus, tmp_path, event_mode_run,
                                                                                host_step):
    r = Host(fmus[CLOCKED], tmp_path).run(grid(host_step))
    assert len(r.samples) == 201  # t = 0 and the 200 ticks after it
    assert [t for t, _ in r.samples] == pytest.approx([t for t, _ in event_mode_run.samples], abs=1e-15)
    assert [out for _, out in r.samples] == [out for _, out in event_mode_run.samples]
    assert r.log == []
    assert r.next_event is None  # no time events of its own: the host schedules the clock
    r.free()


def test_between_ticks_and_in_an_event_without_a_tick_the_command_holds(fmus, tmp_path):
    r = Host(fmus[CLOCKED], tmp_path)
    r.start()
    first = r.samples[-1][1]
    r.inputs(0.0)
    r.slave.doStep(0.0, 0.5 * T_S)
    assert r.outputs() == first
    r.slave.enterEventMode()
    r.update(0.5 * T_S, tick=False)  # an event of another FMU: no tick, no sample
    assert r.samples[-1][1] == first
    r.slave.doStep(0.5 * T_S, 0.5 * T_S)
    r.slave.enterEventMode()
    r.update(T_S)
    assert r.samples[-1][1] != first and r.log == []
    r.free()


def test_clock_interval_and_shift_are_reported_as_T_s_and_zero(fmus, tmp_path):
    r = Host(fmus[CLOCKED], tmp_path)
    clock = (c_uint32 * 1)(r.vr["sample_clock"])
    interval, qualifier = (c_double * 1)(), (c_int * 1)()
    r.slave.setFloat64([r.vr["T_s"]], [2e-4])
    r.slave.getIntervalDecimal(clock, interval, qualifier)
    assert interval[0] == 2e-4 and qualifier[0] == 2  # fmi3IntervalChanged
    counter, resolution = (c_uint64 * 1)(), (c_uint64 * 1)()
    r.slave.getIntervalFraction(clock, counter, resolution, qualifier)
    assert (counter[0], resolution[0]) == (1, 5000)
    shift = (c_double * 1)()
    r.slave.getShiftDecimal(clock, shift)
    assert shift[0] == 0.0
    r.slave.setIntervalDecimal(clock, (c_double * 1)(2e-4))  # the interval it has: accepted
    assert r.log == []
    r.slave.freeInstance()


def refused(r, call, *args):
    with pytest.raises(Exception):
        call(*args)
    return r.log[-1]


def test_eventModeUsed_false_is_refused_with_a_message(fmus, tmp_path):
    fmu = fmus[CLOCKED]
    md = read_model_description(str(fmu))
    slave = FMU3Slave(guid=md.guid, unzipDirectory=extract(str(fmu), unzipdir=str(tmp_path / "x")),
                      modelIdentifier=CLOCKED, instanceName="x")
    log = []
    with pytest.raises(Exception):
        slave.instantiate(loggingOn=True, eventModeUsed=False, earlyReturnAllowed=False,
                          logMessage=lambda env, status, category, message: log.append((status, message.decode())))
    assert log == [(3, "fmi3InstantiateCoSimulation: eventModeUsed = false is invalid: allowed is true "
                       "(TAPMP_ControllerClocked has the input clock sample_clock, which ticks only in Event Mode)")]


def test_an_interval_other_than_T_s_is_refused(fmus, tmp_path):
    r = Host(fmus[CLOCKED], tmp_path)
    clock = (c_uint32 * 1)(r.vr["sample_clock"])
    assert refused(r, r.slave.setIntervalDecimal, clock, (c_double * 1)(2e-4)) == (
        3, "interval of sample_clock = 0.0002 is invalid: allowed is the sample period T_s = 0.0001 s (set the "
           "parameter T_s for another period) (at t = 0 s)")
    r.slave.freeInstance()
    r = Host(fmus[CLOCKED], tmp_path, name="d")
    assert refused(r, r.slave.setIntervalFraction, clock, (c_uint64 * 1)(1), (c_uint64 * 1)(1000)) == (
        3, "interval of sample_clock = 0.001 is invalid: allowed is the sample period T_s = 0.0001 s (set the "
           "parameter T_s for another period) (at t = 0 s)")
    r.slave.freeInstance()


def set_interval_to_T_s(r):
    """fmi3SetIntervalDecimal of the clock's own interval T_s."""
    return r.slave.setIntervalDecimal, (c_uint32 * 1)(r.vr["sample_clock"]), (c_double * 1)(T_S)


def tick(r):
    """fmi3SetClock of sample_clock."""
    return r.slave.setClock, [r.vr["sample_clock"]], [True]


def set_clock_of_F1_in_event_mode(r):
    """fmi3SetClock of the output F1 (no clock), in Event Mode."""
    r.slave.enterEventMode()
    return r.slave.setClock, [r.vr["F1"]], [True]


@pytest.mark.parametrize("misuse, message", [
    pytest.param(set_interval_to_T_s, "fmi3SetIntervalDecimal is not allowed in Step Mode: allowed in Instantiated "
                 "or Initialization Mode (the interval of the clock sample_clock is fixed once the model runs)",
                 id="setting_the_interval_once_the_model_runs"),
    pytest.param(tick, "fmi3SetClock is not allowed in Step Mode: allowed in Event Mode (the clock sample_clock "
                 "ticks at an event)", id="setClock_outside_event_mode"),
    pytest.param(set_clock_of_F1_in_event_mode, "SetClock valueReference = {F1} is invalid: allowed is "
                 "{sample_clock}, the clock sample_clock (fmi3SetClock takes clocks only) (at t = 0 s)",
                 id="setClock_of_a_value_reference_that_is_not_a_clock"),
])
def test_a_misuse_of_the_clock_once_the_model_runs_is_refused_with_a_message(fmus, tmp_path, misuse, message):
    """Each misuse after initialization (now in Step Mode) fails with one error naming what is allowed;
    ``message`` names value references as {F1} and {sample_clock}."""
    r = Host(fmus[CLOCKED], tmp_path)
    r.start()
    call, *args = misuse(r)
    assert refused(r, call, *args) == (3, message.format(**r.vr))
    r.slave.freeInstance()


def test_a_tick_off_the_grid_t0_plus_k_T_s_is_refused(fmus, tmp_path):
    r = Host(fmus[CLOCKED], tmp_path)
    r.start()
    r.slave.doStep(0.0, 0.5 * T_S)
    r.slave.enterEventMode()
    r.slave.setClock([r.vr["sample_clock"]], [True])
    assert refused(r, r.slave.updateDiscreteStates) == (
        3, "time of the tick of sample_clock = 5e-05 is invalid: allowed is an instant t0 + k T_s (t0 = 0.0 s, "
           "T_s = 0.0001 s)")
    r.slave.freeInstance()


def test_a_host_that_never_ticks_gets_one_warning_and_a_held_command(fmus, tmp_path):
    r = Host(fmus[CLOCKED], tmp_path)
    r.start()
    first = r.samples[-1][1]
    t = 0.0
    for _ in range(5):
        r.slave.doStep(t, T_S)
        t += T_S
    assert r.outputs() == first
    assert r.log == [(1, "the input clock sample_clock (interval T_s = 0.0001 s) did not tick at t = 0.0001 s: the "
                         "controller holds its command until the host activates the clock (fmi3SetClock in Event "
                         "Mode, then fmi3UpdateDiscreteStates) at an instant t0 + k T_s; doStep reached t = "
                         "0.0002 s")]  # a step that ends on a tick leaves the host its Event Mode there
    r.free()


def test_fmpy_simulate_fmu_does_not_tick_input_clocks(fmus, request):
    """FMPy 0.3 (simulate_fmu) has no input clock scheduling: without Event Mode the clocked FMU refuses
    to instantiate; with it, FMPy never ticks the clock and the command computed at initialization holds
    (one warning)."""
    fmu = str(fmus[CLOCKED])
    with pytest.raises(Exception, match="Failed to instantiate"):
        simulate_fmu(fmu, stop_time=0.001, output_interval=T_S, fmi_type="CoSimulation")
    messages = []
    rows = simulate_fmu(fmu, stop_time=0.001, output_interval=T_S, fmi_type="CoSimulation", use_event_mode=True,
                        early_return_allowed=True, output=["F1", "F2", "F3"], start_values={"q1": 1e-3},
                        logger=lambda *a: messages.append(a[-1].decode() if isinstance(a[-1], bytes) else a[-1]))
    assert len(rows) == 11 and len(set(tuple(r)[1:] for r in rows)) == 1  # the command of initialization, held
    assert sum("did not tick" in m for m in messages) == 1
    compatibility.record(
        request, tool="FMPy", version=compatibility.python_version("fmpy"), fmi="3.0", interface="CS, input clock",
        command=compatibility.python_c("from fmpy import simulate_fmu; r = simulate_fmu('build/native/fmi3/"
                                        "TAPMP_ControllerClocked.fmu', stop_time=0.001, output_interval=1e-4, "
                                        "use_event_mode=True, early_return_allowed=True, output=['F1']); print(r)"),
        result="runs, but never ticks the input clock: the command of initialization holds (one warning); without "
               "use_event_mode the FMU refuses to instantiate",
        difference="not comparable: the controller never samples")


FMUSIM = Path(__file__).resolve().parents[2].parent / "shared" / "tools" / "fmusim" / "bin" / "fmusim"


@pytest.mark.needs_shared("tools/fmusim/bin/fmusim")
def test_fmusim_in_event_mode_does_not_tick_input_clocks(fmus, tmp_path, request):
    """fmusim (Reference FMUs) runs the clocked FMU with --event-mode-used but never activates the input
    clock: the first command holds, with the controller's one warning."""
    import subprocess
    out = tmp_path / "out.csv"
    done = subprocess.run([str(FMUSIM), "--interface-type", "cs", "--stop-time", "0.001", "--output-interval", "1e-4",
                           "--event-mode-used", "--early-return-allowed", "--start-value", "q1", "0.001",
                           "--output-variable", "F1", "--output-file", str(out), str(fmus[CLOCKED])],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "did not tick at t = 0.0 s" in done.stdout + done.stderr
    rows = np.loadtxt(out, delimiter=",", skiprows=1)
    assert rows.shape == (11, 2) and len(set(rows[:, 1])) == 1  # the command of t = 0 (initialization) holds
    compatibility.record(
        request, tool="fmusim", version=compatibility.fmusim_version(FMUSIM), fmi="3.0", interface="CS, input clock",
        command=f"{compatibility.FMUSIM} --interface-type cs --event-mode-used --early-return-allowed "
                "build/native/fmi3/TAPMP_ControllerClocked.fmu",
        result="runs, but never ticks the input clock: the command of initialization holds (one warning)",
        difference="not comparable: the controller never samples")


def test_getClock_reports_the_activation_until_the_update_ends_it(fmus, tmp_path):
    r = Host(fmus[CLOCKED], tmp_path)
    r.slave.enterInitializationMode(startTime=0.0)
    r.inputs(0.0)
    r.slave.exitInitializationMode()  # Event Mode at t0
    clock = [r.vr["sample_clock"]]
    assert r.slave.getClock(clock) == [False]
    r.slave.setClock(clock, [True])
    assert r.slave.getClock(clock) == [True]
    r.slave.updateDiscreteStates()
    assert r.slave.getClock(clock) == [False]
    assert r.log == []
    r.slave.freeInstance()


@pytest.mark.needs_shared("tools/fmil/fmil_check")
def test_fmil_parses_the_clocked_controller_with_only_its_known_gaps_on_the_terminals(fmus, tmp_path, request):
    """FMIL 3.0.4 reads the clock, the clocked outputs and Event Mode; what it logs is only what it does not
    know of the valid terminalsAndIcons.xml, which the clocked FMU carries like every native FMI 3.0 FMU
    (tests/support/fmil_gaps.py)."""
    import subprocess
    from tests.support.fmil_gaps import fmil_messages, terminal_messages, warnings_and_errors
    proc = subprocess.run([str(shared("tools/fmil/fmil_check")), "parse", str(fmus[CLOCKED])], cwd=tmp_path,
                          capture_output=True, text=True, timeout=120)
    expected = terminal_messages(fmus[CLOCKED])
    assert fmil_messages(proc.stderr) == expected, proc.stderr
    warnings, errors = warnings_and_errors(expected)
    assert f"FMIL parse: {warnings} warnings, {errors} errors" in proc.stdout, proc.stdout
    assert "outputs 12, initial unknowns 0" in proc.stdout and "hasEventMode 1" in proc.stdout
    compatibility.record(
        request, tool="FMIL", version=compatibility.readme_version("fmil"), fmi="3.0", interface="CS, input clock",
        command=f'{compatibility.FMIL_CHECK} parse build/native/fmi3/TAPMP_ControllerClocked.fmu || echo "exit code $?"',
        difference="none (reads the FMU's XML only): errors and warnings only on the valid terminalsAndIcons.xml, "
                   "whose elements FMIL does not know")


def test_the_clocked_fmu_carries_its_sources_its_binary_and_the_license(fmus):
    from orchestrator.builder.fmu_extras import LICENSE_FILE
    names = set(zipfile.ZipFile(fmus[CLOCKED]).namelist())
    assert {"modelDescription.xml", "binaries/x86_64-linux/TAPMP_ControllerClocked.so", "sources/all.c",
            "sources/buildDescription.xml", LICENSE_FILE} <= names
    build = ET.fromstring(zipfile.ZipFile(fmus[CLOCKED]).read("sources/buildDescription.xml"))
    assert {c.get("modelIdentifier") for c in build.iter("BuildConfiguration")} == {CLOCKED}


def test_a_tick_not_handled_before_leaving_event_mode_is_refused_and_never_samples_later(fmus, tmp_path):
    """fmi3SetClock, then fmi3EnterStepMode without fmi3UpdateDiscreteStates: an error naming the tick; the
    command holds (no sample at this event or any later one)."""
    r = Host(fmus[CLOCKED], tmp_path)
    r.start()
    first = r.outputs()
    r.slave.doStep(0.0, T_S)
    r.slave.enterEventMode()
    r.inputs(T_S)
    r.slave.setClock([r.vr["sample_clock"]], [True])
    assert refused(r, r.slave.enterStepMode) == (
        3, "fmi3EnterStepMode at t = 0.0001 s is not allowed: the tick of the clock sample_clock set in this event "
           "(fmi3SetClock) was not handled: allowed is fmi3UpdateDiscreteStates before leaving Event Mode (a tick "
           "belongs to its event)")
    assert r.slave.getClock([r.vr["sample_clock"]]) == [False]  # the tick is gone
    assert r.outputs() == first
    r.slave.freeInstance()


def test_an_event_off_the_grid_without_a_tick_is_fine_after_a_tick_handled_at_the_last_instant(fmus, tmp_path):
    """A tick at t = T_s handled, then an event of another FMU at t = 1.5 T_s (off the grid) with no tick:
    GetClock is inactive, the update holds the command with OK, and the next tick samples."""
    r = Host(fmus[CLOCKED], tmp_path)
    r.start()
    r.inputs(0.0)
    r.slave.doStep(0.0, T_S)
    r.slave.enterEventMode()
    r.update(T_S)
    held = r.outputs()
    r.slave.doStep(T_S, 0.5 * T_S)
    r.slave.enterEventMode()
    assert r.slave.getClock([r.vr["sample_clock"]]) == [False]
    r.update(1.5 * T_S, tick=False)
    assert r.outputs() == held
    r.slave.doStep(1.5 * T_S, 0.5 * T_S)
    r.slave.enterEventMode()
    r.update(2 * T_S)
    assert r.outputs() != held and r.log == []
    r.free()


def test_a_tick_is_part_of_the_fmu_state_of_its_event(fmus, tmp_path):
    """A state got after fmi3SetClock in Event Mode comes back with the tick (the update samples); a
    state's tick outside Event Mode, crafted into its serialized bytes, is refused."""
    r = Host(fmus[CLOCKED], tmp_path)
    r.start()
    r.inputs(0.0)
    r.slave.doStep(0.0, T_S)
    r.slave.enterEventMode()
    r.inputs(T_S)
    held = r.outputs()
    r.slave.setClock([r.vr["sample_clock"]], [True])
    ticked = r.slave.getFMUState()
    r.slave.updateDiscreteStates()
    sampled = r.outputs()
    assert sampled != held
    r.slave.setFMUState(ticked)
    assert r.slave.getClock([r.vr["sample_clock"]]) == [True]
    r.slave.updateDiscreteStates()
    assert r.outputs() == sampled
    r.slave.enterStepMode()
    from tests.support.fmu_states import SerializedState
    state = SerializedState(r.slave.serializeFMUState(r.slave.getFMUState()))
    assert state.header("clock_active") == 0
    state.set_header("clock_active", 1)
    with pytest.raises(Exception):
        r.slave.deserializeFMUState(bytes(state))
    assert r.log[-1] == (3, "fmi3DeserializeFMUState: FMU state: clock tick = 1 is invalid in Step Mode: allowed is 0 "
                            "(a tick exists only in the Event Mode it was set in); nothing was changed")
    r.slave.freeInstance()
