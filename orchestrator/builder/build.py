"""Build the TAPMP FMUs with pythonfmu, complete their modelDescription.xml, give them
their own binary, and write the SSP system TAPMP.ssp and the closed-loop container FMU
TAPMP_ClosedLoop.fmu (orchestrator/builder/container.py).

pythonfmu 0.7 writes no units and no initial unknowns; :func:`complete_model_description`
adds them from the variable tables in ``tapmp.interface`` (one source of truth).

pythonfmu 0.7's binary cannot return fmi2Error (a Python exception becomes fmi2Fatal and
corrupts the host interpreter), needs libpython already in the host process, and costs
a Python call per getReal/setReal. So the FMUs ship their own binary instead: the native
FMUs' runtime (``fmu_common/c``) with model operations that call Python
(``fmu_common/pyfront``), compiled here by the project's C compiler (zig cc from the ziglang
package, or $CC; ctoolchain/__init__.py): see :func:`compile_binaries`.
"""

import shutil
import site
import sys
import sysconfig
import tempfile
import threading
import time
import zipfile
from contextlib import contextmanager
from pathlib import Path
from xml.etree import ElementTree as ET

from tapmp.interface import VARIABLES, dependencies
from tapmp.models import names, record

import ctoolchain as toolchain
from tapmp import cmodel
from .families import default_build_dir
from ..errors import UserError
from .model_description import fmi2_model_structure, to_bytes, unit_definitions

# The package's root: the repository in a checkout, site-packages in an installed wheel
# (the adapters and the C sources are package data there).
ROOT = Path(__file__).resolve().parents[2]
BUNDLED_PACKAGES = (ROOT / "tapmp", ROOT / "fmu_common")
PYFRONT = ROOT / "fmu_common" / "pyfront"
RUNTIME = ROOT / "fmu_common" / "c"
PLATFORM = "linux64"
BINDING = "tapmp_fmi2_python.so"     # name the front binary loads (fmi2_front.c BACKEND)
PYTHON_ENV = "python-env.txt"        # read by both binaries (python_env.h)
DEFAULT_BUILD_DIR = default_build_dir()
SSP_NAME = "TAPMP.ssp"


def complete_model_description(xml: bytes, model: str) -> bytes:
    """Add unit definitions, units and the model structure to a pythonfmu modelDescription.

    pythonfmu writes every output with no dependency attribute (an importer must then
    assume each depends on every input: an algebraic loop that is not there). The model
    structure is rewritten from ``tapmp.interface.dependencies``: outputs change only in
    doStep (no direct feedthrough), and the initial unknowns list the inputs and
    parameters they are computed from in Initialization Mode.
    """
    root = ET.fromstring(xml)
    table = {v.name: v for v in VARIABLES[model]}
    pos = list(root).index(root.find("CoSimulation")) + 1
    root.insert(pos, unit_definitions(v.unit for v in table.values() if v.unit))
    outputs, index = [], {}
    for i, sv in enumerate(root.find("ModelVariables"), start=1):
        var = table[sv.get("name")]
        index[var.name] = i
        real = sv.find("Real")
        if real is not None and var.unit:
            real.set("unit", var.unit)
        if var.causality == "output":
            outputs.append((i, var.name))
    structure = root.find("ModelStructure")
    for child in list(structure):
        structure.remove(child)
    if outputs:
        fmi2_model_structure(structure, outputs, dependencies(model), index)
    return to_bytes(root)


class BuildError(RuntimeError, UserError):
    """Building an FMU failed; the message says which step and why."""


def python_env() -> str:
    """The python-env.txt text: the Python an FMU starts when its host has none.

    Records this interpreter's shared libpython, its prefix (home) and the
    site-packages that hold numpy, so a C host on this machine needs nothing else.
    """
    lines = ["# Python used by this FMU when the host process has none (written at build time).",
             "# Edit for another machine, or set TAPMP_LIBPYTHON / PYTHONHOME / PYTHONPATH."]
    libdir, soname = sysconfig.get_config_var("LIBDIR"), sysconfig.get_config_var("INSTSONAME")
    candidates = [Path(libdir or "", soname or ""),
                  Path(sysconfig.get_config_var("LIBPL") or "", soname or ""),
                  Path("/usr/lib", sysconfig.get_config_var("MULTIARCH") or "", soname or "")]
    lib = next((p for p in candidates if soname and ".so" in soname and p.is_file()), None)
    lines.append(f"libpython={lib}" if lib else
                 f"# no shared libpython found for {sys.executable}: set TAPMP_LIBPYTHON")
    lines.append(f"home={sys.base_prefix}")
    import numpy
    paths = [*site.getsitepackages(), str(Path(numpy.__file__).resolve().parent.parent)]
    lines += [f"path={p}" for p in dict.fromkeys(paths)]
    return "\n".join(lines) + "\n"


def _compile(sources, output: Path, **kw) -> None:
    try:
        toolchain.compile_c(sources, output, toolchain.HOST, **kw)
    except toolchain.ToolchainError as err:
        raise BuildError(str(err)) from None


def python_headers() -> Path:
    """The folder of this interpreter's Python.h; BuildError names the Debian package if it
    is missing (a Debian Python without python3-dev)."""
    include = Path(sysconfig.get_paths()["include"])
    if not (include / "Python.h").is_file():
        raise BuildError(f"Python's C headers are missing ({include / 'Python.h'} does not exist), needed for "
                         "the pythonfmu FMUs' binary: install Debian's python3-dev (apt-get install python3-dev)")
    return include


def python_model_vars(model: str) -> str:
    """model_vars.h of ``model``'s pythonfmu binary: the native FMUs' table (build_native.py)
    with the Python model's data (python_model.h), its output block, and the fmuGUID read
    from resources/guid.txt at run time (pythonfmu makes a new one per build)."""
    from .build_native import model_files, model_vars_header
    outputs = [vr for vr, v in enumerate(VARIABLES[model]) if v.causality == "output"]
    if outputs != list(range(outputs[0], outputs[0] + len(outputs))):
        raise BuildError(f"the outputs of {model} are not contiguous: the runtime publishes them as one block")
    text = model_vars_header(model).replace(f'#include "{model_files(model)[1].name}"', '#include "python_model.h"')
    lines = [("#define INSTANTIATION_TOKEN tapmp_python_token" if line.startswith("#define INSTANTIATION_TOKEN ")
              else line) for line in text.splitlines()]
    at = lines.index("#endif")
    lines[at:at] = [f"#define MODEL_N_OUT {len(outputs)}", f"#define MODEL_OUT_FIRST {outputs[0]}"]
    return "\n".join(lines) + "\n"


def python_unity() -> str:
    """The pythonfmu binding as one translation unit: the native runtime's FMI 2.0 files
    (build_native.RUNTIME_SOURCES, API) with the Python model operations."""
    from .build_native import API, RUNTIME_SOURCES
    parts = [p.name for p in (*RUNTIME_SOURCES, PYFRONT / "python_model.c", *API["fmi2"])]
    return "\n".join(["#define _GNU_SOURCE /* dladdr */", "#define PY_SSIZE_T_CLEAN", "#include <Python.h>",
                      "#define TAPMP_LINKAGE static __attribute__((unused))", "#define TAPMP_DEFINITION static",
                      *(f'#include "{name}"' for name in parts), ""])


def python_models() -> tuple[str, ...]:
    """The models with a pythonfmu twin (ModelRecord.adapter), in registry order."""
    return tuple(m for m in names() if record(m).adapter)


def adapter_script(model: str) -> Path:
    """The pythonfmu adapter script of ``model`` (its record's adapter)."""
    return ROOT / record(model).adapter


def compile_binaries(dest: Path, models=None) -> tuple[Path, dict[str, Path]]:
    """Compile the FMI front (no Python dependency) and, per model, the Python binding into dest.

    ``models``: the models to bind (default: every model with a pythonfmu twin, :func:`python_models`).
    Returns (front, {model: binding}). A binding is the native FMUs' runtime
    (fmu_common/c: the version-neutral files and fmi2_api.c) with model operations that call Python
    (fmu_common/pyfront/python_model.c), built against this interpreter's headers and
    deliberately not linked to libpython: in a Python host it uses the host's, in a C host
    the front loads the recorded one first (RTLD_GLOBAL).
    """
    import fmpy

    include = python_headers()
    fmi_headers = Path(fmpy.__file__).parent / "c-code"
    flags = ["-O2", "-Wall", "-fvisibility=hidden", "-g0"]
    front = dest / "front.so"
    # The front's fmi2 functions are its only exports (default visibility in fmi2Functions.h).
    _compile([PYFRONT / "fmi2_front.c"], front, flags=flags, includes=[fmi_headers, PYFRONT],
             libs=["dl", "pthread"], what="the pythonfmu FMUs' front binary")
    bindings = {}
    for model in python_models() if models is None else models:
        src = dest / f"{model}_src"
        src.mkdir(exist_ok=True)
        (src / "model_vars.h").write_text(python_model_vars(model))
        (src / "python_unity.c").write_text(python_unity())
        bindings[model] = dest / f"{model}_{BINDING}"
        _compile([src / "python_unity.c"], bindings[model], flags=flags, extra=["-Wl,-z,nodelete", "-Wl,-z,lazy"],
                 includes=[src, RUNTIME, PYFRONT, fmi_headers, include], libs=["pthread"],
                 what=f"the pythonfmu {model}'s Python binding")
    return front, bindings


def _rewrite_fmu(fmu: Path, transform: dict, add: dict) -> None:
    """Rewrite a zip archive atomically: members in ``transform`` map old bytes to new,
    pythonfmu's binaries are dropped, and ``add`` (name -> bytes) is appended."""
    tmp = fmu.with_suffix(".tmp")
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as dst:
        for item in src.infolist():
            if item.filename.startswith("binaries/") or item.filename in add:
                continue
            data = src.read(item)
            dst.writestr(item, transform[item.filename](data) if item.filename in transform else data)
        for name, data in add.items():
            info = zipfile.ZipInfo(name, date_time=(2024, 1, 1, 0, 0, 0))
            info.external_attr = 0o755 << 16
            info.compress_type = zipfile.ZIP_DEFLATED
            dst.writestr(info, data)
    tmp.replace(fmu)


def build_fmu(model: str, out_dir: Path, binaries: tuple[Path, Path] | None = None,
              script: Path | None = None) -> Path:
    """Build one FMU into out_dir with pythonfmu, complete its modelDescription and
    install the binaries from :func:`compile_binaries` (compiled here if not given).

    ``script`` replaces the model's adapter (the benchmark's pass-through FMUs)."""
    from pythonfmu import FmuBuilder

    script = Path(script) if script else adapter_script(model)
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    with tempfile.TemporaryDirectory(prefix="tapmp_build_") as tmp:
        # Copy the bundled packages without bytecode caches.
        staged = []
        for pkg in BUNDLED_PACKAGES:
            dest = Path(tmp) / pkg.name
            shutil.copytree(pkg, dest, ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "pyfront"))
            staged.append(dest)
        # the compiled C model goes with its sources: the FMU loads it, never compiles it
        shutil.copyfile(cmodel.library_path(), Path(tmp) / "tapmp" / "c" / cmodel.bundled_name())
        fmu = FmuBuilder.build_FMU(script, dest=out_dir, project_files=staged,
                                   canGetAndSetFMUstate=True, canSerializeFMUstate=True)
        if binaries is None:
            binaries = compile_binaries(Path(tmp), (model,))
        fmu = Path(fmu)
        front, binding = binaries[0], binaries[1][model]
        where = f"binaries/{PLATFORM}/"
        with zipfile.ZipFile(fmu) as z:  # the binding checks the host's fmuGUID against resources/guid.txt
            guid = ET.fromstring(z.read("modelDescription.xml")).get("guid", "")
        _rewrite_fmu(fmu, {"modelDescription.xml": lambda b: complete_model_description(b, model)},
                     {f"{where}{script.stem}.so": front.read_bytes(), f"{where}{BINDING}": binding.read_bytes(),
                      f"{where}{PYTHON_ENV}": python_env().encode(), "resources/guid.txt": guid.encode()})
    return fmu


@contextmanager
def still_running(log, what: str, every: float = 10.0):
    """While the block runs, ``log`` a line saying ``what`` is still running (with the seconds
    since it started) every ``every`` seconds, so a long compile is never silent."""
    start, done = time.monotonic(), threading.Event()

    def beat():
        while not done.wait(every):
            log(f"{what}: still compiling ({time.monotonic() - start:.0f} s)")
    watcher = threading.Thread(target=beat, daemon=True)
    watcher.start()
    try:
        yield
    finally:
        done.set()
        watcher.join()


def build_all(out_dir: Path = DEFAULT_BUILD_DIR, log=print, every: float = 10.0) -> dict[str, Path]:
    """Build the three FMUs, TAPMP.ssp and the closed-loop container FMU into out_dir;
    return their paths by model name (``"ssp"`` for TAPMP.ssp, ``TAPMP_ClosedLoop`` for
    the container). While the compiler runs, a line every ``every`` seconds [s]."""
    from .container import CONTAINER, build_container
    from .ssp import write_ssp

    out_dir = Path(out_dir).resolve()
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = {}
    with tempfile.TemporaryDirectory(prefix="tapmp_cc_") as tmp:
        log(f"pythonfmu: compiling the FMI front and the three Python bindings ({toolchain.HOST})")
        with still_running(log, "pythonfmu", every):
            binaries = compile_binaries(Path(tmp))
        for model in python_models():
            paths[model] = build_fmu(model, out_dir, binaries)
            log(f"built {paths[model]}")
    paths["ssp"] = write_ssp(out_dir / SSP_NAME, paths)
    log(f"wrote {paths['ssp']}")
    paths[CONTAINER] = build_container(paths, out_dir)
    log(f"built {paths[CONTAINER]}")
    return paths


# The head of a pythonfmu script on pythonfmu 0.7's own binary: pythonfmu's names and
# ``register_interface(slave, model)``, which registers the variables of the TAPMP model ``model``
# on ``slave`` at their start values. A script adds one class derived from Fmi2Slave itself, named
# after its file (pythonfmu wants one such class a script; that binary's fmi2Reset crashed with a
# base class in between): the benchmark's floor, the tests' FMUs that fail on purpose.
INTERFACE_SCRIPT = '''
from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real
from tapmp.interface import VARIABLES


def register_interface(slave, model):
    """The variables of the TAPMP model ``model`` registered on ``slave``, at their start values."""
    for v in VARIABLES[model]:
        setattr(slave, v.name, v.start)
        kw = dict(causality=Fmi2Causality[v.causality])
        if v.causality == "parameter":
            kw["variability"] = Fmi2Variability[v.variability]
        elif v.type == "Real":
            kw["variability"] = Fmi2Variability.continuous
        slave.register_variable((Real if v.type == "Real" else Integer)(v.name, **kw))
'''


def declare_no_feedthrough(fmu: Path) -> Path:
    """Declare in ``fmu``'s modelDescription that its outputs depend on no input
    (ModelStructure/Outputs dependencies=""), as the TAPMP FMUs do: pythonfmu writes no
    dependencies, which means every input, and the master refuses the loop as algebraic."""
    with zipfile.ZipFile(fmu) as z:
        members = {i: z.read(i) for i in z.infolist()}
    for info in members:
        if info.filename == "modelDescription.xml":
            root = ET.fromstring(members[info])
            outputs = [i for i, v in enumerate(root.find("ModelVariables"), start=1)
                       if v.get("causality") == "output"]
            structure = root.find("ModelStructure")
            for child in list(structure):
                structure.remove(child)
            out, init = ET.SubElement(structure, "Outputs"), ET.SubElement(structure, "InitialUnknowns")
            for index in outputs:
                ET.SubElement(out, "Unknown", index=str(index), dependencies="")
                ET.SubElement(init, "Unknown", index=str(index))
            members[info] = ET.tostring(root, encoding="UTF-8", xml_declaration=True)
    tmp = fmu.with_suffix(".tmp")
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
        for info, data in members.items():
            z.writestr(info, data)
    tmp.replace(fmu)
    return fmu


def build_interface_fmu(script: Path, code: str, out_dir: Path) -> Path:
    """Write ``script`` (:data:`INTERFACE_SCRIPT` followed by ``code``: a subclass of Fmi2Slave
    named after the script's file that calls ``register_interface``) and build it into ``out_dir``
    on pythonfmu 0.7's own binary, ``tapmp`` bundled, its outputs declared without direct
    feedthrough; returns the FMU's path. Such an FMU runs only in a process whose Python can
    import pythonfmu (the binary uses the host's libpython)."""
    from pythonfmu import FmuBuilder

    script.parent.mkdir(parents=True, exist_ok=True)
    script.write_text(INTERFACE_SCRIPT + code)
    fmu = FmuBuilder.build_FMU(script, dest=out_dir, project_files=[ROOT / "tapmp"])
    return declare_no_feedthrough(Path(fmu))
