"""Export a scenario as an SSP that other tools run as `tapmp run` does (`tapmp export`).

The exported SSP is the family's TAPMP.ssp (the same FMUs, the same SystemStructure.ssd)
with the scenario's parameter set added the way SSP 1.0 defines it:

* one SSP parameter set (SystemStructureParameterValues, ``.ssv``) per element,
  ``resources/<element>.ssv``, holding every value the scenario gives that element's FMU
  (the values of ``Scenario.parameters()``: trajectory, plant and controller tables, the 15
  gains, ``law`` and, with ``start_on_trajectory``, the plant's initial state X0 ... dB0)
  under the FMU's own variable names, typed (Real/Integer) and with units;
* in the SSD each ``ssd:Component`` gets ``<ssd:ParameterBindings><ssd:ParameterBinding
  source="resources/<element>.ssv"/>``: a binding on the component, so the names are the
  FMU's variable names (no prefix). Component-level bindings are what libcosim reads (it
  ignores system-level ones) and every SSP 1.0 reader understands them;
* every parameter set is named after the scenario, so a tool that selects sets by name
  (libcosim, Ecos ``--parameterSet``) finds the whole scenario under one name;
* ``ssd:DefaultExperiment`` gets the scenario's start and stop time [s] and three
  annotations: OMSimulator's (``org.openmodelica``: ``oms:SimulationInformation``, the result
  file ``<scenario>_res.csv``), the fixed step size for libcosim (``com.opensimulationplatform``:
  ``osp:FixedStepAlgorithm baseStepSize``) and the scenario's name, step, ordering, clock
  and connection start (``org.tapmp.scenario``), which SSP has no element for; the system's
  own OMSimulator annotation (``oms:FixedStepMaster stepSize``) gets the scenario's step.

``start_values`` gives the same values as ``--start-values`` arguments of ``fmpy simulate``
for the container FMU TAPMP_ClosedLoop.fmu, whose parameters are named ``element.variable``.
"""

import io
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

from ..builder import fmu_extras
from ..builder.fmu_extras import SSV, value_text
from ..engine.ssd import ParameterAddressError, resolve_parameters
from ..builder.ssp import SSC, SSD, default_experiment, qname, set_system_step
from .folders import atomic_file
from ..errors import UserError
from .roles import ROLES, SCENARIO_TABLES
from .scenario import Scenario

TAPMP_NS = "https://github.com/tapmp-cosim/ssp-annotations"
ET.register_namespace("ssv", SSV)
ET.register_namespace("tapmp", TAPMP_NS)
SSD_MEMBER = "SystemStructure.ssd"
SCENARIO_ANNOTATION = "org.tapmp.scenario"
# FMI 2.0 and FMI 3.0 variable types -> SSV parameter types
_SSV_TYPES = {"Real": "Real", "Float64": "Real", "Float32": "Real", "Integer": "Integer", "Int32": "Integer",
              "Int16": "Integer", "Int8": "Integer", "UInt32": "Integer", "UInt16": "Integer",
              "UInt8": "Integer", "Boolean": "Boolean", "String": "String"}


class ExportError(ValueError, UserError):
    """The scenario cannot be exported; the message names the path or variable and what is allowed."""


def _model_description(fmu_bytes: bytes) -> ET.Element:
    with zipfile.ZipFile(io.BytesIO(fmu_bytes)) as z:
        return ET.fromstring(z.read("modelDescription.xml"))


def _fmu_parameters(root: ET.Element) -> tuple[dict, dict]:
    """({parameter name: (SSV type, unit)}, {unit name: base-unit exponents}) of an FMU's
    modelDescription (FMI 2.0 ScalarVariable or FMI 3.0 typed variable elements)."""
    params = {}
    for mv in root.find("ModelVariables"):
        if mv.tag == "ScalarVariable":  # FMI 2.0: the type is a child element
            typed = next(iter(mv))
            kind, unit = typed.tag, typed.get("unit", "")
        else:                           # FMI 3.0: the element is the type
            kind, unit = mv.tag, mv.get("unit", "")
        if mv.get("causality") == "parameter" and kind in _SSV_TYPES:
            params[mv.get("name")] = (_SSV_TYPES[kind], unit)
    units = {}
    for u in root.findall("UnitDefinitions/Unit"):
        base = u.find("BaseUnit")
        units[u.get("name")] = dict(base.attrib) if base is not None else {}
    return params, units


def parameter_set(name: str, values: dict, declared: dict, units: dict, element: str) -> bytes:
    """One SSV document (builder.fmu_extras.parameter_set); ExportError names a variable the
    element's FMU does not declare."""
    try:
        return fmu_extras.parameter_set(name, values, declared, units, element)
    except ValueError as err:
        raise ExportError(str(err)) from None


def _default_experiment(root: ET.Element, scenario: Scenario) -> None:
    """Replace the SSD's DefaultExperiment with the scenario's times and step annotations and
    give the system OMSimulator's fixed-step master at the scenario's step."""
    for old in root.findall(qname(SSD, "DefaultExperiment")):
        root.remove(old)
    set_system_step(root.find(qname(SSD, "System")), scenario.step)
    exp = default_experiment(scenario.start_time, scenario.stop_time, scenario.step, f"{scenario.name}_res.csv")
    annotations = exp.find(qname(SSD, "Annotations"))
    own = ET.SubElement(annotations, qname(SSC, "Annotation"), type=SCENARIO_ANNOTATION)
    ET.SubElement(own, qname(TAPMP_NS, "Scenario"), name=scenario.name, step=repr(scenario.step),
                  ordering=scenario.ordering, clock=scenario.clock, connectionStart=scenario.connection_start,
                  eventMode="true" if scenario.event_mode else "false", law=scenario.law)
    # DefaultExperiment follows Units and precedes Annotations (SSD schema sequence)
    after = [i for i, child in enumerate(root) if child.tag != qname(SSD, "Annotations")]
    root.insert(after[-1] + 1 if after else 0, exp)


def _bind(component: ET.Element, source: str) -> None:
    """Give a Component one ParameterBinding to ``source``, placed where the SSD schema wants
    it (after Connectors and ElementGeometry, before Annotations)."""
    for old in component.findall(qname(SSD, "ParameterBindings")):
        component.remove(old)
    bindings = ET.Element(qname(SSD, "ParameterBindings"))
    ET.SubElement(bindings, qname(SSD, "ParameterBinding"), source=source)
    before = [i for i, c in enumerate(component) if c.tag in (qname(SSD, "Connectors"), qname(SSD, "ElementGeometry"))]
    component.insert(before[-1] + 1 if before else 0, bindings)


def exported_ssp(scenario: Scenario, source_ssp: Path) -> dict[str, bytes]:
    """The members of the exported SSP archive {name: bytes}: the source SSP's members, its
    SystemStructure.ssd with the bindings and default experiment, and one .ssv per element."""
    source_ssp = Path(source_ssp)
    try:
        with zipfile.ZipFile(source_ssp) as z:
            members = {info.filename: z.read(info) for info in z.infolist() if not info.is_dir()}
    except (zipfile.BadZipFile, OSError) as err:
        raise ExportError(f"SSP file {source_ssp} cannot be read ({err}): allowed is an SSP built by "
                          "`bash build_fmus.sh`") from None
    if SSD_MEMBER not in members:
        raise ExportError(f"SSP file {source_ssp} has no {SSD_MEMBER}: allowed is an SSP built by `bash build_fmus.sh`")
    root = ET.fromstring(members[SSD_MEMBER])
    components = {c.get("name"): c for c in root.iter(qname(SSD, "Component"))}
    descriptions = {}
    for element, component in components.items():
        fmu = component.get("source", "")
        if fmu not in members:
            raise ExportError(f"SSP file {source_ssp}: element {element} names {fmu!r}, which the archive lacks")
        descriptions[element] = _model_description(members[fmu])
    models = {element: md.get("modelName") for element, md in descriptions.items()}
    try:
        resolved = resolve_parameters(scenario.parameters(), models, source_ssp, ROLES, SCENARIO_TABLES)
    except ParameterAddressError as err:
        raise ExportError(str(err)) from None
    for element, table in resolved.items():
        component = components[element]
        declared, units = _fmu_parameters(descriptions[element])
        ssv = f"resources/{element}.ssv"
        members[ssv] = parameter_set(scenario.name, table, declared, units, element)
        _bind(component, ssv)
    _default_experiment(root, scenario)
    ET.indent(root)
    members[SSD_MEMBER] = ET.tostring(root, encoding="UTF-8", xml_declaration=True)
    return members


def start_values(scenario: Scenario) -> list[tuple[str, str]]:
    """The scenario's parameters as (``element.variable``, value text) pairs: the
    ``--start-values`` of ``fmpy simulate`` for the container FMU TAPMP_ClosedLoop.fmu."""
    from tapmp.models import built_models
    kinds = {f"{r.element}.{v.name}": v.type for r in built_models() for v in r.variables}  # the drive's too
    return [(f"{element}.{name}", value_text(kinds.get(f"{element}.{name}", "Real"), value))
            for element, table in scenario.parameters().items() for name, value in table.items()]


def start_values_path(out: Path) -> Path:
    """Where `tapmp export` writes the start values: FILE.ssp -> FILE.start-values.txt."""
    return Path(out).with_suffix(".start-values.txt")


def _write_atomic(path: Path, data: bytes | dict) -> None:
    """Write ``data`` (bytes, or {member: content} of a zip archive) to ``path`` under a temporary name,
    then renamed over it (folders.atomic_file: a symbolic link at ``path`` is refused, never followed)."""
    with atomic_file(path, "wb") as f:
        if isinstance(data, dict):
            with zipfile.ZipFile(f, "w", zipfile.ZIP_DEFLATED) as z:
                for name, content in data.items():
                    z.writestr(name, content)
        else:
            f.write(data)


def export(scenario: Scenario, source_ssp: Path, out: Path, overwrite: bool = False) -> tuple[Path, Path]:
    """Write the exported SSP to ``out`` (must end in .ssp: libcosim unpacks only .ssp files)
    and the container's start values next to it; return both paths. Existing files are
    refused unless ``overwrite``."""
    out = Path(out)
    if out.suffix != ".ssp":
        raise ExportError(f"--out {str(out)!r} is invalid: allowed is a file name ending in .ssp "
                          "(libcosim and Ecos recognise an SSP archive by that suffix)")
    values_file = start_values_path(out)
    for path in (out, values_file):
        if path.exists() and not overwrite:
            raise ExportError(f"{path} already exists: pass --overwrite to replace it")
    if out.resolve() == Path(source_ssp).resolve():
        raise ExportError(f"--out {out} is the source SSP itself: allowed is another file")
    members = exported_ssp(scenario, source_ssp)
    out.parent.mkdir(parents=True, exist_ok=True)
    _write_atomic(out, members)
    text = "".join(f"{name} {value}\n" for name, value in start_values(scenario))
    _write_atomic(values_file, text.encode())
    return out, values_file
