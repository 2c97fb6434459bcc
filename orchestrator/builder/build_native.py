"""Build the self-contained native FMUs: FMI 2.0 and FMI 3.0, C sources inside, binaries
for Linux, Windows and macOS on x86-64 and ARM (compiled by Zig's C compiler from PyPI,
ctoolchain/__init__.py), no Python at run time. One C model (tapmp/c/tapmp_model.c) and one instance layer
(fmu_common/c, RUNTIME_SOURCES) feed both FMI versions; the model files (fmu_plant/plant.c,
fmu_controller/controller.c, fmu_controller/trajectory.c) map variables to the model.

Everything about the interface is generated here from ``tapmp.interface`` (one source
of truth): ``model_vars.h`` (value references, names, kinds, start values, ranges and the
reading of the parameters into the model's settings struct), ``tapmp_settings.h`` (the range
checks) and both modelDescription.xml files, so the native FMUs have exactly the names, causalities,
variabilities, units, descriptions, start values and value references of the pythonfmu
FMUs, and an SSP accepts either family.

Layout (``build/native/<fmi2|fmi3>/``): TAPMP_Plant.fmu, TAPMP_Controller.fmu,
TAPMP_Trajectory.fmu and TAPMP.ssp, TAPMP_Drive.fmu and TAPMP_Drive.ssp (the loop with the drive);
FMI 3.0 also TAPMP_ControllerClocked.fmu, the controller with a periodic input clock
(:func:`model_description_clocked`), and TAPMP_Clocked.ssp, the system with it.
Inside each FMU: modelDescription.xml, sources/ (every C file and header of the FMU, but not the
standard's FMI headers, which the importer brings; one file to compile, all.c, which includes the
others, so that only the fmi* functions have external linkage; FMI 2.0 lists it in <SourceFiles>,
both versions in sources/buildDescription.xml with libm), and binaries/ for every platform of PLATFORM_DIRS:
FMI 2.0 linux64, aarch64-linux, win64, win32 and darwin64 (one universal x86_64 + arm64 dylib);
FMI 3.0 x86_64-linux, aarch64-linux, x86_64-windows, x86-windows, x86_64-darwin and aarch64-darwin.
"""

import hashlib
import os
import shutil
import tempfile
import uuid
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

from concurrent.futures import ThreadPoolExecutor

from tapmp.interface import (CONTROLLER, DEFAULT_EXPERIMENT, TIME, VARIABLES, Var, dependencies,
                             dependency_attributes, settings_read_macro)
from tapmp.models import CLOCKED, built_models, names, optional_names, record
from tapmp.records import CLOCK_NAME
from tapmp.cmodel import SETTINGS_HEADER, settings_header
from tapmp import laws

import ctoolchain as toolchain
from .families import default_build_dir
from ..errors import UserError
from .model_description import fmi2_model_structure, to_bytes, unit_definitions
from ctoolchain import PLATFORMS, ToolchainError

# The package's root: the repository in a checkout, site-packages in an installed wheel
# (the C sources are package data there).
ROOT = Path(__file__).resolve().parents[2]
FAMILIES = ("fmi2", "fmi3")
NATIVE_BUILD_DIR = default_build_dir() / "native"
# The FMI runtime (fmu_common/c): every C file in that folder, read here once for everything that
# compiles or ships it (the native FMUs' sources/ and all.c, the pythonfmu binding, the tests' hosts
# through all.c). Files named fmi2_* / fmi3_* are one FMI version's API; the others are version neutral.
RUNTIME = ROOT / "fmu_common" / "c"
RUNTIME_SOURCES = tuple(p for p in sorted(RUNTIME.glob("*.c")) if not p.name.startswith(("fmi2_", "fmi3_")))
API = {family: tuple(sorted(RUNTIME.glob(f"{family}_*.c"))) for family in FAMILIES}
COMMON_SOURCES = (ROOT / "tapmp" / "c" / "tapmp_model.c", *RUNTIME_SOURCES)
COMMON_HEADERS = (ROOT / "tapmp" / "c" / "tapmp_model.h", *sorted(RUNTIME.glob("*.h")))
UNITY = "all.c"  # the one file to compile: the whole FMU as one translation unit
# binaries/ folder per family and platform (toolchain.PLATFORMS). FMI 2.0 names six platforms
# (win32/64, linux32/64, darwin32/64); for the others FMI 2.0.4 takes FMI 3.0's platform tuple,
# so ARM Linux is aarch64-linux in both versions. FMI 2.0's darwin64 is one universal dylib
# (x86_64 + arm64) so that a host on either Mac finds its code there.
PLATFORM_DIRS = {"fmi2": {"x86_64-linux": "linux64", "aarch64-linux": "aarch64-linux", "x86_64-windows": "win64",
                          "x86-windows": "win32", "x86_64-darwin": "darwin64", "aarch64-darwin": "darwin64"},
                 "fmi3": {p: p for p in PLATFORMS}}
ALL_PLATFORMS = tuple(PLATFORMS)
SUFFIX = toolchain.SUFFIX


def model_files(model: str) -> tuple[Path, Path]:
    """(model source, model header) of ``model``: its record's C files."""
    r = record(model)
    return ROOT / r.source, ROOT / r.header


def native_models(family: str) -> tuple[str, ...]:
    """The models built in ``family`` ("fmi2" or "fmi3"), in registry order: the base and the optional ones."""
    return tuple(r.name for r in built_models() if family in r.fmi_versions)


class NativeBuildError(RuntimeError, UserError):
    """Building a native FMU failed; the message says which step and why."""


def fmi_headers_dir() -> Path:
    """The FMI 2.0 and 3.0 standard headers (shipped with fmpy)."""
    import fmpy
    return Path(fmpy.__file__).parent / "c-code"


def instantiation_token(model: str) -> str:
    """GUID / instantiation token: a hash of the interface and the C sources, so a
    modelDescription.xml and a binary of different builds never match."""
    h = hashlib.sha256(model.encode())
    for v in VARIABLES[model]:
        h.update(repr(tuple(v)).encode())
    for path in (*COMMON_SOURCES, *COMMON_HEADERS, *model_files(model)):
        h.update(path.read_bytes())
    h.update(settings_header().encode())
    return "{" + str(uuid.UUID(bytes=h.digest()[:16], version=5)) + "}"


def _c_number(x) -> str:
    if x is None:
        return "HUGE_VAL"
    return repr(float(x))


def model_vars_header(model: str) -> str:
    """The generated model_vars.h of ``model``."""
    table = VARIABLES[model]
    header = model_files(model)[1].name
    lines = ["/* Generated by orchestrator/builder/build_native.py from tapmp/interface.py: do not edit. */",
             "#ifndef TAPMP_MODEL_VARS_H", "#define TAPMP_MODEL_VARS_H", "#include <math.h>",
             f'#include "{header}"', "",
             f'#define MODEL_IDENTIFIER_STRING "{model}"',
             f'#define INSTANTIATION_TOKEN "{instantiation_token(model)}"',
             f"#define N_VARS {len(table)}", "enum {"]
    lines += [f"    VR_{v.name} = {vr}," for vr, v in enumerate(table)]
    lines += ["};", "#define MODEL_VARS_INIT { \\"]
    for v in table:
        causality = {"input": "i", "output": "o", "parameter": "p"}[v.causality]
        variability = {"fixed": "f", "tunable": "t", "": "c"}[v.variability]
        lo = "-HUGE_VAL" if v.min is None else _c_number(v.min)
        lines.append(f"    {{\"{v.name}\", '{causality}', '{variability}', '{v.type[0]}', "
                     f"{_c_number(v.start)}, {lo}, {_c_number(v.max)}}}, \\")
    lines += ["}", settings_read_macro(model), "#endif", ""]
    return "\n".join(lines)


def unity_source(model: str, family: str) -> str:
    """sources/all.c: the FMU's C files included into one translation unit, with internal
    linkage for everything but the fmi2* / fmi3* functions (TAPMP_LINKAGE, tapmp_model.h).
    Functions of the shared model that this FMU does not call are marked unused for gcc and
    clang, which would otherwise warn about them."""
    parts = [p.name for p in (*COMMON_SOURCES, model_files(model)[0], *API[family])]
    return "\n".join([
        f"/* {model} ({'FMI 2.0' if family == 'fmi2' else 'FMI 3.0'}) as one translation unit: compile this "
        "file only. Generated by orchestrator/builder/build_native.py. */",
        "#if defined(__GNUC__) || defined(__clang__)",
        "#define TAPMP_LINKAGE static __attribute__((unused))",
        "#else",
        "#if defined(_MSC_VER)",
        "#pragma warning(disable : 4505) /* the shared model's functions this FMU does not call */",
        "#endif",
        "#define TAPMP_LINKAGE static",
        "#endif",
        "#define TAPMP_DEFINITION static",
        *(f'#include "{name}"' for name in parts), ""])


def source_files(model: str, family: str, model_source: Path | None = None) -> dict[str, bytes]:
    """Every file of the FMU's sources/ folder, by name; ``model_source`` replaces the model
    file (the benchmark's pass-through floor). The FMI headers are not among them: the
    importer compiles with its own (FMI 2.0.5 section 2.3, FMI 3.0 section 2.4)."""
    source, header = model_files(model)
    files = {p.name: p.read_bytes() for p in (*COMMON_SOURCES, *COMMON_HEADERS, header, *API[family])}
    files[source.name] = Path(model_source or source).read_bytes()
    files["model_vars.h"] = model_vars_header(model).encode()
    files[SETTINGS_HEADER] = settings_header().encode()
    files[UNITY] = unity_source(model, family).encode()
    files["buildDescription.xml"] = build_description(model)
    return files


def c_sources(model: str, family: str) -> list[str]:
    """The C files to compile: all.c, which includes the others."""
    return [UNITY]


def _number(x, integer: bool) -> str:
    return str(int(x)) if integer else repr(float(x))


def _categories_and_experiment(root: ET.Element, error_status: str) -> None:
    """LogCategories and DefaultExperiment, the same in both FMI versions."""
    cats = ET.SubElement(root, "LogCategories")
    ET.SubElement(cats, "Category", name="logStatusError", description=f"Log messages with {error_status} status.")
    ET.SubElement(cats, "Category", name="logStatusWarning",
                  description=f"Log messages with {error_status.replace('Error', 'Warning')} status.")
    ET.SubElement(cats, "Category", name="logAll", description="Log all messages.")
    ET.SubElement(root, "DefaultExperiment", {k: repr(float(v)) for k, v in DEFAULT_EXPERIMENT.items()})


def _common_attributes(v: Var, integer: bool) -> dict:
    attrs = {}
    if v.causality != "output":
        attrs["start"] = _number(v.start, integer)
    if v.unit and not integer:
        attrs["unit"] = v.unit
    if v.min is not None:
        attrs["min"] = _number(v.min, integer)
        attrs["max"] = _number(v.max, integer)
    return attrs


def _variability(v: Var) -> str:
    return v.variability or ("continuous" if v.type == "Real" else "discrete")


# Model Exchange (FMI 2.0 and 3.0, the plant): its continuous states (ModelRecord.me_states), in the order of
# fmi2GetContinuousStates / fmi3GetContinuousStates (fmu_plant/plant.c). Their derivatives der(X) ...
# der(dB) follow the table's variables: value references N_VARS ... in FMI 2.0, N_VARS + 1 ... in FMI
# 3.0 (after `time`). The model has no event indicators: see fmu_common/c/instance.h.
_DER_UNIT = {"m": "m/s", "rad": "rad/s", "m/s": "m/s2", "rad/s": "rad/s2"}


def _model_exchange(root: ET.Element, cs: ET.Element, model: str) -> None:
    """<ModelExchange> beside <CoSimulation>, under the same model identifier and sources."""
    me = ET.Element("ModelExchange", {
        "modelIdentifier": model, "needsExecutionTool": "false", "completedIntegratorStepNotNeeded": "true",
        "canBeInstantiatedOnlyOncePerProcess": "false", "canNotUseMemoryManagementFunctions": "true",
        "canGetAndSetFMUstate": "true", "canSerializeFMUstate": "true", "providesDirectionalDerivative": "false"})
    files = ET.SubElement(me, "SourceFiles")
    for f in cs.find("SourceFiles"):
        ET.SubElement(files, "File", name=f.get("name"))
    root.insert(list(root).index(cs), me)  # the schema's order: ModelExchange, CoSimulation


# Settings that do not enter the right-hand side (the measured positions and the CS integrator only)
_NOT_IN_RHS = {"encoder_resolution", "noise_rms", "noise_seed", "substeps"}


def state_derivative_dependencies(model: str) -> dict[str, tuple[tuple[str, ...], tuple[str, ...]]]:
    """{"der(X)": (what it depends on in Continuous-Time Mode, in Initialization Mode), ...} for
    Model Exchange, by variable name in the order of the variables: der(X) is dX (the state dX;
    initially its start dX0); der(dX) ... are the accelerations, of every state and the forces
    F1..F3, initially of every parameter of the right-hand side and the forces."""
    table = VARIABLES[model]
    states = record(model).me_states
    inputs = tuple(v.name for v in table if v.causality == "input")
    rhs = tuple(v.name for v in table if v.causality in ("input", "parameter") and v.name not in _NOT_IN_RHS)
    out = {}
    for k, state in enumerate(states):
        if k < 3:
            rate = states[k + 3]
            out[f"der({state})"] = ((rate,), (f"{rate}0",))
        else:
            out[f"der({state})"] = ((*states, *inputs), rhs)
    return out


def _state_derivatives(model: str, variables: ET.Element, structure: ET.Element, index: dict) -> None:
    """The state derivatives der(X) ... as local variables with their `derivative` attribute, listed in
    <Derivatives> and <InitialUnknowns> with what they depend on (:func:`state_derivative_dependencies`)."""
    table = VARIABLES[model]
    units = {v.name: v.unit for v in table}
    derivatives = ET.Element("Derivatives")
    initial = structure.find("InitialUnknowns")
    first = len(list(variables)) + 1
    for k, (name, (step, init)) in enumerate(state_derivative_dependencies(model).items()):
        state = record(model).me_states[k]
        sv = ET.SubElement(variables, "ScalarVariable", {
            "name": name, "valueReference": str(len(table) + k),
            "description": f"time derivative of {state} (Model Exchange)", "causality": "local",
            "variability": "continuous"})
        ET.SubElement(sv, "Real", {"derivative": str(index[state]), "unit": _DER_UNIT[units[state]]})
        ET.SubElement(derivatives, "Unknown", {"index": str(first + k),
                                               "dependencies": " ".join(str(index[n]) for n in step),
                                               "dependenciesKind": " ".join("dependent" for _ in step)})
        ET.SubElement(initial, "Unknown", {"index": str(first + k),
                                           "dependencies": " ".join(str(index[n]) for n in init),
                                           "dependenciesKind": " ".join("dependent" for _ in init)})
    structure.insert(list(structure).index(initial), derivatives)


def model_description_fmi2(model: str) -> bytes:
    """modelDescription.xml (FMI 2.0 co-simulation) of the native ``model``."""
    table = VARIABLES[model]
    root = ET.Element("fmiModelDescription", {
        "fmiVersion": "2.0", "modelName": model, "guid": instantiation_token(model),
        "description": record(model).description, "author": "TAPMP co-simulation project", "license": "MIT",
        "generationTool": "tapmp-cosim orchestrator/builder/build_native.py", "variableNamingConvention": "structured",
        "numberOfEventIndicators": "0"})
    cs = ET.SubElement(root, "CoSimulation", {
        "modelIdentifier": model, "needsExecutionTool": "false",
        "canHandleVariableCommunicationStepSize": "true", "canInterpolateInputs": "false",
        "maxOutputDerivativeOrder": "0", "canRunAsynchronuously": "false",
        "canBeInstantiatedOnlyOncePerProcess": "false", "canNotUseMemoryManagementFunctions": "true",
        "canGetAndSetFMUstate": "true", "canSerializeFMUstate": "true",
        "providesDirectionalDerivative": "false"})
    files = ET.SubElement(cs, "SourceFiles")
    for name in c_sources(model, "fmi2"):
        ET.SubElement(files, "File", name=name)
    units = [v.unit for v in table if v.unit]
    if record(model).me_states:
        _model_exchange(root, cs, model)
        units += [_DER_UNIT[v.unit] for v in table if v.name in record(model).me_states]
    root.append(unit_definitions(units))
    _categories_and_experiment(root, "fmi2Error")
    variables = ET.SubElement(root, "ModelVariables")
    outputs = []
    for vr, v in enumerate(table):
        sv = ET.SubElement(variables, "ScalarVariable", {
            "name": v.name, "valueReference": str(vr), "description": v.description,
            "causality": v.causality, "variability": _variability(v)})
        ET.SubElement(sv, v.type, _common_attributes(v, v.type == "Integer"))
        if v.causality == "output":
            outputs.append(vr + 1)
    index = {v.name: vr + 1 for vr, v in enumerate(table)}  # FMI 2.0 declares no independent variable
    structure = ET.SubElement(root, "ModelStructure")
    fmi2_model_structure(structure, [(i, table[i - 1].name) for i in outputs], dependencies(model), index)
    if record(model).me_states:
        _state_derivatives(model, variables, structure, index)
    return to_bytes(root)


# The models with time events (their C header defines MODEL_HAS_EVENTS): the controller, whose
# sample instants t0 + k T_s are time events in FMI 3.0's Event Mode. The plant is continuous and
# the trajectory a function of time: neither has an instant at which something jumps.
EVENT_MODELS = frozenset({"TAPMP_Controller"})


def event_mode_attributes(model: str) -> dict:
    """The FMI 3.0 co-simulation attributes of Event Mode for ``model``: hasEventMode and
    mightReturnEarlyFromDoStep (doStep stops at the next sample instant when the host allows early
    return); canReturnEarlyAfterIntermediateUpdate stays false (no intermediate update)."""
    events = "true" if model in EVENT_MODELS else "false"
    return {"mightReturnEarlyFromDoStep": events, "canReturnEarlyAfterIntermediateUpdate": "false",
            "hasEventMode": events}


def _model_exchange_fmi3(model: str) -> ET.Element:
    """FMI 3.0's <ModelExchange>, under the model identifier of <CoSimulation>: no event indicators
    and no discrete state, so neither completedIntegratorStep nor evaluateDiscreteStates is needed."""
    return ET.Element("ModelExchange", {
        "modelIdentifier": model, "needsExecutionTool": "false", "canBeInstantiatedOnlyOncePerProcess": "false",
        "canGetAndSetFMUState": "true", "canSerializeFMUState": "true",
        "providesDirectionalDerivatives": "false", "providesAdjointDerivatives": "false",
        "needsCompletedIntegratorStep": "false", "providesEvaluateDiscreteStates": "false"})


def _state_derivatives_fmi3(model: str, variables: ET.Element, structure: ET.Element, refs: dict,
                            place: dict) -> None:
    """FMI 3.0: the state derivatives der(X) ... as local Float64 variables (value references N_VARS + 1
    ...) with their `derivative` attribute, each a <ContinuousStateDerivative> and an <InitialUnknown>
    with what it depends on (:func:`state_derivative_dependencies`), in the schema's order."""
    table = VARIABLES[model]
    units = {v.name: v.unit for v in table}
    first = len(table) + 1  # after `time`
    derivatives, initial = [], []
    for k, (name, (step, init)) in enumerate(state_derivative_dependencies(model).items()):
        state = record(model).me_states[k]
        ET.SubElement(variables, "Float64", {
            "name": name, "valueReference": str(first + k), "description": f"time derivative of {state} (Model "
            "Exchange)", "causality": "local", "variability": "continuous", "unit": _DER_UNIT[units[state]],
            "derivative": str(refs[state])})
        derivatives.append(ET.Element("ContinuousStateDerivative", {"valueReference": str(first + k),
                                                                    **dependency_attributes(step, refs, place)}))
        initial.append(ET.Element("InitialUnknown", {"valueReference": str(first + k),
                                                     **dependency_attributes(init, refs, place)}))
    children = list(structure)
    at = next((i for i, e in enumerate(children) if e.tag != "Output"), len(children))
    for k, element in enumerate(derivatives):  # after the outputs, before the initial unknowns
        structure.insert(at + k, element)
    for element in initial:
        structure.append(element)


def model_description_fmi3(model: str) -> bytes:
    """modelDescription.xml (FMI 3.0 co-simulation, and Model Exchange for the plant) of the native ``model``."""
    table = VARIABLES[model]
    root = ET.Element("fmiModelDescription", {
        "fmiVersion": "3.0", "modelName": model, "instantiationToken": instantiation_token(model),
        "description": record(model).description, "author": "TAPMP co-simulation project", "license": "MIT",
        "generationTool": "tapmp-cosim orchestrator/builder/build_native.py", "variableNamingConvention": "structured"})
    if record(model).me_states:
        root.append(_model_exchange_fmi3(model))  # the schema's order: ModelExchange, CoSimulation
    ET.SubElement(root, "CoSimulation", {
        "modelIdentifier": model, "needsExecutionTool": "false", "canBeInstantiatedOnlyOncePerProcess": "false",
        "canGetAndSetFMUState": "true", "canSerializeFMUState": "true",
        "providesDirectionalDerivatives": "false", "providesAdjointDerivatives": "false",
        "canHandleVariableCommunicationStepSize": "true", "maxOutputDerivativeOrder": "0",
        "providesIntermediateUpdate": "false", **event_mode_attributes(model),
        "providesEvaluateDiscreteStates": "false"})
    units = [v.unit for v in table if v.unit]
    if record(model).me_states:
        units += [_DER_UNIT[v.unit] for v in table if v.name in record(model).me_states]
    root.append(unit_definitions(units))
    _categories_and_experiment(root, "fmi3Error")
    variables = ET.SubElement(root, "ModelVariables")
    ET.SubElement(variables, "Float64", name="time", valueReference=str(len(table)), causality="independent",
                  variability="continuous", description="simulation time")
    outputs = []
    for vr, v in enumerate(table):
        integer = v.type == "Integer"
        attrs = {"name": v.name, "valueReference": str(vr), "description": v.description,
                 "causality": v.causality, "variability": _variability(v)}
        attrs.update(_common_attributes(v, integer))
        ET.SubElement(variables, "Int32" if integer else "Float64", attrs)
        if v.causality == "output":
            outputs.append(vr)
    structure = ET.SubElement(root, "ModelStructure")
    refs = {TIME: len(table), **{v.name: vr for vr, v in enumerate(table)}}
    place = {TIME: 0, **{v.name: vr + 1 for vr, v in enumerate(table)}}  # time comes first
    deps = dependencies(model)
    for vr in outputs:
        ET.SubElement(structure, "Output", {"valueReference": str(vr),
                                            **dependency_attributes(deps[table[vr].name].step, refs, place)})
    for vr in outputs:
        ET.SubElement(structure, "InitialUnknown", {"valueReference": str(vr),
                                                    **dependency_attributes(deps[table[vr].name].initial, refs, place)})
    if record(model).me_states:
        _state_derivatives_fmi3(model, variables, structure, refs, place)
    return to_bytes(root)


# The clocked controller: the native FMI 3.0 controller as a separate model identifier, with a periodic
# input clock of interval T_s that clocks its sampled outputs. A separate FMU rather than a variant of
# TAPMP_Controller.fmu: an FMU with clocks must be run with eventModeUsed (FMI 3.0.2), so the one FMU could
# no longer be run without Event Mode, as every importer runs TAPMP_Controller today.
CLOCKED_DESCRIPTION = record(CLOCKED).description


def clocked_token() -> str:
    """The instantiation token of the clocked controller: its own, so that neither controller's binary
    accepts the other's modelDescription."""
    h = hashlib.sha256((CLOCKED + instantiation_token(CONTROLLER)).encode())
    for path in API["fmi3"]:
        h.update(path.read_bytes())
    return "{" + str(uuid.UUID(bytes=h.digest()[:16], version=5)) + "}"


def clocked_source_files() -> dict[str, bytes]:
    """sources/ of the clocked controller: the controller's, with a model_vars.h that names it and defines
    TAPMP_CLOCKED (controller.h: the input clock) and its own unity file and build description."""
    files = source_files(CONTROLLER, "fmi3")
    header = model_vars_header(CONTROLLER)
    include = f'#include "{model_files(CONTROLLER)[1].name}"'
    header = (header.replace(include, "#define TAPMP_CLOCKED\n" + include, 1)
              .replace(f'"{CONTROLLER}"', f'"{CLOCKED}"', 1)
              .replace(instantiation_token(CONTROLLER), clocked_token(), 1))
    files["model_vars.h"] = header.encode()
    files[UNITY] = unity_source(CONTROLLER, "fmi3").replace(CONTROLLER, CLOCKED, 1).encode()
    files["buildDescription.xml"] = build_description(CLOCKED)
    return files


def clock_interval() -> float:
    """The clock's interval in the modelDescription [s]: the start value of the parameter T_s."""
    return next(float(v.start) for v in VARIABLES[CONTROLLER] if v.name == "T_s")


def model_description_clocked() -> bytes:
    """modelDescription.xml of the clocked controller: the FMI 3.0 controller's, under its own model
    identifier and token, with the input clock ``sample_clock`` (intervalVariability ``fixed``: its interval
    is the fixed parameter T_s, so a host that sets T_s before initialization changes it, and it never
    changes afterwards) and every output clocked by it (variability discrete: an output changes only when
    the clock ticks). The inputs stay continuous: the controller samples the plant's continuous signals,
    and an importer may set them at any time between ticks."""
    root = ET.fromstring(model_description_fmi3(CONTROLLER))
    root.set("modelName", CLOCKED)
    root.set("instantiationToken", clocked_token())
    root.set("description", CLOCKED_DESCRIPTION)
    cs = root.find("CoSimulation")
    cs.set("modelIdentifier", CLOCKED)
    variables = root.find("ModelVariables")
    table = VARIABLES[CONTROLLER]
    clock_vr = len(table) + 1
    clock = ET.Element("Clock", {
        "name": CLOCK_NAME, "valueReference": str(clock_vr), "causality": "input", "variability": "discrete",
        "description": "the controller's sample clock: periodic, interval T_s, first tick at the start time; the "
                       "host activates it (fmi3SetClock in Event Mode) at every tick",
        "intervalVariability": "fixed", "intervalDecimal": repr(clock_interval()), "shiftDecimal": "0.0"})
    variables.insert(1, clock)  # after time
    for var in variables:
        if var.get("causality") == "output":
            var.set("variability", "discrete")
            var.set("clocks", str(clock_vr))
    structure = root.find("ModelStructure")
    for unknown in structure.findall("InitialUnknown"):  # clocked variables are no initial unknowns
        structure.remove(unknown)
    return to_bytes(root)


def build_clocked_controller(out_dir: Path, platforms=None, built: dict | None = None,
                             stimulus: dict | None = None) -> Path:
    """Build TAPMP_ControllerClocked.fmu (FMI 3.0) into ``out_dir``; atomic. ``platforms`` as for
    :func:`build_native_fmu` (default: all); ``built`` ({platform: bytes}) the binaries compiled already;
    ``stimulus``: fmu_extras.closed_loop_stimulus() (computed if None)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    fmu = out_dir / f"{CLOCKED}.fmu"
    platforms = check_platforms(ALL_PLATFORMS if platforms is None else platforms)
    files = clocked_source_files()
    md = model_description_clocked()
    from .fmu_extras import clocked_extra_members
    with tempfile.TemporaryDirectory(prefix="tapmp_native_") as tmp:
        src = staged_sources(files, CLOCKED, "fmi3")
        built = dict(built or {})
        for p in platforms:
            if p not in built:
                built[p] = _compile_one(Path(tmp), src, CLOCKED, "fmi3", p)
        binaries = _members({p: built[p] for p in platforms}, CLOCKED, "fmi3")
        # the reference experiment (with its tick schedule), documentation, license, terminals and icon
        host = _host_fmu(Path(tmp), src, CLOCKED, "fmi3", md, binaries)
        extra = clocked_extra_members(host, platforms, stimulus)
    _write_fmu(fmu, md, files, binaries, extra)
    return fmu


def write_clocked_ssp(path: Path, fmus: dict) -> Path:
    """The TAPMP system's SSP with the clocked controller in the controller element (``fmus``: {model name or
    CLOCKED: path}, as :func:`build_native` returns them); atomic. Run it with event_mode (the clock ticks
    only in Event Mode)."""
    from .ssp import system_structure
    path = Path(path)
    note = ("The TAPMP closed loop with the clocked controller (FMI 3.0): run it with Event Mode, activating the "
            f"controller's input clock {CLOCK_NAME} at every tick (tapmp run --set event_mode=true; FMPy's FMI 3.0 "
            "API: the TAPMP repository's examples/clocked_fmpy_host.py). Tools that do not tick input clocks "
            "(OMSimulator 3.0.0, fmusim, FMPy's simulate_fmu) cannot run it: use TAPMP.ssp.")
    ssd = system_structure(description=note).replace(f'source="resources/{CONTROLLER}.fmu"'.encode(),
                                     f'source="resources/{CLOCKED}.fmu"'.encode(), 1)
    tmp = path.with_suffix(".tmp")
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("SystemStructure.ssd", ssd)
        for model in (*(m for m in names() if m != CONTROLLER), CLOCKED):  # the clocked one in the controller's place
            z.write(fmus[model], f"resources/{model}.fmu")
    tmp.replace(path)
    return path


def build_description(model: str) -> bytes:
    """sources/buildDescription.xml of the native ``model``, the same in FMI 2.0 and 3.0 (FMI
    2.0.4 and later take the FMI 3.0 build description; it has precedence over <SourceFiles>).

    Two build configurations: Windows, where the math functions are part of the C runtime,
    and every other platform, which links the C math library libm from the system
    (``external="true"``: it is not shipped in binaries/). No -ffast-math and no fused
    multiply-add, to reproduce the reference results: gcc's and clang's -ffp-contract=off
    (the source switches contraction off for clang and MSVC by pragma too)."""
    root = ET.Element("fmiBuildDescription", fmiVersion="3.0")
    fallback = ET.SubElement(root, "BuildConfiguration", modelIdentifier=model,
                             description="Linux, macOS and other POSIX platforms (gcc or clang): C99, no "
                             "fused multiply-add, link the system's libm")
    files = ET.SubElement(fallback, "SourceFileSet", language="C99", compilerOptions="-ffp-contract=off")
    ET.SubElement(files, "SourceFile", name=UNITY)
    ET.SubElement(fallback, "Library", name="m", external="true", description="the C math library (libm)")
    windows = ET.SubElement(root, "BuildConfiguration", modelIdentifier=model, platform="x86_64-windows",
                            description="Windows (Visual C or mingw-w64): C99; the math functions are part of "
                            "the C runtime")
    files = ET.SubElement(windows, "SourceFileSet", language="C99")
    ET.SubElement(files, "SourceFile", name=UNITY)
    return to_bytes(root)


def compile_sources(sources_dir: Path, model: str, family: str, output: Path,
                    platform: str = toolchain.HOST) -> Path:
    """Compile the C files the FMU declares in ``sources_dir`` into the shared library
    ``output`` for ``platform`` (a name of toolchain.PLATFORMS), with the FMI headers an
    importer brings (FMPy's); NativeBuildError (one line: the FMU, the platform and the
    compiler's first error) if it fails."""
    files = [sources_dir / name for name in c_sources(model, family)]
    try:
        return toolchain.compile_c(files, output, platform, includes=[sources_dir, fmi_headers_dir()], libs=["m"],
                                   what=f"{family}/{model}.fmu")
    except ToolchainError as err:
        raise NativeBuildError(str(err)) from None


def _zip_write(z: zipfile.ZipFile, name: str, data: bytes) -> None:
    info = zipfile.ZipInfo(name, date_time=(2024, 1, 1, 0, 0, 0))  # reproducible archives
    info.compress_type = zipfile.ZIP_DEFLATED
    info.external_attr = 0o644 << 16
    z.writestr(info, data)


def _write_fmu(fmu: Path, md: bytes, files: dict, binaries: dict, extra: dict) -> None:
    """The FMU archive at ``fmu``: its modelDescription, sources/, binaries and extra members; the
    whole archive or nothing (written beside it, then renamed)."""
    partial = fmu.with_name(f".{fmu.name}.{os.getpid()}.tmp")
    try:
        with zipfile.ZipFile(partial, "w") as z:
            _zip_write(z, "modelDescription.xml", md)
            for name, data in sorted(files.items()):
                _zip_write(z, f"sources/{name}", data)
            for name, data in binaries.items():
                _zip_write(z, name, data)
            for name, data in sorted(extra.items()):
                _zip_write(z, name, data)
        partial.replace(fmu)
    finally:
        partial.unlink(missing_ok=True)


def staged_sources(files: dict[str, bytes], model: str, family: str) -> Path:
    """The FMU's sources/ written to a folder named by a hash of their content, under the
    system's temporary folder, and reused: zig cc's cache knows a C file by its path, so the
    same sources from the same path make a rebuild take about 0.1 s per binary instead of 1 s."""
    h = hashlib.sha256()
    for name, data in sorted(files.items()):
        h.update(name.encode() + b"\0" + hashlib.sha256(data).digest())
    folder = Path(tempfile.gettempdir()) / "tapmp-native-sources" / f"{model}-{family}-{h.hexdigest()[:20]}"
    if not folder.is_dir():
        folder.parent.mkdir(parents=True, exist_ok=True)
        partial = Path(tempfile.mkdtemp(prefix=f".{folder.name}.", dir=folder.parent))
        for name, data in files.items():
            (partial / name).write_bytes(data)
        try:
            partial.rename(folder)  # complete or absent, even with two builds at once
        except OSError:
            shutil.rmtree(partial, ignore_errors=True)
    return folder


def check_platforms(platforms) -> tuple[str, ...]:
    """The platforms as a tuple in PLATFORMS order; ValueError names an unknown one."""
    for p in platforms:
        toolchain.check_platform(p)
    return tuple(p for p in ALL_PLATFORMS if p in set(platforms))


def _compile_one(tmp: Path, src: Path, model: str, family: str, platform: str) -> bytes:
    """The bytes of ``model``'s binary for ``platform``, compiled in a folder of its own under ``tmp``."""
    folder = Path(tempfile.mkdtemp(prefix=f"{family}-{model}-{platform}-", dir=tmp))
    lib = folder / f"{model}{SUFFIX[toolchain.os_of(platform)]}"  # the name a dylib records
    return compile_sources(src, model, family, lib, platform).read_bytes()


def _members(built: dict[str, bytes], model: str, family: str) -> dict[str, bytes]:
    """{member name in the FMU: bytes} of the binaries ``built`` ({platform: bytes}); FMI 2.0's
    darwin64 is the universal file of both Macs."""
    members = {}
    for platform, data in built.items():
        folder = PLATFORM_DIRS[family][platform]
        name = f"binaries/{folder}/{model}{SUFFIX[toolchain.os_of(platform)]}"
        if folder == "darwin64":
            members[name] = toolchain.universal_macho([built[p] for p in ("x86_64-darwin", "aarch64-darwin")
                                                       if p in built])
        else:
            members[name] = data
    return members


def compile_every_binary(units: dict, platforms, tmp: Path, log=print, every: float = 10.0) -> dict:
    """Compile each unit ({(model, family): staged sources folder}) for each platform, all in one pool of
    compiler processes; returns {(model, family): {platform: bytes}}.

    The host's binaries come first (they are what runs here; the reference experiments need them),
    then one unit per platform at a time, so that every platform's first compile, which builds Zig's
    C runtime for that target into its cache (minutes for Windows on a cold cache), starts early and
    runs beside the others. ``log`` gets one line per family and platform when its binaries are
    done, and a line naming the platforms still compiling whenever ``every`` seconds pass without one."""
    import threading
    import time
    ordered = [toolchain.HOST] if toolchain.HOST in platforms else []
    ordered += [p for p in platforms if p != toolchain.HOST]
    jobs = [(unit, p) for p in ordered[:1] for unit in units]
    jobs += [(unit, p) for unit in units for p in ordered[1:]]  # round robin over the other platforms
    left = {(family, p): sum(1 for (m, f) in units if f == family) for (_, family) in units for p in ordered}
    built = {unit: {} for unit in units}
    start, lock = time.monotonic(), threading.Lock()
    last = [start]
    done = threading.Event()

    def say(line):
        with lock:
            last[0] = time.monotonic()
            log(line)

    def one(job):
        (model, family), platform = job
        data = _compile_one(tmp, units[(model, family)], model, family, platform)
        with lock:
            built[(model, family)][platform] = data
            left[(family, platform)] -= 1
            finished = left[(family, platform)] == 0
        if finished:
            say(f"native {family}: {platform} binaries done ({time.monotonic() - start:.0f} s)")

    def heartbeat():
        while not done.wait(1.0):
            now = time.monotonic()
            if now - last[0] >= every:
                with lock:
                    busy = sorted({p for (f, p), n in left.items() if n}, key=ordered.index)
                say(f"native: still compiling for {', '.join(busy)} ({now - start:.0f} s; a platform's first "
                    "build also builds Zig's C runtime for it, once per machine)")

    watcher = threading.Thread(target=heartbeat, daemon=True)
    watcher.start()
    toolchain.allow_compilers()
    # one compiler process per core beside the one waiting for its target's C runtime
    pool = ThreadPoolExecutor(max_workers=max(2, os.cpu_count() or 1) + 1)
    try:
        list(pool.map(one, jobs))
    except BaseException:
        # stopped (Ctrl-C, SIGTERM) or failed: drop the queued compiles and kill the running ones, so the
        # command ends now rather than after a target's C runtime (minutes)
        pool.shutdown(wait=False, cancel_futures=True)
        toolchain.stop_compilers()
        pool.shutdown()  # the killed compiles return at once
        toolchain.allow_compilers()
        raise
    finally:
        done.set()
        watcher.join()
    pool.shutdown()
    return built


def _host_fmu(tmp: Path, src: Path, model: str, family: str, md: bytes, binaries: dict) -> Path:
    """An FMU in ``tmp`` with the modelDescription and this machine's binary (compiled here if
    ``binaries`` lack it), for running the reference experiment at build time."""
    folder = PLATFORM_DIRS[family][toolchain.HOST]
    name = f"binaries/{folder}/{model}{SUFFIX[toolchain.os_of(toolchain.HOST)]}"
    if name not in binaries:
        (tmp / "host").mkdir()
        lib = compile_sources(src, model, family, tmp / "host" / Path(name).name, toolchain.HOST)
        binaries = {name: lib.read_bytes()}
    path = tmp / f"{model}.fmu"
    with zipfile.ZipFile(path, "w") as z:
        _zip_write(z, "modelDescription.xml", md)
        _zip_write(z, name, binaries[name])
    return path


def build_native_fmu(model: str, family: str, out_dir: Path, windows: bool = True,
                     model_source: Path | None = None, platforms=None, extras: bool = True,
                     stimulus: dict | None = None, built: dict | None = None) -> Path:
    """Build one native FMU (``family`` "fmi2" or "fmi3") into out_dir; atomic (a build that
    fails leaves no FMU of that name half written). ``platforms`` (names of
    toolchain.PLATFORMS) default to all, or the host's (x86_64-linux) alone if not ``windows``;
    ``model_source`` replaces the model's C file (benchmarks/floor_model.c). With ``extras``
    the FMU carries its reference experiment, documentation, license and (FMI 3.0) terminals
    and icon (fmu_extras.extra_members; ``stimulus``: fmu_extras.closed_loop_stimulus(), computed
    if None). ``built`` ({platform: bytes}) are binaries already compiled from these sources
    (:func:`compile_every_binary`); the platforms missing from it are compiled here."""
    from . import fmu_extras

    out_dir = Path(out_dir)
    fmu = out_dir / f"{model}.fmu"
    with tempfile.TemporaryDirectory(prefix="tapmp_native_") as tmp:
        files = source_files(model, family, model_source)
        src = staged_sources(files, model, family)
        if platforms is None:
            platforms = ALL_PLATFORMS if windows else (toolchain.HOST,)
        platforms = check_platforms(platforms)
        built = dict(built or {})
        missing = [p for p in platforms if p not in built]
        if missing:
            with ThreadPoolExecutor(max_workers=max(2, os.cpu_count() or 1)) as pool:
                built.update(zip(missing, pool.map(lambda p: _compile_one(Path(tmp), src, model, family, p),
                                                   missing)))
        binaries = _members({p: built[p] for p in platforms}, model, family)
        md = model_description_fmi2(model) if family == "fmi2" else model_description_fmi3(model)
        extra = {}
        if extras:
            host = _host_fmu(Path(tmp), src, model, family, md, binaries)
            folders = tuple(dict.fromkeys(PLATFORM_DIRS[family][p] for p in platforms))  # darwin64 once
            extra = fmu_extras.extra_members(model, family, host, folders, stimulus)
        _write_fmu(fmu, md, files, binaries, extra)
    return fmu


def build_native(out_dir: Path = NATIVE_BUILD_DIR, families=FAMILIES, log=print,
                 windows: bool | None = None, platforms=None) -> dict[str, dict[str, Path]]:
    """Build the native FMUs and a TAPMP.ssp per family into ``out_dir/<family>/``.

    Binaries for every platform of toolchain.PLATFORMS (``platforms`` to choose; ``windows=False``
    keeps the host's x86_64-linux alone). Returns {family: {model or "ssp": path}}.
    """
    from .ssp import FMI3_NOTE, write_ssp

    if platforms is None:
        platforms = ALL_PLATFORMS if windows is not False else (toolchain.HOST,)
    platforms = check_platforms(platforms)
    units = {(model, family): staged_sources(source_files(model, family), model, family)
             for family in families for model in native_models(family)}
    if "fmi3" in families:  # the clocked controller, beside the FMI 3.0 FMUs (not in the SSP)
        units[(CLOCKED, "fmi3")] = staged_sources(clocked_source_files(), CLOCKED, "fmi3")
    log(f"native: compiling {len(units)} FMUs ({', '.join(families)}) for {len(platforms)} platform(s): "
        f"{', '.join(platforms)}")
    with tempfile.TemporaryDirectory(prefix="tapmp_native_") as tmp:
        built = compile_every_binary(units, platforms, Path(tmp), log)
    # the reference experiments' inputs, the same for every family (after the FMUs' own sources
    # compiled: it runs the C model's library, so a compiler error names an FMU first)
    from .fmu_extras import closed_loop_stimulus
    stimulus = closed_loop_stimulus()
    out = {}
    for family in families:
        folder = Path(out_dir) / family
        folder.mkdir(parents=True, exist_ok=True)
        log(f"native {family}: writing the FMUs (each runs its reference experiment)")
        paths = {model: build_native_fmu(model, family, folder, platforms=platforms, stimulus=stimulus,
                                         built=built[(model, family)])
                 for model in native_models(family)}
        for model in native_models(family):
            log(f"built {paths[model]}")
        paths["ssp"] = write_ssp(folder / "TAPMP.ssp", paths, FMI3_NOTE if family == "fmi3" else None)
        log(f"wrote {paths['ssp']}")
        for model in optional_names():  # each optional model's own system: TAPMP_Drive.ssp
            if model in paths:
                paths[f"{model}_ssp"] = write_ssp(folder / f"{model}.ssp", paths, optional_note(model, family),
                                                  extra=model)
                log(f"wrote {paths[f'{model}_ssp']}")
        if family == "fmi3":
            paths[CLOCKED] = build_clocked_controller(folder, platforms, built[(CLOCKED, family)], stimulus)
            log(f"built {paths[CLOCKED]}")
            paths["clocked_ssp"] = write_clocked_ssp(folder / "TAPMP_Clocked.ssp", paths)
            log(f"wrote {paths['clocked_ssp']}")
        out[family] = paths
    return out


def optional_note(model: str, family: str) -> str:
    """The SSD description of the system with the optional ``model``: how it must be stepped (and FMI 3.0's
    note for OMSimulator)."""
    from .ssp import FMI3_NOTE
    from tapmp.interface import ELEMENT, step_order
    note = (f"The TAPMP closed loop with {model} between controller and plant. Step it Gauss-Seidel in the order "
            f"{', '.join(step_order(model))}: the {ELEMENT[model]}'s output after doStep(t, h) is its force over "
            "[t, t + h], like the "
            "controller's command, so the plant must step after it (a master that orders by the declared "
            "dependencies steps the plant first and adds one communication step of delay).")
    return f"{note} {FMI3_NOTE}" if family == "fmi3" else note


def main(argv=None) -> int:
    """``python -m orchestrator.builder.build_native [--out DIR] [--platform P ...]``."""
    import argparse
    import sys

    from tapmp.cmodel import CModelError

    p = argparse.ArgumentParser(prog="python -m orchestrator.builder.build_native",
                                description="Build the native FMI 2.0 and 3.0 FMUs and their TAPMP.ssp "
                                "into DIR/fmi2 and DIR/fmi3, with binaries for every platform (zig cc "
                                "from the ziglang package; $CC for x86_64-linux if set).")
    p.add_argument("--out", default=str(NATIVE_BUILD_DIR), help=f"output folder (default: {NATIVE_BUILD_DIR})")
    p.add_argument("--platform", action="append", metavar="P",
                   help=f"build only these platforms (repeatable): {', '.join(ALL_PLATFORMS)} (default: all)")
    p.add_argument("--no-windows", action="store_true", help="the host's x86_64-linux binaries only")
    args = p.parse_args(argv)
    for platform in args.platform or ():  # before building anything
        if platform not in PLATFORMS:
            print(f"error: --platform = {platform!r} is invalid: allowed are {', '.join(PLATFORMS)}", file=sys.stderr)
            return 2
    try:
        platforms = args.platform or (None if not args.no_windows else (toolchain.HOST,))
        build_native(Path(args.out), platforms=platforms)
    except (NativeBuildError, CModelError, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
