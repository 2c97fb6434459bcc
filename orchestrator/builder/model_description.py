"""The modelDescription.xml elements every FMU family writes the same way.

One writer each for the unit definitions, the FMI 2.0 model structure and the serialized
document, used by the pythonfmu family (build.complete_model_description), the native FMI 2.0
and 3.0 families (build_native.model_description_fmi2 / _fmi3) and the closed-loop container
(container.model_description), so the units and dependencies the families declare cannot drift
apart. The units and their SI base-unit exponents are tapmp.interface.UNITS.
"""

from xml.etree import ElementTree as ET

from tapmp.interface import UNITS, dependency_attributes


def unit_definitions(used) -> ET.Element:
    """<UnitDefinitions> (the same element in FMI 2.0 and 3.0): one <Unit> per name in ``used``
    (keys of tapmp.interface.UNITS, e.g. "m", "N.s/m"), sorted by name, each with a <BaseUnit>
    holding its SI base-unit exponents (kg, m, s, rad)."""
    units = ET.Element("UnitDefinitions")
    for name in sorted(set(used)):
        unit = ET.SubElement(units, "Unit", name=name)
        ET.SubElement(unit, "BaseUnit", {k: str(e) for k, e in UNITS[name].items()})
    return units


def fmi2_model_structure(structure: ET.Element, outputs, deps: dict, index: dict) -> None:
    """Fill an FMI 2.0 <ModelStructure>: <Outputs> then <InitialUnknowns>, one <Unknown> per
    output in the order of ``outputs`` ((index in ModelVariables, 1-based; name) pairs).
    ``deps``: name -> tapmp.interface.Dependencies (step: what the output depends on after
    doStep, initial: in Initialization Mode); ``index``: name -> index of every declared known."""
    out = ET.SubElement(structure, "Outputs")
    init = ET.SubElement(structure, "InitialUnknowns")
    for i, name in outputs:
        ET.SubElement(out, "Unknown", {"index": str(i), **dependency_attributes(deps[name].step, index)})
    for i, name in outputs:
        ET.SubElement(init, "Unknown", {"index": str(i), **dependency_attributes(deps[name].initial, index)})


def to_bytes(root: ET.Element) -> bytes:
    """The document of ``root`` as written into an FMU: indented, UTF-8, with the XML declaration."""
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)
