"""Build the TAPMP FMUs with pythonfmu, complete their modelDescription.xml, and
write the SSP system TAPMP.ssp.

pythonfmu 0.7 writes no units and no initial unknowns; :func:`complete_model_description`
adds them from the variable tables in ``tapmp.interface`` (one source of truth).
On Linux the FMU's binary is our status shim (fmu_common/fmi2_status_shim.c, compiled
with the system C compiler) in front of pythonfmu's, which then ships as
``<model>_pythonfmu.so``: pythonfmu alone cannot return fmi2Error.
"""

import os
import platform
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

from tapmp.interface import CONTROLLER, PLANT, TRAJECTORY, UNITS, VARIABLES

ROOT = Path(__file__).resolve().parent.parent
SCRIPTS = {
    PLANT: ROOT / "fmu_plant" / "TAPMP_Plant.py",
    CONTROLLER: ROOT / "fmu_controller" / "TAPMP_Controller.py",
    TRAJECTORY: ROOT / "fmu_controller" / "TAPMP_Trajectory.py",
}
BUNDLED_PACKAGES = (ROOT / "tapmp", ROOT / "fmu_common")
DEFAULT_BUILD_DIR = ROOT / "build"
SSP_NAME = "TAPMP.ssp"


def complete_model_description(xml: bytes, model: str) -> bytes:
    """Add unit definitions, units and the model structure to a pythonfmu modelDescription.

    Outputs change only in doStep (no direct feedthrough), so ModelStructure/Outputs
    lists them with no dependencies; all outputs are initial unknowns computed from
    the parameters (and, for the controller, the inputs) during initialization.
    """
    root = ET.fromstring(xml)
    table = {v.name: v for v in VARIABLES[model]}
    used = sorted({v.unit for v in table.values() if v.unit})
    units = ET.Element("UnitDefinitions")
    for name in used:
        unit = ET.SubElement(units, "Unit", name=name)
        ET.SubElement(unit, "BaseUnit", {k: str(e) for k, e in UNITS[name].items()})
    pos = list(root).index(root.find("CoSimulation")) + 1
    root.insert(pos, units)
    outputs = []
    for index, sv in enumerate(root.find("ModelVariables"), start=1):
        var = table[sv.get("name")]
        real = sv.find("Real")
        if real is not None and var.unit:
            real.set("unit", var.unit)
        if var.causality == "output":
            outputs.append(index)
    structure = root.find("ModelStructure")
    for child in list(structure):
        structure.remove(child)
    if outputs:
        out = ET.SubElement(structure, "Outputs")
        init = ET.SubElement(structure, "InitialUnknowns")
        for index in outputs:
            ET.SubElement(out, "Unknown", index=str(index), dependencies="")
            ET.SubElement(init, "Unknown", index=str(index))
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


SHIM_SOURCE = ROOT / "fmu_common" / "fmi2_status_shim.c"


def compile_shim(out: Path) -> Path:
    """Compile the fmi2 status shim into ``out`` (a .so) with the system C compiler."""
    import fmpy

    headers = Path(fmpy.__file__).parent / "c-code"
    cc = os.environ.get("CC", "cc")
    cmd = [cc, "-shared", "-fPIC", "-O2", f"-I{headers}", str(SHIM_SOURCE), "-o", str(out), "-ldl"]
    try:
        subprocess.run(cmd, check=True, capture_output=True, text=True)
    except FileNotFoundError:
        raise RuntimeError(f"no C compiler '{cc}' found: the FMU build needs one (set CC)") from None
    except subprocess.CalledProcessError as err:
        raise RuntimeError(f"compiling {SHIM_SOURCE} failed:\n{err.stderr}") from None
    return out


def _rewrite(fmu: Path, model: str, shim: Path | None) -> None:
    """Complete modelDescription.xml and put the shim in front of pythonfmu's Linux binary."""
    tmp = fmu.with_suffix(".tmp")
    linux_bin = f"binaries/linux64/{model}.so"
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as dst:
        for item in src.infolist():
            data = src.read(item)
            if item.filename == "modelDescription.xml":
                data = complete_model_description(data, model)
            elif item.filename == linux_bin and shim is not None:
                dst.writestr(f"binaries/linux64/{model}_pythonfmu.so", data)
                data = shim.read_bytes()
            dst.writestr(item, data)
    tmp.replace(fmu)


def build_fmu(model: str, out_dir: Path) -> Path:
    """Build one FMU into out_dir with pythonfmu and complete its modelDescription."""
    from pythonfmu import FmuBuilder

    script = SCRIPTS[model]
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    with tempfile.TemporaryDirectory(prefix="tapmp_build_") as tmp:
        # Copy the bundled packages without bytecode caches.
        staged = []
        for pkg in BUNDLED_PACKAGES:
            dest = Path(tmp) / pkg.name
            shutil.copytree(pkg, dest, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
            staged.append(dest)
        fmu = Path(FmuBuilder.build_FMU(script, dest=out_dir, project_files=staged,
                                        canGetAndSetFMUstate=True, canSerializeFMUstate=True))
        shim = compile_shim(Path(tmp) / "shim.so") if platform.system() == "Linux" else None
        _rewrite(fmu, model, shim)
    return fmu


def build_all(out_dir: Path = DEFAULT_BUILD_DIR, log=print) -> dict[str, Path]:
    """Build the three FMUs and TAPMP.ssp into out_dir; return their paths by model name."""
    from .ssp import write_ssp

    out_dir = Path(out_dir).resolve()
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = {}
    for model in (PLANT, CONTROLLER, TRAJECTORY):
        paths[model] = build_fmu(model, out_dir)
        log(f"built {paths[model]}")
    paths["ssp"] = write_ssp(out_dir / SSP_NAME, paths)
    log(f"wrote {paths['ssp']}")
    return paths
