"""The native FMI 2.0 and 3.0 plants' Model Exchange interface (fmu_common/c/fmi2_api.c and fmi3_model_exchange.c
on model_exchange.c's tapmp_me_* operations and fmu_plant/plant.c's model_me_* hooks), called through FMPy: the
states and derivatives are the C model's, the external force step is a time event, and every call
that does not fit is an error with its message. The controller and the trajectory stay
Co-Simulation only. Third-party integrators on it: tests/interop/test_model_exchange.py."""

import re
import zipfile
from pathlib import Path
from ctypes import POINTER, byref, c_double, c_int, c_void_p
from xml.etree import ElementTree as ET

import numpy as np
import pytest
from fmpy import calloc, extract, free, read_model_description, simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (FMU2Model, FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE, fmi2CallbackFunctions,
                       fmi2CallbackLoggerTYPE)
from fmpy.fmi3 import FMU3Model, FMU3Slave
from fmpy.logging import addLoggerProxy

from tapmp.interface import CONTROLLER, INITIAL_STATE, PLANT, TRAJECTORY

STATES = ("X", "Z", "B", "dX", "dZ", "dB")
FAMILIES = ("fmi2", "fmi3")


class MEPlant:
    """One Model Exchange instance of the native FMI 2.0 or 3.0 (``family``) plant, its log messages
    kept, with the calls both versions have under one name each."""

    def __init__(self, fmu, folder, family="fmi2", model=PLANT):
        self.family = family
        self.md = read_model_description(str(fmu))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.messages = []
        unzip = extract(str(fmu), unzipdir=str(folder))
        if family == "fmi2":
            self.callbacks = fmi2CallbackFunctions()
            self.callbacks.logger = fmi2CallbackLoggerTYPE(
                lambda env, name, status, category, message: self.messages.append((status, message.decode())))
            self.callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
            self.callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
            addLoggerProxy(byref(self.callbacks))
            self.fmu = FMU2Model(guid=self.md.guid, unzipDirectory=unzip, modelIdentifier=model, instanceName="me")
            self.fmu.instantiate(callbacks=self.callbacks, loggingOn=True)
        else:
            self.fmu = FMU3Model(guid=self.md.guid, unzipDirectory=unzip, modelIdentifier=model, instanceName="me")
            self.fmu.instantiate(loggingOn=True, logMessage=lambda env, status, category, message:
                                 self.messages.append((status, message.decode())))

    def initialize(self, **values):
        if self.family == "fmi2":
            for name, value in values.items():
                self.fmu.setReal([self.vr[name]], [float(value)])
            self.fmu.setupExperiment(startTime=0.0)
            self.fmu.enterInitializationMode()
        else:
            for name, value in values.items():
                self.fmu.setFloat64([self.vr[name]], [float(value)])
            self.fmu.enterInitializationMode(startTime=0.0)
        self.fmu.exitInitializationMode()

    def get_real(self, names) -> list:
        vrs = [self.vr[n] for n in names]
        return self.fmu.getReal(vrs) if self.family == "fmi2" else self.fmu.getFloat64(vrs)

    def derivatives(self, pdx, n):
        if self.family == "fmi2":
            return self.fmu.getDerivatives(pdx, n)
        return self.fmu.getContinuousStateDerivatives(pdx, n)

    def update(self) -> tuple:
        """The event update in Event Mode: (next time event defined, its time [s])."""
        if self.family == "fmi2":
            info = self.fmu.newDiscreteStates()
            assert info[:4] == (False, False, False, False)  # nothing discrete changes, nothing ends
            return info[4], info[5]
        info = self.fmu.updateDiscreteStates()
        assert info[:4] == (False, False, False, False)
        return info[4], info[5]

    def call(self, name) -> str:
        """The name of a call of this family, as messages name it."""
        return f"{self.family}{name}"

    def error(self, call) -> str:
        """The one error message ``call`` logs as it fails with an error status."""
        before = len(self.messages)
        with pytest.raises(FMICallException) as err:
            call()
        assert err.value.status == 3
        (message,) = [m for s, m in self.messages[before:] if s >= 3]
        return message


@pytest.fixture(params=FAMILIES)
def me_plant(request, native_built, tmp_path):
    plant = MEPlant(native_built[request.param][PLANT], tmp_path / "unzip", request.param)
    yield plant
    plant.fmu.freeInstance()


@pytest.mark.parametrize("family", FAMILIES)
def test_both_interfaces_share_one_model_identifier_and_the_derivatives_are_declared(native_built, family):
    with zipfile.ZipFile(native_built[family][PLANT]) as z:
        root = ET.fromstring(z.read("modelDescription.xml"))
    me, cs = root.find("ModelExchange"), root.find("CoSimulation")
    assert list(root).index(me) < list(root).index(cs)  # the schema's order
    assert me.get("modelIdentifier") == cs.get("modelIdentifier") == PLANT
    md = read_model_description(str(native_built[family][PLANT]))
    assert md.numberOfEventIndicators == 0
    assert [d.variable.name for d in md.derivatives] == [f"der({s})" for s in STATES]
    assert [d.variable.derivative.name for d in md.derivatives] == list(STATES)
    if family == "fmi3":  # after the independent variable `time`, which is N_VARS
        time = next(v for v in md.modelVariables if v.causality == "independent")
        assert [d.variable.valueReference for d in md.derivatives] == [time.valueReference + 1 + k for k in range(6)]
    for model in (CONTROLLER, TRAJECTORY):  # Co-Simulation only
        with zipfile.ZipFile(native_built[family][model]) as z:
            assert ET.fromstring(z.read("modelDescription.xml")).find("ModelExchange") is None


def array(values) -> tuple[np.ndarray, object]:
    """A float64 array and the fmi2Real / fmi3Float64 pointer to it that FMPy's Model Exchange calls take."""
    a = np.ascontiguousarray(values, dtype=float)
    return a, a.ctypes.data_as(POINTER(c_double))


def test_states_and_derivatives_follow_the_model(me_plant):
    """The start state is the defaults' (the paper's start); a state set by the host comes back, its
    derivatives are der(X) = dX ... and the readable model's accelerations (tapmp.plant.PlantModel,
    to 1e-12: the C and the Python reorder some operations); the outputs follow the state."""
    from tapmp.params import ModelParams
    from tapmp.plant import PlantConfig, PlantModel
    me_plant.initialize(F1=20.0, F2=10.0, F3=60.0)
    fmu = me_plant.fmu
    fmu.enterContinuousTimeMode()
    x0, px0 = array(np.zeros(6))
    fmu.getContinuousStates(px0, 6)
    assert tuple(x0) == INITIAL_STATE
    x, px = array([0.01, -0.02, 0.1, 0.3, -0.2, 1.5])
    fmu.setTime(0.01)
    fmu.setContinuousStates(px, 6)
    dx, pdx = array(np.zeros(6))
    me_plant.derivatives(pdx, 6)
    assert np.array_equal(dx, me_plant.get_real([f"der({s})" for s in STATES]))
    assert np.array_equal(dx[:3], x[3:])
    model = PlantModel(ModelParams(), PlantConfig(), INITIAL_STATE[:3], INITIAL_STATE[3:])
    assert np.allclose(dx, model.derivatives(tuple(x), 20.0, 10.0, 60.0), rtol=1e-12, atol=0), dx
    assert me_plant.get_real(STATES) == list(x)
    assert np.abs(dx[3:]).min() > 0.1  # forces and gravity accelerate it
    if me_plant.family == "fmi3":
        assert (fmu.getNumberOfContinuousStates(), fmu.getNumberOfEventIndicators()) == (6, 0)
        assert me_plant.get_real(["time"]) == [0.01]


def test_the_external_force_step_is_a_time_event(me_plant):
    """disturbance_time is announced as the next time event while it is ahead; the derivatives
    change there and not before."""
    me_plant.initialize(disturbance_force1=50.0, disturbance_time=0.05)
    fmu = me_plant.fmu
    assert me_plant.update() == (True, 0.05)
    fmu.enterContinuousTimeMode()
    dx, pdx = array(np.zeros(6))
    before = []
    for t in (0.05 - 1e-9, 0.05):
        fmu.setTime(t)
        me_plant.derivatives(pdx, 6)
        before.append(dx.copy())
    assert np.abs(before[1][3:] - before[0][3:]).max() > 1.0  # m/s2: the 50 N step on mover 1
    fmu.enterEventMode()
    assert me_plant.update()[0] is False  # no further event


@pytest.mark.parametrize("family", FAMILIES)
def test_fmpy_integrates_across_the_time_event_as_the_co_simulation_plant_steps(native_built, family):
    plant = native_built[family][PLANT]
    start = {"F1": 20.0, "F2": 10.0, "F3": 60.0, "disturbance_force2": -80.0, "disturbance_time": 0.05}
    kw = dict(stop_time=0.1, output_interval=1e-4, start_values=start, output=list(STATES))
    cs = simulate_fmu(str(plant), fmi_type="CoSimulation", **kw)
    me = simulate_fmu(str(plant), fmi_type="ModelExchange", solver="CVode", relative_tolerance=1e-10, **kw)
    last = np.r_[np.diff(me["time"]) > 0, True]  # FMPy records the event time twice: before and after
    assert np.count_nonzero(~last) == 1 and me["time"][~last][0] == pytest.approx(0.05)
    got = np.array([me[n][last] for n in STATES]).T
    ref = np.array([cs[n] for n in STATES]).T
    assert np.all(np.abs(got - ref).max(axis=0) <= 1000 * 1e-10 * np.maximum(np.abs(ref).max(axis=0), 1.0))
    without = simulate_fmu(str(plant), fmi_type="CoSimulation", stop_time=0.1, output_interval=1e-4,
                           start_values={**start, "disturbance_force2": 0.0}, output=list(STATES))
    assert abs(without["Z"][-1] - cs["Z"][-1]) > 1e-4  # m: the step matters


@pytest.mark.parametrize("family", FAMILIES)
def test_calls_that_do_not_fit_model_exchange_are_errors_with_their_message(native_built, family, tmp_path):
    plant = native_built[family][PLANT]
    fresh = iter(MEPlant(plant, tmp_path / f"unzip{k}", family) for k in range(4))  # an error ends a run
    early = next(fresh)
    assert early.error(lambda: early.fmu.setTime(0.0)) == (
        f"{family}SetTime is not allowed in Instantiated: allowed in Event Mode and Continuous-Time Mode")
    in_event_mode = next(fresh)
    in_event_mode.initialize()
    assert in_event_mode.error(lambda: in_event_mode.fmu.completedIntegratorStep()) == (
        f"{family}CompletedIntegratorStep is not allowed in Event Mode: allowed in Continuous-Time Mode")
    outside = next(fresh)
    outside.initialize()
    outside.fmu.enterContinuousTimeMode()
    x, px = array([0.0, 0.0, 2.0, 0.0, 0.0, 0.0])
    assert outside.error(lambda: outside.fmu.setContinuousStates(px, 6)) == (
        "plant state B = 2.0 at t = 0 s is invalid: allowed is |B| < pi/2 rad (the kinematic domain)")
    stepping = next(fresh)
    stepping.initialize()
    if family == "fmi2":
        do_step = stepping.fmu.dll.fmi2DoStep
        do_step.argtypes, do_step.restype = [c_void_p, c_double, c_double, c_int], c_int
        assert do_step(stepping.fmu.component, 0.0, 1e-4, 1) == 3
        assert stepping.messages[-1] == (3, "fmi2DoStep is not supported: the instance is a Model Exchange instance "
                                            "(fmuType = fmi2ModelExchange)")
    else:
        do_step = stepping.fmu.dll.fmi3DoStep
        do_step.argtypes = [c_void_p, c_double, c_double, c_int, c_void_p, c_void_p, c_void_p, c_void_p]
        do_step.restype = c_int
        assert do_step(stepping.fmu.component, 0.0, 1e-4, 1, None, None, None, None) == 3
        assert stepping.messages[-1] == (3, "fmi3DoStep is not supported: the instance is a Model Exchange instance "
                                            "(fmi3InstantiateModelExchange)")
        enter_step_mode = stepping.fmu.dll.fmi3EnterStepMode
        enter_step_mode.argtypes, enter_step_mode.restype = [c_void_p], c_int
        assert enter_step_mode(stepping.fmu.component) == 3
        assert stepping.messages[-1][1] == (
            "fmi3EnterStepMode is not supported: the instance is a Model Exchange instance (allowed: "
            "fmi3EnterContinuousTimeMode)")


def test_model_exchange_calls_on_a_co_simulation_instance_are_errors(native_built, tmp_path):
    """An FMI 3.0 Co-Simulation instance of the plant has no Event Mode and no continuous-state calls."""
    md = read_model_description(str(native_built["fmi3"][PLANT]))
    messages = []
    slave = FMU3Slave(guid=md.guid, unzipDirectory=extract(str(native_built["fmi3"][PLANT]), unzipdir=str(tmp_path)),
                      modelIdentifier=PLANT, instanceName="cs")
    slave.instantiate(loggingOn=True, logMessage=lambda env, status, cat, msg: messages.append(msg.decode()))
    try:
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        with pytest.raises(FMICallException):
            slave.enterEventMode()
        assert messages[-1] == "fmi3EnterEventMode is not supported: hasEventMode is false"
        x, px = array(np.zeros(6))
        with pytest.raises(FMICallException):
            slave.fmi3GetContinuousStates(slave.component, px, 6)
        assert messages[-1] == ("fmi3GetContinuousStates is not allowed: the instance was instantiated for "
                                "Co-Simulation (fmi3InstantiateCoSimulation)")
    finally:
        slave.freeInstance()


def test_noise_is_refused_in_model_exchange(me_plant):
    message = me_plant.error(lambda: me_plant.initialize(noise_rms=1e-7))
    assert message == ("noise_rms = 1e-07 is invalid: allowed is 0 in Model Exchange (the noise is drawn once per "
                       "communication step; use Co-Simulation)"), message


@pytest.mark.parametrize("model", [CONTROLLER, TRAJECTORY])
def test_the_controller_and_the_trajectory_refuse_model_exchange(native_built, model, tmp_path):
    """They export no FMI 2.0 Model Exchange function; fmi2Instantiate and fmi3InstantiateModelExchange
    for Model Exchange are refused with a message."""
    messages = []
    callbacks = fmi2CallbackFunctions()
    callbacks.logger = fmi2CallbackLoggerTYPE(lambda env, name, status, cat, msg: messages.append(msg.decode()))
    callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    addLoggerProxy(byref(callbacks))
    md = read_model_description(str(native_built["fmi2"][model]))
    folder = extract(str(native_built["fmi2"][model]), unzipdir=str(tmp_path / "fmi2"))
    slave = FMU2Slave(guid=md.guid, unzipDirectory=folder, modelIdentifier=model, instanceName="me")
    assert not hasattr(slave.dll, "fmi2GetDerivatives") and hasattr(slave.dll, "fmi2DoStep")
    component = slave.fmi2Instantiate(b"me", 0, md.guid.encode(), Path(folder).as_uri().encode(), byref(callbacks),
                                      0, 1)  # 0: fmi2ModelExchange
    assert not component
    assert messages == [f"fmi2Instantiate: fmuType = 0 is invalid: allowed is fmi2CoSimulation (1); {model} is a "
                        "co-simulation FMU"], messages
    md3 = read_model_description(str(native_built["fmi3"][model]))
    me = FMU3Model(guid=md3.guid, unzipDirectory=extract(str(native_built["fmi3"][model]),
                                                         unzipdir=str(tmp_path / "fmi3")),
                   modelIdentifier=model, instanceName="me")
    logged = []
    with pytest.raises(Exception, match="Failed to instantiate FMU"):
        me.instantiate(logMessage=lambda env, status, cat, msg: logged.append(msg.decode()))
    assert logged == [f"fmi3InstantiateModelExchange: {model} is a co-simulation FMU only: allowed is "
                      "fmi3InstantiateCoSimulation"], logged


def fresh_plant(native_built, tmp_path, family, name):
    """A new Model Exchange plant of ``family``, initialized with the defaults, in Continuous-Time Mode."""
    plant = MEPlant(native_built[family][PLANT], tmp_path / name, family)
    plant.initialize()
    plant.fmu.enterContinuousTimeMode()
    return plant


BOUND = re.compile(r"allowed is \|value\| <= (\S+) (m|m/s|rad/s) ")


@pytest.mark.parametrize("family", FAMILIES)
@pytest.mark.parametrize("state, message", [
    ((1e308, 1e308, 0.0, 0.0, 0.0, 0.0), "plant state X = 1e+308 at t = 0 s is invalid: allowed is |value| <= 3.0 m "
     "(the platform's domain: the initial pose's range widened by its stroke)"),
    ((1e154, 0.0, 0.0, 0.0, 0.0, 0.0), "plant state X = 1e+154 at t = 0 s is invalid: allowed is |value| <= 3.0 m "
     "(the platform's domain: the initial pose's range widened by its stroke)"),
    ((0.0, -3.5, 0.0, 0.0, 0.0, 0.0), "plant state Z = -3.5 at t = 0 s is invalid: allowed is |value| <= 3.0 m "
     "(the platform's domain: the initial pose's range widened by its stroke)"),
    ((0.0, 0.0, 0.0, 1e200, 0.0, 0.0), "plant state dX = 1e+200 at t = 0 s is invalid: allowed is |value| <= {v} m/s "
     "(the speed the plant's forces can reach across its domain)"),
    ((0.0, 0.0, 0.0, 0.0, float("nan"), 0.0), "plant state dZ = nan at t = 0 s is invalid: allowed is |value| <= {v} "
     "m/s (the speed the plant's forces can reach across its domain)"),
    ((0.0, 0.0, 0.0, 0.0, 0.0, -float("inf")), "plant state dB = -inf at t = 0 s is invalid: allowed is |value| <= "
     "{w} rad/s (the speed the plant's forces can reach across its domain)"),
], ids=["X_1e308", "X_1e154", "Z_beyond_the_stroke", "dX_1e200", "dZ_nan", "dB_minus_inf"])
def test_a_continuous_state_outside_the_domain_is_refused_naming_the_state_and_its_bound(native_built, tmp_path,
                                                                                      family, state, message):
    """SetContinuousStates checks each state against the Model Exchange domain (plant.c, me_limits): an error
    naming the first state outside, its value and its bound; the outputs keep the values they had."""
    plant = fresh_plant(native_built, tmp_path, family, "u")
    before = plant.get_real(["q1", "q2", "q3", *STATES])
    got = plant.error(lambda: plant.fmu.setContinuousStates(array(state)[1], 6))
    speed = BOUND.search(got)
    assert got == message.format(v=speed and speed.group(1), w=speed and speed.group(1))
    assert plant.get_real(["q1", "q2", "q3", *STATES]) == before
    plant.fmu.freeInstance()


@pytest.mark.parametrize("family", FAMILIES)
@pytest.mark.parametrize("index", [0, 3, 5], ids=["X", "dX", "dB"])
def test_a_state_on_its_bound_is_accepted_and_one_past_it_refused(native_built, tmp_path, family, index):
    """The bound a message names is the domain's edge: the state on it is accepted with finite outputs and
    derivatives, the next double past it refused."""
    probe = fresh_plant(native_built, tmp_path, family, "probe")
    x = np.zeros(6)
    x[index] = 1e300
    bound = float(BOUND.search(probe.error(lambda: probe.fmu.setContinuousStates(array(x)[1], 6))).group(1))
    probe.fmu.freeInstance()
    assert {0: 3.0 <= bound <= 3.0, 3: 1.1e3 < bound < 1.3e3, 5: 1.6e3 < bound < 1.8e3}[index]  # the defaults
    on = fresh_plant(native_built, tmp_path, family, "on")
    x[index] = bound
    on.fmu.setContinuousStates(array(x)[1], 6)
    dx, pdx = array(np.zeros(6))
    on.derivatives(pdx, 6)
    assert np.all(np.isfinite(dx)) and np.all(np.isfinite(on.get_real(["q1", "q2", "q3", *STATES])))
    on.fmu.freeInstance()
    past = fresh_plant(native_built, tmp_path, family, "past")
    x[index] = np.nextafter(bound, np.inf)
    with pytest.raises(FMICallException):
        past.fmu.setContinuousStates(array(x)[1], 6)
    past.fmu.freeInstance()


@pytest.mark.parametrize("family", FAMILIES)
def test_setTime_never_goes_before_the_last_accepted_time(native_built, tmp_path, family):
    """1 -> -1e300 and 1e300 -> -0.5 are refused; an integrator may go back over a step it has not
    completed (1 -> 0.5), but not before a completed integrator step (0.5 -> 0.4) or an event."""
    allowed = ("allowed is a time >= {floor} s, the last accepted time (the end of initialization, an event or a "
               "completed integrator step; time only moves forward) (at t = {now} s)")
    back = fresh_plant(native_built, tmp_path, family, "back")
    back.fmu.setTime(1.0)
    assert back.error(lambda: back.fmu.setTime(-1e300)) == (
        "time = -1e+300 is invalid: " + allowed.format(floor="0.0", now="1"))
    back.fmu.freeInstance()
    far = fresh_plant(native_built, tmp_path, family, "far")
    far.fmu.setTime(1e300)
    assert far.error(lambda: far.fmu.setTime(-0.5)) == (
        "time = -0.5 is invalid: " + allowed.format(floor="0.0", now="1e+300"))
    far.fmu.freeInstance()
    retry = fresh_plant(native_built, tmp_path, family, "retry")
    retry.fmu.setTime(1.0)
    retry.fmu.setTime(0.5)  # a rejected step tried again, shorter
    retry.fmu.completedIntegratorStep()
    assert retry.error(lambda: retry.fmu.setTime(0.4)) == (
        "time = 0.4 is invalid: " + allowed.format(floor="0.5", now="0.5"))
    retry.fmu.freeInstance()
    event = fresh_plant(native_built, tmp_path, family, "event")
    event.fmu.setTime(0.25)
    event.fmu.enterEventMode()
    assert event.error(lambda: event.fmu.setTime(0.2)) == (
        "time = 0.2 is invalid: " + allowed.format(floor="0.25", now="0.25"))
    event.fmu.freeInstance()


def state_calls(plant):
    """(get, set, free, serialize, deserialize) of the plant's FMI version."""
    f = plant.fmu
    if plant.family == "fmi2":
        return f.getFMUstate, f.setFMUstate, f.freeFMUstate, f.serializeFMUstate, f.deSerializeFMUstate
    return f.getFMUState, f.setFMUState, f.freeFMUState, f.serializeFMUState, f.deserializeFMUState


@pytest.mark.parametrize("family", FAMILIES)
@pytest.mark.parametrize("serialized", [False, True], ids=["state", "serialized"])
def test_an_fmu_state_keeps_continuous_time_mode_and_event_mode(native_built, tmp_path, family, serialized):
    """A state got in Continuous-Time Mode comes back in Continuous-Time Mode (CompletedIntegratorStep is
    allowed), one got in Event Mode in Event Mode (it is not); also through its serialized bytes."""
    plant = fresh_plant(native_built, tmp_path, family, "modes")
    get, set_, free, serialize, deserialize = state_calls(plant)

    def keep():
        state = get()
        if not serialized:
            return state
        data = serialize(state)
        free(state)
        return deserialize(data)
    continuous = keep()
    plant.fmu.enterEventMode()
    event = keep()
    set_(continuous)
    plant.fmu.completedIntegratorStep()  # Continuous-Time Mode again
    set_(event)
    assert plant.error(lambda: plant.fmu.completedIntegratorStep()) == (
        f"{family}CompletedIntegratorStep is not allowed in Event Mode: allowed in Continuous-Time Mode")
    plant.fmu.freeInstance()


@pytest.mark.parametrize("family", FAMILIES)
def test_a_serialized_state_claiming_continuous_time_mode_in_co_simulation_is_refused(native_built, tmp_path,
                                                                                     family):
    """The flag (tests.support.fmu_states' layout) set to 1 in a Co-Simulation plant's serialized state:
    refused with a message, nothing changed."""
    from tests.support.fmu_host import Host
    from tests.support.fmu_states import SerializedState
    host = Host(native_built[family][PLANT], tmp_path / "cs", name="cs")
    host.enter_initialization(0.0)
    host.fmu.exitInitializationMode()
    calls = ((host.fmu.getFMUstate, host.fmu.serializeFMUstate, host.fmu.deSerializeFMUstate) if family == "fmi2"
             else (host.fmu.getFMUState, host.fmu.serializeFMUState, host.fmu.deserializeFMUState))
    state = SerializedState(calls[1](calls[0]()))
    assert state.header("me_continuous") == 0
    state.set_header("me_continuous", 1)
    with pytest.raises(FMICallException):
        calls[2](bytes(state))
    deserialize = "fmi2DeSerializeFMUstate" if family == "fmi2" else "fmi3DeserializeFMUState"
    assert host.messages[-1][-1] == (
        f"{deserialize}: FMU state: Continuous-Time Mode = 1 is invalid in Step Mode of a Co-Simulation instance: "
        "allowed is 0 (only a Model Exchange instance after initialization is in Continuous-Time Mode); nothing was "
        "changed")
    host.fmu.freeInstance()
