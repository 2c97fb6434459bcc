"""One closed-loop FMU: TAPMP_ClosedLoop.fmu holds trajectory, controller and plant.

It is a container FMU for the runtime that fmpy 0.3.32 ships (``fmpy/container_fmu/
binaries/<platform>/container_fmu.so``, an FMI 2.0 co-simulation front that loads the
nested FMUs from ``resources/<element>/`` and reads ``resources/container.json``).
The container exposes every output of the three FMUs as an output and every parameter
as a parameter, named ``element.variable`` as in the SSP (e.g. ``plant.q1``,
``controller.Lambda_p1``); the inputs are connected inside, as in TAPMP.ssp.

How the runtime co-simulates (FMPy's native/container-fmu):
* every fixed step of ``fixedStepSize`` (1e-4 s) it steps all FMUs from t on the
  inputs of t, then copies outputs to inputs: the Jacobi ordering;
* fmi2ExitInitializationMode copies every connection once, in Initialization Mode,
  then every FMU leaves initialization; so the FMUs must report their initial
  outputs in Initialization Mode (the controller's F from q_d and q), which they do.
Under ``fmpy simulate`` at a 0.1 ms output interval its results equal the
orchestrator's Jacobi ordering bit for bit (tests/fmu/test_container_fmu.py).

Written here rather than with ``fmpy.container_fmu.cli.create_container_fmu`` because
that builder (0.3.32) writes the FMI 2 type name ``Real`` into ``connections``, which
the runtime rejects (``unknown variant `Real```; it expects ``Float64``), and its
modelDescription lacks units and descriptions. The runtime's value reference 0 is
always the container's time, so the modelDescription declares the independent
variable ``time`` first and container variable i of container.json is value
reference i + 1.
"""

import json
import shutil
import uuid
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

from fmpy import read_model_description

from tapmp.interface import (CONNECTIONS, DEFAULT_EXPERIMENT, ELEMENT, FMU_NAMES, TIME, VARIABLES, Dependencies,
                             dependencies)

from .model_description import fmi2_model_structure, to_bytes, unit_definitions

CONTAINER = "TAPMP_ClosedLoop"
RUNTIME_ID = "container_fmu"         # model identifier = the runtime library's name
PLATFORMS = {"linux64": "x86_64-linux", "win64": "x86_64-windows", "darwin64": "x86_64-darwin"}
_SUFFIX = {"linux64": ".so", "win64": ".dll", "darwin64": ".dylib"}
_TYPES = {"Real": "Float64", "Integer": "Int32"}   # FMI 2 type -> container.json type
STEP = DEFAULT_EXPERIMENT["stepSize"]               # s, the servo cycle


class ContainerError(RuntimeError):
    """The container FMU cannot be built; the message names the file or variable."""


def runtime_dir() -> Path:
    """fmpy's folder of container runtime binaries, one subfolder per platform tuple."""
    import fmpy.container_fmu
    return Path(fmpy.container_fmu.__file__).parent / "binaries"


def _runtime_version() -> str:
    import fmpy.container_fmu
    return fmpy.container_fmu.__version__


def _container_variables(fmus: dict) -> list[dict]:
    """The container's variables after ``time``: outputs, then parameters, per element
    in signal-flow order; each with its element, component variable and descriptions."""
    out = []
    for causality in ("output", "parameter"):
        for index, model in enumerate(FMU_NAMES):
            md = read_model_description(str(fmus[model]))
            table = {v.name: v for v in VARIABLES[model]}
            for mv in md.modelVariables:
                if mv.causality != causality:
                    continue
                var = table[mv.name]
                out.append({"name": f"{ELEMENT[model]}.{mv.name}", "component": index, "mv": mv,
                            "unit": var.unit, "description": f"{ELEMENT[model]}: {var.description}"})
    return out


def container_dependencies() -> dict[str, Dependencies]:
    """{"element.output": Dependencies} of the container's outputs, from the nested FMUs'
    (tapmp.interface.dependencies) followed through the connections: the container has no
    inputs, so its outputs depend on time and, in Initialization Mode, on the parameters
    that reach them (the runtime copies every connection once in Initialization Mode, so the
    controller's initial F follows the plant's initial q and the trajectory's q_d)."""
    nested = {m: dependencies(m) for m in FMU_NAMES}
    source = {(dst, dst_var): (src, src_var) for src, src_var, dst, dst_var in CONNECTIONS}

    def reach(model: str, output: str, kind: str, seen: frozenset) -> set:
        found = set()
        for known in getattr(nested[model][output], kind):
            if known == TIME:
                found.add(TIME)
            elif (model, known) in source:
                if (model, known) not in seen:
                    found |= reach(*source[model, known], kind, seen | {(model, known)})
            else:
                found.add(f"{ELEMENT[model]}.{known}")
        return found

    return {f"{ELEMENT[m]}.{name}": Dependencies(tuple(reach(m, name, "step", frozenset())),
                                                 tuple(reach(m, name, "initial", frozenset())))
            for m in FMU_NAMES for name in nested[m]}


def model_description(fmus: dict, guid: str, variables: list[dict]) -> bytes:
    """The container's modelDescription.xml (FMI 2.0 co-simulation)."""
    mds = [read_model_description(str(fmus[m])) for m in FMU_NAMES]
    root = ET.Element("fmiModelDescription", {
        "fmiVersion": "2.0", "modelName": CONTAINER, "guid": guid,
        "description": "TAPMP closed loop in one FMU: trajectory -> controller -> plant -> controller "
                       "(container of TAPMP_Trajectory, TAPMP_Controller, TAPMP_Plant; Jacobi "
                       "ordering at a fixed step of 0.1 ms)",
        "author": "TAPMP co-simulation project", "license": "MIT",
        "generationTool": f"tapmp orchestrator.builder.container (fmpy container runtime {_runtime_version()})",
        "variableNamingConvention": "structured", "numberOfEventIndicators": "0"})
    needs_tool = any(md.coSimulation.needsExecutionTool for md in mds)
    ET.SubElement(root, "CoSimulation", {
        "modelIdentifier": RUNTIME_ID, "needsExecutionTool": str(needs_tool).lower(),
        "canHandleVariableCommunicationStepSize": "true", "canBeInstantiatedOnlyOncePerProcess": "false",
        "canNotUseMemoryManagementFunctions": "true", "canGetAndSetFMUstate": "false",
        "canSerializeFMUstate": "false"})
    root.append(unit_definitions({"s"} | {v["unit"] for v in variables if v["unit"]}))  # "s": the time variable
    cats = ET.SubElement(root, "LogCategories")
    for name, text in (("logStatusError", "errors of the container"),
                       ("logNested", "messages of the nested FMUs"),
                       ("logFMICalls", "FMI calls to the nested FMUs")):
        ET.SubElement(cats, "Category", name=name, description=text)
    ET.SubElement(root, "DefaultExperiment", {k: repr(float(v)) for k, v in DEFAULT_EXPERIMENT.items()})
    mvs = ET.SubElement(root, "ModelVariables")
    sv = ET.SubElement(mvs, "ScalarVariable", name="time", valueReference="0", causality="independent",
                       variability="continuous", description="simulation time")
    ET.SubElement(sv, "Real", unit="s")
    outputs, index = [], {TIME: 1}
    for vr, v in enumerate(variables, start=1):
        index[v["name"]] = vr + 1
        mv = v["mv"]
        attrs = {"name": v["name"], "valueReference": str(vr), "causality": mv.causality,
                 "variability": mv.variability, "description": v["description"]}
        if mv.causality == "parameter":
            attrs["initial"] = "exact"
        sv = ET.SubElement(mvs, "ScalarVariable", attrs)
        typed = {}
        if mv.type == "Real" and v["unit"]:
            typed["unit"] = v["unit"]
        if mv.causality == "parameter":
            typed["start"] = str(mv.start)
        ET.SubElement(sv, mv.type, typed)
        if mv.causality == "output":
            outputs.append(v["name"])  # index: 1-based in ModelVariables; time is index 1
    fmi2_model_structure(ET.SubElement(root, "ModelStructure"), [(index[name], name) for name in outputs],
                         container_dependencies(), index)
    return to_bytes(root)


def configuration(fmus: dict, guid: str, variables: list[dict]) -> dict:
    """The runtime's resources/container.json."""
    mds = {m: read_model_description(str(fmus[m])) for m in FMU_NAMES}
    vrs = {m: {v.name: v for v in mds[m].modelVariables} for m in FMU_NAMES}
    components = [{"fmiMajorVersion": "2", "name": ELEMENT[m], "instantiationToken": mds[m].guid,
                   "modelIdentifier": mds[m].coSimulation.modelIdentifier, "path": ELEMENT[m]}
                  for m in FMU_NAMES]
    index = {m: i for i, m in enumerate(FMU_NAMES)}
    connections = []
    for src, src_var, dst, dst_var in CONNECTIONS:
        for model, name in ((src, src_var), (dst, dst_var)):
            if name not in vrs[model]:
                raise ContainerError(f"connection {ELEMENT[src]}.{src_var} -> {ELEMENT[dst]}.{dst_var}: "
                                     f"{model}.fmu has no variable {name!r}")
        connections.append({"variableType": _TYPES[vrs[src][src_var].type],
                            "srcComponent": index[src], "dstComponent": index[dst],
                            "srcValueReferences": [vrs[src][src_var].valueReference],
                            "dstValueReferences": [vrs[dst][dst_var].valueReference], "size": 1})
    return {"containerVersion": _runtime_version(), "instantiationToken": guid, "fixedStepSize": STEP,
            "parallelDoStep": False, "components": components,
            "variables": [{"variableType": _TYPES[v["mv"].type],
                           "mappings": [{"component": v["component"],
                                         "valueReference": v["mv"].valueReference}]}
                          for v in variables],
            "connections": connections}


def build_container(fmus: dict, out_dir: Path) -> Path:
    """Write TAPMP_ClosedLoop.fmu into out_dir from the FMUs given by model name; atomic.

    The runtime binary is included for the platforms every nested FMU has binaries for
    (linux64 for the TAPMP FMUs), so the container claims no platform it cannot run on.
    """
    out_dir = Path(out_dir)
    for model in FMU_NAMES:
        path = Path(fmus[model])
        if not zipfile.is_zipfile(path):
            raise ContainerError(f"{path} is not an FMU (no zip archive): build it first")
    guid = "{" + str(uuid.uuid5(uuid.NAMESPACE_URL, CONTAINER + "/" + "/".join(
        read_model_description(str(fmus[m])).guid for m in FMU_NAMES))) + "}"
    platforms = [p for p in PLATFORMS if all(
        any(n.startswith(f"binaries/{p}/") for n in zipfile.ZipFile(fmus[m]).namelist()) for m in FMU_NAMES)]
    if not platforms:
        raise ContainerError("the nested FMUs share no platform with fmpy's container runtime "
                             f"({', '.join(PLATFORMS)})")
    variables = _container_variables(fmus)
    target = out_dir / f"{CONTAINER}.fmu"
    tmp = target.with_suffix(".tmp")
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("modelDescription.xml", model_description(fmus, guid, variables))
        z.writestr("resources/container.json", json.dumps(configuration(fmus, guid, variables), indent=1))
        for model in FMU_NAMES:
            with zipfile.ZipFile(fmus[model]) as nested:
                for item in nested.infolist():
                    if item.is_dir():
                        continue
                    info = zipfile.ZipInfo(f"resources/{ELEMENT[model]}/{item.filename}", item.date_time)
                    info.external_attr, info.compress_type = item.external_attr, zipfile.ZIP_DEFLATED
                    z.writestr(info, nested.read(item))
        for fmi2_platform in platforms:
            lib = runtime_dir() / PLATFORMS[fmi2_platform] / f"{RUNTIME_ID}{_SUFFIX[fmi2_platform]}"
            if not lib.is_file():
                raise ContainerError(f"fmpy's container runtime {lib} is missing: install fmpy==0.3.32")
            info = zipfile.ZipInfo(f"binaries/{fmi2_platform}/{lib.name}", (2024, 1, 1, 0, 0, 0))
            info.external_attr, info.compress_type = 0o755 << 16, zipfile.ZIP_DEFLATED
            z.writestr(info, lib.read_bytes())
    shutil.move(tmp, target)
    return target
