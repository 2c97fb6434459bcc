"""The SSP writer's two systems: TAPMP.ssp without the optional drive, TAPMP_Drive.ssp with it between
controller and plant (orchestrator/builder/ssp.py, the records' sources and feeds)."""

import re

from orchestrator.builder.ssp import system_structure
from tapmp.models import DRIVE


def components(ssd: str) -> list[str]:
    return re.findall(r'<ssd:Component name="(\w+)"', ssd)


def wire(start, out, end, into) -> str:
    return (f'<ssd:Connection startElement="{start}" startConnector="{out}" endElement="{end}" '
            f'endConnector="{into}" />')


def test_the_default_system_has_no_drive_and_the_controller_drives_the_plant():
    ssd = system_structure().decode()
    assert components(ssd) == ["trajectory", "controller", "plant"] and "drive" not in ssd
    assert all(wire("controller", f"F{i}", "plant", f"F{i}") in ssd for i in (1, 2, 3))


def test_the_drive_system_puts_the_drive_between_controller_and_plant():
    ssd = system_structure(extra=DRIVE).decode()
    assert components(ssd) == ["trajectory", "controller", "drive", "plant"]
    for i in (1, 2, 3):
        assert wire("controller", f"F{i}", "drive", f"F_cmd{i}") in ssd and wire("drive", f"F{i}", "plant", f"F{i}") in ssd
        assert wire("controller", f"F{i}", "plant", f"F{i}") not in ssd
    assert 'source="resources/TAPMP_Drive.fmu"' in ssd
    # everything else is the default system's
    assert ssd.count("<ssd:Connection ") == system_structure().decode().count("<ssd:Connection ") + 3
