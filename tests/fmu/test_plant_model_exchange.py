"""The native FMI 2.0 plant's Model Exchange interface (fmu_common/c/fmi2_api.c on fmu_plant/plant.c's
model_me_* hooks), called through FMPy: the states and derivatives are the C model's, the external
force step is a time event, and every call that does not fit is an error with its message. The
controller and the trajectory stay Co-Simulation only. Third-party integrators on it:
tests/interop/test_model_exchange.py."""

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
from fmpy.logging import addLoggerProxy

from tapmp.interface import CONTROLLER, INITIAL_STATE, PLANT, TRAJECTORY

STATES = ("X", "Z", "B", "dX", "dZ", "dB")


class MEPlant:
    """One Model Exchange instance of the native FMI 2.0 plant, its log messages kept."""

    def __init__(self, fmu, folder, model=PLANT):
        self.md = read_model_description(str(fmu))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.messages = []
        self.callbacks = fmi2CallbackFunctions()
        self.callbacks.logger = fmi2CallbackLoggerTYPE(
            lambda env, name, status, category, message: self.messages.append((status, message.decode())))
        self.callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        self.callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        addLoggerProxy(byref(self.callbacks))
        self.fmu = FMU2Model(guid=self.md.guid, unzipDirectory=extract(str(fmu), unzipdir=str(folder)),
                             modelIdentifier=model, instanceName="me")
        self.fmu.instantiate(callbacks=self.callbacks, loggingOn=True)

    def initialize(self, **values):
        for name, value in values.items():
            self.fmu.setReal([self.vr[name]], [float(value)])
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()

    def error(self, call) -> str:
        """The one error message ``call`` logs as it fails with fmi2Error."""
        before = len(self.messages)
        with pytest.raises(FMICallException) as err:
            call()
        assert err.value.status == 3
        (message,) = [m for s, m in self.messages[before:] if s >= 3]
        return message


@pytest.fixture
def me_plant(native_built, tmp_path):
    plant = MEPlant(native_built["fmi2"][PLANT], tmp_path / "unzip")
    yield plant
    plant.fmu.freeInstance()


def test_both_interfaces_share_one_model_identifier_and_the_derivatives_are_declared(native_built):
    with zipfile.ZipFile(native_built["fmi2"][PLANT]) as z:
        root = ET.fromstring(z.read("modelDescription.xml"))
    me, cs = root.find("ModelExchange"), root.find("CoSimulation")
    assert me.get("modelIdentifier") == cs.get("modelIdentifier") == PLANT
    assert root.get("numberOfEventIndicators") == "0"
    md = read_model_description(str(native_built["fmi2"][PLANT]))
    assert [d.variable.name for d in md.derivatives] == [f"der({s})" for s in STATES]
    assert [d.variable.derivative.name for d in md.derivatives] == list(STATES)
    for model in (CONTROLLER, TRAJECTORY):  # Co-Simulation only
        with zipfile.ZipFile(native_built["fmi2"][model]) as z:
            assert ET.fromstring(z.read("modelDescription.xml")).find("ModelExchange") is None


def array(values) -> tuple[np.ndarray, object]:
    """A float64 array and the fmi2Real pointer to it that FMPy's Model Exchange calls take."""
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
    fmu.getDerivatives(pdx, 6)
    assert np.array_equal(dx, fmu.getReal([me_plant.vr[f"der({s})"] for s in STATES]))
    assert np.array_equal(dx[:3], x[3:])
    model = PlantModel(ModelParams(), PlantConfig(), INITIAL_STATE[:3], INITIAL_STATE[3:])
    assert np.allclose(dx, model.derivatives(tuple(x), 20.0, 10.0, 60.0), rtol=1e-12, atol=0), dx
    assert fmu.getReal([me_plant.vr[s] for s in STATES]) == list(x)
    assert np.abs(dx[3:]).min() > 0.1  # forces and gravity accelerate it


def test_the_external_force_step_is_a_time_event(me_plant):
    """disturbance_time is announced as the next time event while it is ahead; the derivatives
    change there and not before."""
    me_plant.initialize(disturbance_force1=50.0, disturbance_time=0.05)
    fmu = me_plant.fmu
    info = fmu.newDiscreteStates()
    assert info == (False, False, False, False, True, 0.05)
    fmu.enterContinuousTimeMode()
    dx, pdx = array(np.zeros(6))
    before = []
    for t in (0.05 - 1e-9, 0.05):
        fmu.setTime(t)
        fmu.getDerivatives(pdx, 6)
        before.append(dx.copy())
    assert np.abs(before[1][3:] - before[0][3:]).max() > 1.0  # m/s2: the 50 N step on mover 1
    fmu.enterEventMode()
    assert fmu.newDiscreteStates()[4] is False  # no further event


def test_fmpy_integrates_across_the_time_event_as_the_co_simulation_plant_steps(native_built):
    plant = native_built["fmi2"][PLANT]
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


def test_calls_that_do_not_fit_model_exchange_are_errors_with_their_message(native_built, tmp_path):
    plant = native_built["fmi2"][PLANT]
    fresh = iter(MEPlant(plant, tmp_path / f"unzip{k}") for k in range(4))  # an error ends an instance's run
    early = next(fresh)
    assert early.error(lambda: early.fmu.setTime(0.0)) == (
        "fmi2SetTime is not allowed in Instantiated: allowed in Event Mode and Continuous-Time Mode")
    in_event_mode = next(fresh)
    in_event_mode.initialize()
    assert in_event_mode.error(lambda: in_event_mode.fmu.completedIntegratorStep()) == (
        "fmi2CompletedIntegratorStep is not allowed in Event Mode: allowed in Continuous-Time Mode")
    outside = next(fresh)
    outside.initialize()
    outside.fmu.enterContinuousTimeMode()
    x, px = array([0.0, 0.0, 2.0, 0.0, 0.0, 0.0])
    assert outside.error(lambda: outside.fmu.setContinuousStates(px, 6)) == (
        "plant state (X, Z, B, dX, dZ, dB) = (0.0, 0.0, 2.0, 0.0, 0.0, 0.0) at t = 0 s is invalid: allowed is "
        "finite values with |B| < pi/2 rad")
    stepping = next(fresh)
    stepping.initialize()
    do_step = stepping.fmu.dll.fmi2DoStep
    do_step.argtypes, do_step.restype = [c_void_p, c_double, c_double, c_int], c_int
    assert do_step(stepping.fmu.component, 0.0, 1e-4, 1) == 3
    assert stepping.messages[-1] == (3, "fmi2DoStep is not supported: the instance is a Model Exchange instance "
                                        "(fmuType = fmi2ModelExchange)")


def test_noise_is_refused_in_model_exchange(me_plant):
    message = me_plant.error(lambda: me_plant.initialize(noise_rms=1e-7))
    assert message == ("noise_rms = 1e-07 is invalid: allowed is 0 in Model Exchange (the noise is drawn once per "
                       "communication step; use Co-Simulation)"), message


@pytest.mark.parametrize("model", [CONTROLLER, TRAJECTORY])
def test_the_controller_and_the_trajectory_refuse_model_exchange(native_built, model, tmp_path):
    """They export no Model Exchange function; fmi2Instantiate for Model Exchange is refused."""
    messages = []
    callbacks = fmi2CallbackFunctions()
    callbacks.logger = fmi2CallbackLoggerTYPE(lambda env, name, status, cat, msg: messages.append(msg.decode()))
    callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    addLoggerProxy(byref(callbacks))
    md = read_model_description(str(native_built["fmi2"][model]))
    folder = extract(str(native_built["fmi2"][model]), unzipdir=str(tmp_path))
    slave = FMU2Slave(guid=md.guid, unzipDirectory=folder, modelIdentifier=model, instanceName="me")
    assert not hasattr(slave.dll, "fmi2GetDerivatives") and hasattr(slave.dll, "fmi2DoStep")
    component = slave.fmi2Instantiate(b"me", 0, md.guid.encode(), Path(folder).as_uri().encode(), byref(callbacks),
                                      0, 1)  # 0: fmi2ModelExchange
    assert not component
    assert messages == [f"fmi2Instantiate: fmuType = 0 is invalid: allowed is fmi2CoSimulation (1); {model} is a "
                        "co-simulation FMU"], messages
