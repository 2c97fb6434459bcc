"""Every input starts at the value its connected output has at the start of the paper's run
(tapmp.interface.START_OUTPUTS): the controller at the trajectory's initial reference and the plant's
initial encoder positions and velocities, the plant at the controller's first command. So a host that
initializes each FMU alone, in any order, without passing a value in Initialization Mode, computes the
paper run's first command and steps the plant with it: a Jacobi host that never propagates gives
`tapmp run --set ordering=jacobi` bit for bit."""

import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np

import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

from tapmp.interface import CONNECTIONS, ELEMENT, START_OUTPUTS, VARIABLES
from tests.support.fmu_host import ssp_fmi2_units
from tests.support.runs import orchestrator_rows, paper_scenario

pytestmark = pytest.mark.slow  # builds the native FMUs for this machine

STEP, STOP = 1e-4, 0.2


@pytest.fixture(scope="module")
def native(tmp_path_factory):
    """The native FMI 2.0 and 3.0 FMUs and SSPs, built for this machine."""
    from orchestrator.builder.build_native import build_native
    return build_native(tmp_path_factory.mktemp("native"), log=lambda *_: None, windows=False)


def connected_outputs_at_start(ssp):
    """{(element, output): value} of every connected output in the first row of the paper's run."""
    names = [f"{ELEMENT[src]}.{out}" for src, out, _, _ in CONNECTIONS]
    row = orchestrator_rows(ssp, paper_scenario(STEP), names, "gauss-seidel")[0]
    return dict(zip(names, row))


def start_attributes(fmu) -> dict[str, str]:
    """{input name: its start attribute} in ``fmu``'s modelDescription.xml (FMI 2.0 or 3.0)."""
    with zipfile.ZipFile(fmu) as z:
        root = ET.fromstring(z.read("modelDescription.xml"))
    out = {}
    for var in root.find("ModelVariables"):
        if var.get("causality") == "input" and var.tag != "Clock":
            typed = var if root.get("fmiVersion") == "3.0" else var[0]
            out[var.get("name")] = typed.get("start")
    return out


def test_every_inputs_start_value_is_its_connected_outputs_value_at_the_start_of_the_paper_run(native):
    at_start = connected_outputs_at_start(native["fmi2"]["ssp"])
    for src, out, dst, inp in CONNECTIONS:
        value = at_start[f"{ELEMENT[src]}.{out}"]
        start = next(v.start for v in VARIABLES[dst] if v.name == inp)
        assert start == value and np.signbit(start) == np.signbit(value), (dst, inp, start, value)
        assert START_OUTPUTS[out] == value
    assert abs(START_OUTPUTS["F1"]) > 15.0 and START_OUTPUTS["dq1"] > 0.03  # the paper's, not zeros


def test_both_native_families_and_the_clocked_controller_declare_those_start_values(native):
    for family, fmus in native.items():
        for model in (m for m, path in fmus.items() if Path(path).suffix == ".fmu"):
            table = "TAPMP_Controller" if model == "TAPMP_ControllerClocked" else model
            declared = start_attributes(fmus[model])
            expected = {v.name: repr(float(v.start)) for v in VARIABLES[table] if v.causality == "input"}
            assert declared == expected, (family, model)


def test_the_pythonfmu_family_starts_its_inputs_there_too(built, tmp_path):
    """The pythonfmu FMUs hold those doubles as their inputs' defaults (read back with nothing set); their
    modelDescription writes them as pythonfmu does every start value, to 16 significant digits."""
    for model in ("TAPMP_Controller", "TAPMP_Plant"):
        starts = {v.name: v.start for v in VARIABLES[model] if v.causality == "input"}
        declared = {n: float(x) for n, x in start_attributes(built[model]).items()}
        assert declared == {n: float(f"{x:.16g}") for n, x in starts.items()}, model
        md = read_model_description(str(built[model]))
        refs = {v.name: v.valueReference for v in md.modelVariables}
        slave = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(built[model]), unzipdir=str(tmp_path / model)),
                          modelIdentifier=md.coSimulation.modelIdentifier, instanceName=model)
        slave.instantiate()
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        assert slave.getReal([refs[n] for n in starts]) == list(starts.values()), model
        slave.terminate()
        slave.freeInstance()


def jacobi_without_propagation(ssp, folder, order) -> tuple[list[str], np.ndarray]:
    """The SSP's FMI 2.0 FMUs in FMPy, each initialized alone at its start values in ``order`` (nothing set
    in Initialization Mode), then Jacobi steps (every FMU from t on the outputs of t) of STEP up to STOP;
    (columns "element.output", rows at t_0 ... t_n)."""
    units, links = ssp_fmi2_units(ssp, folder)
    value = {}

    def read(name):
        slave, refs, outputs = units[name]
        value.update(zip((f"{name}.{o}" for o in outputs), slave.getReal([refs[o] for o in outputs])))

    for name in order:
        slave = units[name][0]
        slave.instantiate()
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        read(name)
    columns = sorted(value)
    rows = [[value[c] for c in columns]]
    for k in range(round(STOP / STEP)):
        for a, output, b, inp in links:
            units[b][0].setReal([units[b][1][inp]], [value[f"{a}.{output}"]])
        for name in order:
            units[name][0].doStep(k * STEP, STEP)
        for name in order:
            read(name)
        rows.append([value[c] for c in columns])
    for slave, _, _ in units.values():
        slave.terminate()
        slave.freeInstance()
    return columns, np.array(rows)


@pytest.mark.parametrize("order", [("trajectory", "controller", "plant"), ("plant", "controller", "trajectory")])
def test_a_jacobi_host_that_never_propagates_gives_tapmp_run_jacobi_bit_for_bit(native, tmp_path, order):
    """In the SSP's order and in the reverse one: every output at every one of the 2,001 rows."""
    ssp = native["fmi2"]["ssp"]
    columns, rows = jacobi_without_propagation(ssp, tmp_path, order)
    expected = orchestrator_rows(ssp, paper_scenario(STOP), columns, "jacobi")
    assert rows.shape == expected.shape == (round(STOP / STEP) + 1, len(columns))
    np.testing.assert_array_equal(rows, expected)
    assert np.abs(rows[:, columns.index("controller.F1")]).max() > 1.0


def test_without_those_start_values_the_first_command_is_not_the_paper_runs():
    """What the start values change: the controller's first command from inputs at 0 (a host that neither
    propagates nor has these start values) is 15.57 N on motor 1, not the paper run's 15.32 N."""
    from tapmp.control import ControllerModel, Gains
    from tapmp.params import GAIN_PRESETS, PAPER_MODEL

    def first_command(inputs):
        model = ControllerModel(PAPER_MODEL, Gains.from_preset(GAIN_PRESETS["default"]), 0)
        return model.sample(0.0, STEP, inputs[:9], inputs[9:12], inputs[12:15], advance=False)[0]

    starts = [v.start for v in VARIABLES["TAPMP_Controller"] if v.causality == "input"]
    assert tuple(first_command(starts)) == (START_OUTPUTS["F1"], START_OUTPUTS["F2"], START_OUTPUTS["F3"])
    assert round(first_command([0.0] * 15)[0], 2) == 15.57 and round(START_OUTPUTS["F1"], 2) == 15.32
