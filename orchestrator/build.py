"""Build the TAPMP FMUs with pythonfmu, complete their modelDescription.xml, and
write the SSP system TAPMP.ssp.

pythonfmu 0.7 writes no units and no initial unknowns; :func:`complete_model_description`
adds them from the variable tables in ``tapmp.interface`` (one source of truth).
"""

import shutil
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


def _rewrite_member(fmu: Path, member: str, transform) -> None:
    """Replace one member of a zip archive by ``transform(old_bytes)``, atomically."""
    tmp = fmu.with_suffix(".tmp")
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as dst:
        for item in src.infolist():
            data = src.read(item)
            dst.writestr(item, transform(data) if item.filename == member else data)
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
        fmu = FmuBuilder.build_FMU(script, dest=out_dir, project_files=staged,
                                   canGetAndSetFMUstate=True, canSerializeFMUstate=True)
    fmu = Path(fmu)
    _rewrite_member(fmu, "modelDescription.xml", lambda b: complete_model_description(b, model))
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
