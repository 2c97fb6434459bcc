"""Python side of the FMU binary's fmi2Instantiate (see fmu_common/native/fmi2_python.c).

The binary has put the FMU's resources folder on sys.path; this loads the adapter script
that ``pythonfmu build`` recorded in ``resources/slavemodule.txt`` and creates its class.
The script is loaded from this FMU's own file under a name unique to its location, so
two FMUs whose adapters share a module name (two builds of TAPMP_Plant, say) never run
each other's code in one process.
"""

import importlib.util
import sys
from pathlib import Path

from fmu_common.slave import TapmpSlave


def _load_adapter(resources: Path, module_name: str):
    path = (resources / f"{module_name}.py").resolve()
    key = f"_tapmp_fmu.{module_name}.{abs(hash(str(path))):x}"
    module = sys.modules.get(key)
    if module is None:
        spec = importlib.util.spec_from_file_location(key, path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[key] = module
        try:
            spec.loader.exec_module(module)
        except BaseException:
            del sys.modules[key]
            raise
    return module


GUID_FILE = "guid.txt"  # in resources/: the guid of the FMU's modelDescription.xml, written at build time


class GuidMismatch(ValueError):
    """The host's fmuGUID is not the one of this FMU's modelDescription.xml."""


def _own_guid(resources: Path) -> str:
    # The standard guarantees only the resources folder to the FMU (fmpy simulate unpacks
    # nothing else), so the guid is read from its copy there, not from ../modelDescription.xml.
    return (resources / GUID_FILE).read_text(encoding="utf-8").strip()


def instantiate(resources: str, instance_name: str, visible: int, logging_on: int,
                guid: str = "") -> TapmpSlave:
    """Create the FMU's slave object for one fmi2Instantiate; the host's ``guid`` must be
    the one of this FMU's modelDescription.xml (else GuidMismatch, logged by the binary)."""
    own = _own_guid(Path(resources))
    if guid != own:
        module = (Path(resources) / "slavemodule.txt").read_text().strip()
        raise GuidMismatch(f"fmi2Instantiate: fmuGUID = {guid!r} is not this FMU's: allowed is {own!r} "
                           f"(the modelDescription.xml does not belong to this binary of {module})")
    module_name = (Path(resources) / "slavemodule.txt").read_text().strip()
    cls = getattr(_load_adapter(Path(resources), module_name), module_name)
    if not (isinstance(cls, type) and issubclass(cls, TapmpSlave)):
        raise TypeError(f"{module_name}.{module_name} is not a TapmpSlave subclass")
    slave = cls(instance_name=instance_name, resources=resources, visible=bool(visible))
    slave.logging_on = bool(logging_on)
    return slave
