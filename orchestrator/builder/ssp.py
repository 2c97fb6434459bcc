"""Write the TAPMP system as an SSP 1.0 archive (SystemStructure.ssd plus the FMUs), and the
vendor annotations of its DefaultExperiment (``tapmp export`` writes them too). Reading an SSP
is orchestrator.engine.ssd.

The connections come from ``tapmp.interface.connections`` (the default system's, or with an optional
model such as the drive inserted); fmpy's SSD reader
(``fmpy.ssp.ssd.read_ssd``) validates the file against the SSP 1.0 schema.
"""

import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

from tapmp.interface import ELEMENT, UNITS, VARIABLES, connections
from tapmp.models import system_models

SSD = "http://ssp-standard.org/SSP1/SystemStructureDescription"
SSC = "http://ssp-standard.org/SSP1/SystemStructureCommon"
OSP = "http://opensimulationplatform.com/SSP/OSPAnnotations"
OMS = "https://raw.githubusercontent.com/OpenModelica/OMSimulator/master/schema/oms.xsd"
ET.register_namespace("ssd", SSD)
ET.register_namespace("ssc", SSC)
ET.register_namespace("osp", OSP)  # libcosim matches the literal prefix "osp:"
ET.register_namespace("oms", OMS)  # OMSimulator matches the literal prefix "oms:"
OSP_ANNOTATION = "com.opensimulationplatform"
OMS_ANNOTATION = "org.openmodelica"
SERVO_STEP = 1e-4     # [s] the communication step of the built SSPs, the FMUs' DefaultExperiment stepSize


def qname(ns: str, tag: str) -> str:
    """ElementTree's qualified name of ``tag`` in the XML namespace ``ns``: "{ns}tag"."""
    return f"{{{ns}}}{tag}"


def _oms_annotation(parent: ET.Element) -> ET.Element:
    """An ``ssc:Annotation`` of OMSimulator (type org.openmodelica) under ``parent``; its
    ``oms:Annotations`` element is returned."""
    annotation = ET.SubElement(parent, qname(SSC, "Annotation"), type=OMS_ANNOTATION)
    return ET.SubElement(annotation, qname(OMS, "Annotations"))


def default_experiment(start_time: float, stop_time: float, step: float, result_file: str) -> ET.Element:
    """``ssd:DefaultExperiment`` with the start and stop time [s] and the fixed step [s] in the
    vendor annotations SSP 1.0 leaves it to: OMSimulator's ``oms:SimulationInformation`` (its
    result file, every step recorded) and libcosim's ``osp:FixedStepAlgorithm``.

    OMSimulator reads only the first ``ssc:Annotation`` here, so its own comes first.
    """
    exp = ET.Element(qname(SSD, "DefaultExperiment"), startTime=repr(float(start_time)), stopTime=repr(float(stop_time)))
    annotations = ET.SubElement(exp, qname(SSD, "Annotations"))
    ET.SubElement(_oms_annotation(annotations), qname(OMS, "SimulationInformation"), resultFile=result_file,
                  loggingInterval="0", bufferSize="1")
    osp = ET.SubElement(annotations, qname(SSC, "Annotation"), type=OSP_ANNOTATION)
    algorithm = ET.SubElement(osp, qname(OSP, "Algorithm"))
    ET.SubElement(algorithm, qname(OSP, "FixedStepAlgorithm"), baseStepSize=repr(float(step)))
    return exp


def set_system_step(system: ET.Element, step: float) -> None:
    """Give the ``ssd:System`` OMSimulator's fixed-step master with ``step`` [s] in its vendor
    annotation (OMSimulator derives the system's kind from it and refuses a system without it),
    replacing an earlier one; the annotations go last in the System (SSD schema sequence)."""
    for old in system.findall(qname(SSD, "Annotations")):
        for annotation in old.findall(qname(SSC, "Annotation")):
            if annotation.get("type") == OMS_ANNOTATION:
                old.remove(annotation)
        if not len(old):
            system.remove(old)
    annotations = system.find(qname(SSD, "Annotations"))
    if annotations is None:
        annotations = ET.SubElement(system, qname(SSD, "Annotations"))
    info = ET.SubElement(_oms_annotation(annotations), qname(OMS, "SimulationInformation"))
    ET.SubElement(info, qname(OMS, "FixedStepMaster"), description="oms-ma", stepSize=repr(float(step)))


# What an importer of the FMI 3.0 SSPs must know, in their SSD's description: OMSimulator reads its loop
# solver from its command line only (Flags::AlgLoopSolver; no SSP annotation sets it).
FMI3_NOTE = ("The TAPMP closed loop of FMI 3.0 FMUs. OMSimulator 3.0.0: run it with --algLoopSolver=fixedpoint "
             "(OMSimulator reads no output dependencies from FMI 3.0 FMUs and assumes an algebraic loop, which its "
             "default solver KINSOL cannot solve without directional derivatives: without the flag it exits 0 with "
             "KINSol errors and writes no result file; the fixed-point solver converges at once, as there is no "
             "loop, and gives the FMI 2.0 results bit for bit). Its result file has two rows per time, before and "
             "after it passes the outputs on to the inputs: the outputs are equal in both.")


def system_structure(stop_time: float = 2.5, step: float = SERVO_STEP, description: str | None = None,
                     extra: str = "") -> bytes:
    """The SystemStructure.ssd document of the three-FMU closed loop, run from 0 to
    ``stop_time`` [s] at the fixed communication step ``step`` [s] (given for OMSimulator and
    libcosim in their vendor annotations); ``description``: the SSD's own (what an importer must know);
    ``extra``: an optional model inserted into the loop (tapmp.models.ModelRecord.optional, the drive)."""
    models = tuple(r.name for r in system_models(extra))
    root = ET.Element(qname(SSD, "SystemStructureDescription"), version="1.0", name="TAPMP")
    if description:
        root.set("description", description)
    flow = " -> ".join(ELEMENT[m] for m in models if m != models[0])  # the trajectory feeds the loop
    system = ET.SubElement(root, qname(SSD, "System"), name="TAPMP",
                           description=f"TAPMP closed loop: {ELEMENT[models[0]]} -> {flow} -> controller")
    elements = ET.SubElement(system, qname(SSD, "Elements"))
    used_units = set()
    for model in models:
        comp = ET.SubElement(elements, qname(SSD, "Component"), name=ELEMENT[model],
                             type="application/x-fmu-sharedlibrary", source=f"resources/{model}.fmu")
        connectors = ET.SubElement(comp, qname(SSD, "Connectors"))
        for v in VARIABLES[model]:
            if v.causality not in ("input", "output"):
                continue
            c = ET.SubElement(connectors, qname(SSD, "Connector"), name=v.name, kind=v.causality)
            ET.SubElement(c, qname(SSC, "Real"), unit=v.unit)
            used_units.add(v.unit)
    conns = ET.SubElement(system, qname(SSD, "Connections"))
    for src, src_var, dst, dst_var in connections(extra):
        ET.SubElement(conns, qname(SSD, "Connection"), startElement=ELEMENT[src], startConnector=src_var,
                      endElement=ELEMENT[dst], endConnector=dst_var)
    units = ET.SubElement(root, qname(SSD, "Units"))
    for name in sorted(used_units):
        u = ET.SubElement(units, qname(SSC, "Unit"), name=name)
        ET.SubElement(u, qname(SSC, "BaseUnit"), {k: str(e) for k, e in UNITS[name].items()})
    set_system_step(system, step)
    root.append(default_experiment(0.0, stop_time, step, f"{root.get('name')}_res.csv"))
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def write_ssp(path: Path, fmus: dict, description: str | None = None, extra: str = "") -> Path:
    """Write the SSP archive to ``path`` with the FMUs given by model name (``description``: the SSD's;
    ``extra``: the optional model inserted, see :func:`system_structure`); atomic."""
    path = Path(path)
    tmp = path.with_suffix(".tmp")
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("SystemStructure.ssd", system_structure(description=description, extra=extra))
        for model in (r.name for r in system_models(extra)):
            z.write(fmus[model], f"resources/{model}.fmu")
    tmp.replace(path)
    return path
