"""Write the TAPMP system as an SSP 1.0 archive (SystemStructure.ssd plus the FMUs).

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
