"""Python side of the FMU binary's fmi2Instantiate (see fmu_common/pyfront/python_model.c).

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


def instantiate(resources: str, instance_name: str, visible: int) -> TapmpSlave:
    """Create the FMU's model object for one fmi2Instantiate (the runtime has checked the
    host's fmuGUID against resources/guid.txt and put ``resources`` on sys.path)."""
    module_name = (Path(resources) / "slavemodule.txt").read_text().strip()
    cls = getattr(_load_adapter(Path(resources), module_name), module_name)
    if not (isinstance(cls, type) and issubclass(cls, TapmpSlave)):
        raise TypeError(f"{module_name}.{module_name} is not a TapmpSlave subclass")
    return cls(instance_name=instance_name, resources=resources, visible=bool(visible))
