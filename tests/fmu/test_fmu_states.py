"""FMU states by the standard in every family (pythonfmu, native FMI 2.0 and 3.0): getting,
serializing and deserializing a state never changes the live instance, and a state is checked
whole (its mode, settings, outputs and the model's hidden values) before any of it is applied;
a crafted one is refused with a message naming the value. Through the real FMU binaries (fmpy)."""

import math

import pytest
from fmpy.fmi1 import FMICallException

from tests.support.fmu_host import Host
from tests.support.fmu_states import NATIVE_HIDDEN, SerializedState

FAMILIES = ("python", "fmi2", "fmi3")
PLANT, CONTROLLER = "TAPMP_Plant", "TAPMP_Controller"
FORCES = {"F1": 40.0, "F2": -25.0, "F3": 10.0}
PLANT_OUT = ("q1", "q2", "q3", "q1_true", "q2_true", "q3_true", "dq1", "dq2", "dq3", "X", "Z", "B", "dX", "dZ", "dB")
CONTROLLER_OUT = tuple(f"{n}{i}" for n in ("F", "u", "e", "es") for i in (1, 2, 3))
H = 1e-4


@pytest.fixture
def open_fmu(built, native_built, tmp_path):
    """open_fmu(family, model) -> a Host on a new instance; all are closed at the end."""
    hosts = []

    def make(family, model):
        path = built[model] if family == "python" else native_built[family][model]
        host = Host(path, tmp_path / f"{family}-{model}-{len(hosts)}", name=f"i{len(hosts)}")
        hosts.append(host)
        return host
    yield make
    for host in hosts:
        host.close()


def serialize(host) -> bytes:
    state = host.get_state()
    data = bytes(host.fmu.serializeFMUState(state) if host.fmi3 else host.fmu.serializeFMUstate(state))
    (host.fmu.freeFMUState if host.fmi3 else host.fmu.freeFMUstate)(state)
    return data


def deserialize(host, data: bytes):
    return host.fmu.deserializeFMUState(data) if host.fmi3 else host.fmu.deSerializeFMUstate(data)


def controller_inputs(k: int) -> dict:
    return {"X_d": 1e-5 * k, "q1": 2e-6 * k, "q2": 1e-6 * k, "q3": -1e-6 * k}


def run(host, model, k0, n):
    """n steps from step k0 (t = k0 H); every output after each."""
    rows = []
    for k in range(k0, k0 + n):
        if model == CONTROLLER:
            host.set(controller_inputs(k))
        host.do_step(k * H, H)
        rows.append(host.get(PLANT_OUT if model == PLANT else CONTROLLER_OUT))
    return rows


@pytest.mark.parametrize("model", (PLANT, CONTROLLER))
@pytest.mark.parametrize("family", FAMILIES)
def test_deserializing_a_state_without_setting_it_leaves_the_run_bit_identical(open_fmu, family, model):
    runs = []
    for deserialize_midway in (False, True):
        host = open_fmu(family, model)
        host.init({})
        if model == PLANT:
            host.set(FORCES)
        saved = serialize(host)  # at t = 0
        first = run(host, model, 0, 200)
        if deserialize_midway:
            state = deserialize(host, saved)  # kept, never set
        runs.append(first + run(host, model, 200, 200))
        if deserialize_midway:
            (host.fmu.freeFMUState if host.fmi3 else host.fmu.freeFMUstate)(state)
            runs.append(run(host, model, 400, 10))
        else:
            runs.append(run(host, model, 400, 10))
    assert runs[0] == runs[2] and runs[1] == runs[3]
    assert runs[0][-1] != runs[0][0]  # the run moved: a state of t = 0 applied would show


@pytest.mark.parametrize("family", FAMILIES)
def test_a_deserialized_state_set_replays_the_run_bit_for_bit(open_fmu, family):
    host = open_fmu(family, PLANT)
    host.init({})
    host.set(FORCES)
    run(host, PLANT, 0, 50)
    saved = serialize(host)
    first = run(host, PLANT, 50, 100)
    host.set_state(deserialize(host, saved))
    assert run(host, PLANT, 50, 100) == first


def _edit_hidden(state: SerializedState, family: str, model: str, name: str, value) -> None:
    """Set one hidden value by its native name (NATIVE_HIDDEN); in the pythonfmu family in the JSON."""
    if family != "python":
        hidden = state.hidden()
        hidden[NATIVE_HIDDEN[model].index(name)] = value
        state.set_hidden(hidden)
        return
    doc = state.json()
    if model == PLANT:
        doc[NATIVE_HIDDEN[PLANT].index(name)] = value
    elif name.startswith("integral"):
        doc[0][int(name[-1]) - 1] = value
    elif name == "k_last":
        doc[2][1] = value
    else:
        raise AssertionError(name)
    state.set_json(doc)


# (model, steps before the state is taken, the edit, the message it is refused with)
CRAFTED = {
    "Step Mode with no model built": (
        PLANT, 5, lambda s, family, model: s.set_header("has_model", 0),
        "FMU state: has_model = 0 is invalid in Step Mode: allowed is 1 (a model is built on entering "
        "Initialization Mode)"),
    "Instantiated with a model": (
        PLANT, 5, lambda s, family, model: s.set_header("mode", 0),
        "FMU state: has_model = 1 is invalid in Instantiated: allowed is 0 (no model is built before "
        "Initialization Mode)"),
    "plant B = 3 rad": (
        PLANT, 5, lambda s, family, model: _edit_hidden(s, family, model, "B", 3.0),
        "FMU state: plant state B = 3.0 is invalid: allowed is |B| < pi/2 rad (the kinematic domain)"),
    "plant state that its outputs contradict": (
        PLANT, 5, lambda s, family, model: _edit_hidden(s, family, model, "X", 0.25),
        "FMU state: output X = "),
    "plant sample count that is no count": (
        PLANT, 5, lambda s, family, model: _edit_hidden(s, family, model, "sample", 2.5),
        "FMU state: plant sample count = 2.5 is invalid: allowed is a whole number in [0, 2^53]"),
    "controller integral 1e290": (
        CONTROLLER, 5, lambda s, family, model: _edit_hidden(s, family, model, "integral1", 1e290),
        "FMU state: controller integral1 = 1e+290 is invalid: allowed is an integral whose term alone commands "
        "at most 1e9 N"),
    "controller k_last = 1e300": (
        CONTROLLER, 5, lambda s, family, model: _edit_hidden(s, family, model, "k_last", 1e300),
        "FMU state: controller clock k_last = 1e+300 is invalid: allowed is a whole number of sample periods"),
    "controller k_last after the state's time": (
        CONTROLLER, 5, lambda s, family, model: _edit_hidden(s, family, model, "k_last", 6),
        "FMU state: controller clock k_last = 6.0 is invalid"),
}


@pytest.mark.parametrize("case", CRAFTED)
@pytest.mark.parametrize("family", FAMILIES)
def test_a_crafted_state_is_refused_whole_with_a_message_naming_the_value(open_fmu, family, case):
    model, steps, edit, message = CRAFTED[case]
    host = open_fmu(family, model)
    host.init({})
    if model == PLANT:
        host.set(FORCES)
    run(host, model, 0, steps)
    data = serialize(host)
    deserialize(host, data)  # the state as it was is accepted
    crafted = SerializedState(data)
    edit(crafted, family, model)
    assert bytes(crafted) != data
    before = host.get(PLANT_OUT if model == PLANT else CONTROLLER_OUT)
    with pytest.raises(FMICallException):
        deserialize(host, bytes(crafted))
    errors = host.errors()
    assert len(errors) == 1 and message in errors[0] and errors[0].endswith("; nothing was changed"), errors
    assert host.get(PLANT_OUT if model == PLANT else CONTROLLER_OUT) == before


@pytest.mark.parametrize("family", FAMILIES)
def test_a_controller_state_with_an_integral_within_the_force_limit_is_accepted(open_fmu, family):
    """The bound follows force_limit: 1e-6 m s x Lambda_v D b / K_T = 395 N of integral force."""
    for limit, accepted in ((600.0, True), (300.0, False)):
        host = open_fmu(family, CONTROLLER)
        host.init({"force_limit": limit})
        run(host, CONTROLLER, 0, 5)
        state = SerializedState(serialize(host))
        _edit_hidden(state, family, CONTROLLER, "integral2", -1e-6)
        if accepted:
            host.set_state(deserialize(host, bytes(state)))
            assert math.isfinite(run(host, CONTROLLER, 5, 3)[-1][1])
        else:
            with pytest.raises(FMICallException):
                deserialize(host, bytes(state))
            assert "controller integral2 = -1e-06 is invalid: allowed is an integral whose term alone commands " \
                   "at most force_limit" in host.errors()[0]


@pytest.mark.parametrize("family", FAMILIES)
def test_time_only_moves_forward(open_fmu, family):
    host = open_fmu(family, PLANT)
    host.init({}, t0=1e6)
    host.do_step(1e6, H)
    t = 1e6 + H
    with pytest.raises(FMICallException):  # 0.9 ms back: a relative tolerance let 1000 of these pass
        host.do_step(t - 0.9e-3, 1e-12)
    assert "currentCommunicationPoint = 999999.9992 is invalid: allowed is the end of the previous step, " \
           "1000000.0001 s (within 1e-08 s)" in host.errors()[0], host.errors()

    host = open_fmu(family, PLANT)
    host.init({}, t0=1e6)
    with pytest.raises(FMICallException):  # within the tolerance, but ending before the previous end
        host.do_step(1e6 - 5e-9, 1e-12)
    assert "communicationStepSize = 1e-12 is invalid: allowed is a step whose end t + h = " in host.errors()[0]
    assert "lies after the end of the previous step, 1000000.0 s (time only moves forward" in host.errors()[0]

    host = open_fmu(family, PLANT)
    host.init({}, t0=1e6)
    host.do_step(1e6 - 5e-9, H)  # within the tolerance and ending after: OK
    host.do_step(1e6 - 5e-9 + H, H)
    assert host.errors() == []
