"""Python side of the FMU binary's fmi2Instantiate (see fmu_common/native/fmi2_python.c).

The binary has put the FMU's resources folder on sys.path; this finds the slave class
that ``pythonfmu build`` recorded in ``resources/slavemodule.txt`` and creates it.
"""

import importlib
from pathlib import Path

from fmu_common.slave import TapmpSlave


def instantiate(resources: str, instance_name: str, visible: int, logging_on: int) -> TapmpSlave:
    """Create the FMU's slave object for one fmi2Instantiate."""
    module_name = (Path(resources) / "slavemodule.txt").read_text().strip()
    cls = getattr(importlib.import_module(module_name), module_name)
    if not (isinstance(cls, type) and issubclass(cls, TapmpSlave)):
        raise TypeError(f"{module_name}.{module_name} is not a TapmpSlave subclass")
    slave = cls(instance_name=instance_name, resources=resources, visible=bool(visible))
    slave.logging_on = bool(logging_on)
    return slave
