"""What FMI Library 3.0.4 (../shared/tools/fmil) logs about an FMI 3.0 FMU's
terminalsAndIcons/terminalsAndIcons.xml that is FMIL's gap, not the FMU's fault: it knows only part
of that schema, logs the <GraphicalRepresentation> and, per terminal, its ``matchingRule`` and
``description`` and each member's ``variableName``, ``memberName`` and ``variableKind`` as unknown
(errors and warnings of its XML parser), and goes on. The file is valid against the standard's
schema (tests/fmu/test_fmu_documentation.py), so for the native FMI 3.0 FMUs exactly those
messages are expected, one per element and attribute of the file, and nothing else.
"""

import re
import zipfile
from collections import Counter
from xml.etree import ElementTree as ET

TERMINALS = "terminalsAndIcons/terminalsAndIcons.xml"
# What FMIL 3.0.4 says about a valid terminalsAndIcons.xml (see the module docstring)
FMIL_ON_TERMINALS = re.compile(
    r"\[FMIL (?:parse|alone)\] (?:ERROR FMI3XML: (?:\[Line:\d+\] )?(?:Unknown element 'GraphicalRepresentation' in XML, "
    r"skipping|Unknown attribute '(?P<attribute>matchingRule|memberName|variableKind|variableName)=[^']*' in XML)"
    r"|WARNING FMI3XML: (?:\[Line:\d+\] )?(?:Skipping nested XML element '(?:CoordinateSystem|Icon)'"
    r"|Attribute 'description' not processed by element 'Terminal' handle))")


def terminal_messages(fmu) -> Counter:
    """The FMIL messages a native FMI 3.0 FMU's terminals give, by kind: one per attribute of
    each terminal and member, three for the graphical representation."""
    with zipfile.ZipFile(fmu) as z:
        root = ET.fromstring(z.read(TERMINALS))
    terminals, members = root.findall("Terminals/Terminal"), root.findall("Terminals/Terminal/TerminalMemberVariable")
    return Counter({"matchingRule": len(terminals), "description": len(terminals), "memberName": len(members),
                    "variableName": len(members), "variableKind": len(members), "graphical": 3})


def warnings_and_errors(kinds: Counter) -> tuple[int, int]:
    """How FMIL counts messages of these kinds: the graphical representation gives one error
    and two warnings, each terminal's description a warning, every other attribute an error."""
    warnings = kinds["description"] + (2 if kinds["graphical"] else 0)
    return warnings, kinds.total() - warnings


def fmil_messages(stderr: str) -> Counter:
    """FMIL's messages in ``stderr`` by kind; AssertionError on any other message."""
    kinds = Counter()
    for line in stderr.splitlines():
        match = FMIL_ON_TERMINALS.fullmatch(line)
        assert match, line
        kinds[match["attribute"] or ("description" if "description" in line else "graphical")] += 1
    return kinds
