"""What FMI Library 3.0.4 (../shared/tools/fmil) logs about the FMI 3.0 FMUs' terminalsAndIcons.xml
that is FMIL's gap, not the FMU's fault: its terminalsAndIcons scheme knows only the attributes
fmiVersion, name and description and no GraphicalRepresentation, so every other attribute the FMI 3.0
schema defines (Terminal's matchingRule, TerminalMemberVariable's variableName, memberName and
variableKind) is logged as an error and the icon's elements as skipped. The file itself is valid
against the standard's schema (tests/fmu/test_fmu_documentation.py); FMIL goes on and the FMU runs.
"""

import re

GAPS = (
    r"ERROR FMI3XML: \[Line:\d+\] Unknown element 'GraphicalRepresentation' in XML, skipping",
    r"WARNING FMI3XML: \[Line:\d+\] Skipping nested XML element '(CoordinateSystem|Icon)'",
    r"ERROR FMI3XML: Unknown attribute '(matchingRule|variableName|memberName|variableKind)=[^']*' in XML",
    r"WARNING FMI3XML: Attribute 'description' not processed by element 'Terminal' handle",
)


def fmil_problems(log: str) -> list[str]:
    """The WARNING and ERROR lines of fmil_check's output ``log`` other than FMIL's GAPS."""
    return [line for line in log.splitlines() if re.search(r"\b(WARNING|ERROR)\b", line)
            and not any(re.search(gap, line) for gap in GAPS)]


def fmil_counts(log: str) -> tuple[int, int]:
    """(warnings, errors) that fmil_check's summary line "N steps, W warnings, E errors" (or
    "FMIL parse: W warnings, E errors") reports, less the lines of FMIL's GAPS in ``log``."""
    found = re.findall(r"(\d+) warnings, (\d+) errors", log)
    assert found, log
    warnings = sum(int(w) for w, _ in found)
    errors = sum(int(e) for _, e in found)
    gaps = [line for line in log.splitlines() if any(re.search(gap, line) for gap in GAPS)]
    return (warnings - sum("WARNING" in line for line in gaps), errors - sum("ERROR" in line for line in gaps))
