"""Write the TAPMP system as an SSP 1.0 archive (SystemStructure.ssd plus the FMUs), and
address its elements by name or role.

The connections come from ``tapmp.interface.CONNECTIONS``; fmpy's SSD reader
(``fmpy.ssp.ssd.read_ssd``) validates the file against the SSP 1.0 schema.
"""

import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

from tapmp.interface import CONNECTIONS, ELEMENT, FMU_NAMES, UNITS, VARIABLES

SSD = "http://ssp-standard.org/SSP1/SystemStructureDescription"
SSC = "http://ssp-standard.org/SSP1/SystemStructureCommon"
ET.register_namespace("ssd", SSD)
ET.register_namespace("ssc", SSC)


# Role names (the scenario's tables, the recorded columns) -> the modelName of the FMU they address.
ROLES = {role: model for model, role in ELEMENT.items()}


class ParameterAddressError(ValueError):
    """A parameter table addresses no element, several, or sets a value twice; ``element`` names it."""

    def __init__(self, message: str, element: str):
        super().__init__(message)
        self.element = element


def resolve_parameters(parameters: dict, models: dict, ssp_path) -> dict:
    """``parameters`` ({table: {name: value}}) keyed by the SSP's element names.

    A key that names an element addresses it; a role name (:data:`ROLES`) the one element
    whose FMU is that role's model (``models``: {element: modelName}); an empty table sets
    nothing (e.g. [plant] of a system with its own plant FMU). ParameterAddressError for a
    role with no or several elements, an unknown key, or a value set by both name and role.
    The master and ``tapmp export`` both address elements through this function.
    """
    out = {}
    for key, table in parameters.items():
        if not table:
            continue
        if key in models:
            element = key
        elif key in ROLES:
            hits = [e for e, m in models.items() if m == ROLES[key]]
            if len(hits) != 1:
                what = "none" if not hits else f"{len(hits)} ({', '.join(hits)})"
                raise ParameterAddressError(
                    f"parameters [{key}] address the element whose FMU is {ROLES[key]}, and SSP file "
                    f"{ssp_path} has {what}: allowed is a table named after the element, one of "
                    f"{', '.join(models)}", key)
            element = hits[0]
        else:
            raise ParameterAddressError(
                f"parameters given for unknown element(s) {key}: allowed are {', '.join(models)} (or "
                f"{', '.join(ROLES)} for the element whose FMU is TAPMP_Plant, ...)", key)
        target = out.setdefault(element, {})
        for name, value in table.items():
            if name in target:
                raise ParameterAddressError(f"{element}.{name} is set twice (by the tables of the element name "
                                            "and of its role): allowed is one value", element)
            target[name] = value
    return out


def _q(ns: str, tag: str) -> str:
    return f"{{{ns}}}{tag}"


def system_structure(stop_time: float = 2.5) -> bytes:
    """The SystemStructure.ssd document of the three-FMU closed loop."""
    root = ET.Element(_q(SSD, "SystemStructureDescription"), version="1.0", name="TAPMP")
    system = ET.SubElement(root, _q(SSD, "System"), name="TAPMP",
                           description="TAPMP closed loop: trajectory -> controller -> plant -> controller")
    elements = ET.SubElement(system, _q(SSD, "Elements"))
    used_units = set()
    for model in FMU_NAMES:
        comp = ET.SubElement(elements, _q(SSD, "Component"), name=ELEMENT[model],
                             type="application/x-fmu-sharedlibrary", source=f"resources/{model}.fmu")
        connectors = ET.SubElement(comp, _q(SSD, "Connectors"))
        for v in VARIABLES[model]:
            if v.causality not in ("input", "output"):
                continue
            c = ET.SubElement(connectors, _q(SSD, "Connector"), name=v.name, kind=v.causality)
            ET.SubElement(c, _q(SSC, "Real"), unit=v.unit)
            used_units.add(v.unit)
    conns = ET.SubElement(system, _q(SSD, "Connections"))
    for src, src_var, dst, dst_var in CONNECTIONS:
        ET.SubElement(conns, _q(SSD, "Connection"), startElement=ELEMENT[src], startConnector=src_var,
                      endElement=ELEMENT[dst], endConnector=dst_var)
    units = ET.SubElement(root, _q(SSD, "Units"))
    for name in sorted(used_units):
        u = ET.SubElement(units, _q(SSC, "Unit"), name=name)
        ET.SubElement(u, _q(SSC, "BaseUnit"), {k: str(e) for k, e in UNITS[name].items()})
    ET.SubElement(root, _q(SSD, "DefaultExperiment"), startTime="0", stopTime=repr(stop_time))
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def write_ssp(path: Path, fmus: dict) -> Path:
    """Write the SSP archive to ``path`` with the FMUs given by model name; atomic."""
    path = Path(path)
    tmp = path.with_suffix(".tmp")
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("SystemStructure.ssd", system_structure())
        for model in FMU_NAMES:
            z.write(fmus[model], f"resources/{model}.fmu")
    tmp.replace(path)
    return path
