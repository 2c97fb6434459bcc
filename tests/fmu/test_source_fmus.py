"""The native FMUs as source FMUs, by the book (FMI 2.0.5 section 2.3, FMI 3.0 section 2.4):

* sources/ holds the FMU's own C files and headers, not the standard's FMI headers (the
  importer compiles with its own); one file to compile, all.c, listed in FMI 2.0's
  <SourceFiles> and in sources/buildDescription.xml (both versions), which links libm from
  the system (external="true") except on Windows;
* all.c compiles without a single warning under -std=c99 -Wall -Wextra -pedantic with gcc
  and with clang, and exports nothing but the fmi2* / fmi3* functions;
* `fmpy compile --all-warnings --warning-as-error` builds every native FMU, and the binary
  it builds steps bit for bit like the shipped one (FMPy ignores <Library>: its binary does
  not link libm and loads only where the host has libm loaded, as Python has);
* a binary built as the build description says (with the external libm) loads in FMI
  Library, which resolves every symbol at load time, and runs like the shipped binary;
* with FMI2_FUNCTION_PREFIX / FMI3_FUNCTION_PREFIX the three FMUs link statically into one
  C program (tests/fmu/c_host/static_loop.c) that runs the closed loop bit for bit like the
  shipped binaries run by FMPy.
"""

import subprocess
import sys
import zipfile
from collections import Counter
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave
from fmpy.model_description import read_build_description

from tests.support.ctools import compile_c, extract_sources
from tests.support.fmil_gaps import fmil_messages, terminal_messages, warnings_and_errors
from tapmp.interface import CONNECTIONS, CONTROLLER, FMU_NAMES, PLANT, TRAJECTORY, VARIABLES

ROOT = Path(__file__).resolve().parents[2]
FAMILIES = ("fmi2", "fmi3")
STANDARD_HEADERS = {"fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h", "fmi3Functions.h",
                    "fmi3FunctionTypes.h", "fmi3PlatformTypes.h"}
LOOP_ORDER = (TRAJECTORY, CONTROLLER, PLANT)
# FMPy's fmi2Functions.h ignores FMI2_FUNCTION_PREFIX; the standard's own header, as FMI
# Library (../shared/tools/fmil) ships it, honours it. FMPy's fmi3Functions.h honours it.
STANDARD_FMI2_HEADERS = ROOT.parent / "shared" / "tools" / "fmil" / "include" / "FMI2"
STEP = 1e-4


def outputs(model: str) -> list[str]:
    return [v.name for v in VARIABLES[model] if v.causality == "output"]


def vr(model: str, name: str) -> int:
    return [v.name for v in VARIABLES[model]].index(name)


@pytest.mark.parametrize("model", FMU_NAMES)
@pytest.mark.parametrize("family", FAMILIES)
def test_sources_hold_no_standard_header_and_one_file_to_compile_with_libm_declared(native_built, family, model):
    fmu = native_built[family][model]
    with zipfile.ZipFile(fmu) as z:
        names = {n[len("sources/"):] for n in z.namelist() if n.startswith("sources/")}
        md = ET.fromstring(z.read("modelDescription.xml"))
        bd = ET.fromstring(z.read("sources/buildDescription.xml"))
    assert not names & STANDARD_HEADERS, names
    assert {"all.c", "buildDescription.xml", "instance.c", "instance.h", "tapmp_model.c", "model_vars.h"} <= names
    if family == "fmi2":
        assert [f.get("name") for f in md.findall("CoSimulation/SourceFiles/File")] == ["all.c"]
    assert bd.get("fmiVersion") == "3.0"
    configs = bd.findall("BuildConfiguration")
    assert [c.get("platform") for c in configs] == [None, "x86_64-windows"]
    assert all(c.get("modelIdentifier") == model for c in configs)
    for config in configs:
        assert [(s.get("language"), [f.get("name") for f in s.findall("SourceFile")])
                for s in config.findall("SourceFileSet")] == [("C99", ["all.c"])]
    fallback, windows = configs
    assert [(lib.get("name"), lib.get("external")) for lib in fallback.findall("Library")] == [("m", "true")]
    assert windows.findall("Library") == []  # MSVC has no libm: the math functions are in its C runtime
    assert fallback.find("SourceFileSet").get("compilerOptions") == "-ffp-contract=off"
    # valid against the FMI 3.0 schema (fmpy validates it on reading)
    configurations = read_build_description(str(fmu), validate=True)
    assert [c.sourceFileSets[0].sourceFiles for c in configurations] == [["all.c"]] * 2


@pytest.mark.parametrize("compiler", ["cc", "clang"])
@pytest.mark.parametrize("family", FAMILIES)
def test_all_c_compiles_without_a_warning_and_exports_only_the_fmi_functions(native_built, family, compiler,
                                                                                  tmp_path):
    prefix = "fmi2" if family == "fmi2" else "fmi3"
    for model in FMU_NAMES:
        src = extract_sources(native_built[family][model], tmp_path / model)
        obj = tmp_path / f"{model}.o"
        proc = compile_c(["-std=c99", "-Wall", "-Wextra", "-pedantic", "-O3", "-c", f"-I{src}", "-o", obj,
                          src / "all.c"], kind=compiler)
        assert proc.returncode == 0 and proc.stderr == "", (model, proc.stderr)
        nm = subprocess.run(["nm", "-g", "--defined-only", str(obj)], capture_output=True, text=True, check=True)
        exported = [line.split()[-1] for line in nm.stdout.splitlines()]
        assert exported and all(name.startswith(prefix) for name in exported), (model, exported)
        # every function of the standard's header for the interfaces offered (FMI 2.0: 34 common and
        # Co-Simulation ones, 10 more for the plant's Model Exchange)
        assert len(exported) == (75 if family == "fmi3" else 44 if model == PLANT else 34)


@pytest.mark.parametrize("family", FAMILIES)
def test_the_shipped_linux_binaries_export_only_the_fmi_functions(native_built, family, tmp_path):
    platform = "linux64" if family == "fmi2" else "x86_64-linux"
    for model in FMU_NAMES:
        with zipfile.ZipFile(native_built[family][model]) as z:
            lib = tmp_path / f"{model}.so"
            lib.write_bytes(z.read(f"binaries/{platform}/{model}.so"))
        nm = subprocess.run(["nm", "-D", "--defined-only", str(lib)], capture_output=True, text=True, check=True)
        exported = [line.split()[-1] for line in nm.stdout.splitlines()]
        assert exported and all(name.startswith(family) for name in exported), (model, exported)


def fmpy_steps(fmu: Path, unzip_dir: Path, model: str, steps: int, inputs: dict) -> np.ndarray:
    """FMPy on an unpacked FMU: the outputs after each of ``steps`` steps with ``inputs`` set."""
    md = read_model_description(str(unzip_dir))
    fmi3 = md.fmiVersion.startswith("3")
    slave = (FMU3Slave if fmi3 else FMU2Slave)(guid=md.guid, unzipDirectory=str(unzip_dir), modelIdentifier=model,
                                               instanceName="src")
    slave.instantiate()
    set_real, get_real = (slave.setFloat64, slave.getFloat64) if fmi3 else (slave.setReal, slave.getReal)
    if inputs:
        set_real([vr(model, n) for n in inputs], list(inputs.values()))
    if fmi3:
        slave.enterInitializationMode(startTime=0.0)
    else:
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
    slave.exitInitializationMode()
    out_vrs = [vr(model, n) for n in outputs(model)]
    rows = []
    for n in range(steps):
        slave.doStep(n * STEP, STEP)
        rows.append(get_real(out_vrs))
    slave.terminate()
    slave.freeInstance()
    return np.array(rows)


INPUTS = {PLANT: {"F1": 20.0, "F2": 10.0, "F3": 60.0}, TRAJECTORY: {},
          CONTROLLER: {"X_d": 1e-4, "Z_d": -2e-4, "B_d": 0.001, "dX_d": 0.02, "q1": 1e-5, "q2": 2e-5, "q3": -1e-5}}


@pytest.mark.parametrize("family", FAMILIES)
def test_fmpy_compile_with_all_warnings_as_errors_builds_every_native_fmu_and_it_steps_like_the_shipped(
        native_built, family, tmp_path):
    for model in FMU_NAMES:
        fmu = tmp_path / f"{model}.fmu"
        with zipfile.ZipFile(native_built[family][model]) as z:
            shipped_lib = {n: z.read(n) for n in z.namelist() if n.endswith(".so")}
            members = {i.filename: z.read(i) for i in z.infolist()}
        # without the shipped host binary: cmake's install would keep it as "Up-to-date" when the
        # build finishes within the second it was extracted in
        host = "binaries/linux64/" if family == "fmi2" else "binaries/x86_64-linux/"
        with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as z:
            for name, data in members.items():
                if not name.startswith(host):
                    z.writestr(name, data)
        proc = subprocess.run([sys.executable, "-m", "fmpy.cli", "compile", "--all-warnings", "--warning-as-error",
                               str(fmu)], capture_output=True, text=True, cwd=tmp_path, timeout=600)
        assert proc.returncode == 0, (model, proc.stdout[-3000:], proc.stderr[-3000:])
        assert "warning" not in proc.stdout.lower(), proc.stdout
        with zipfile.ZipFile(fmu) as z:
            rebuilt_lib = {n: z.read(n) for n in z.namelist() if n.endswith(".so")}
        assert rebuilt_lib.keys() == shipped_lib.keys() and rebuilt_lib != shipped_lib  # really rebuilt
        shipped = fmpy_steps(fmu, Path(extract(str(native_built[family][model]), str(tmp_path / f"s_{model}"))),
                             model, 200, INPUTS[model])
        rebuilt = fmpy_steps(fmu, Path(extract(str(fmu), str(tmp_path / f"r_{model}"))), model, 200, INPUTS[model])
        assert np.all(np.isfinite(shipped)) and np.abs(shipped).max() > 0.0
        assert np.array_equal(rebuilt.view(np.uint64), shipped.view(np.uint64)), model


# -- three source FMUs in one program --------------------------------------------------------

def loop_config(native: dict, family: str) -> str:
    """loop_config.h of tests/fmu/c_host/static_loop.c for ``family``, from tapmp/interface.py."""
    lines = [f"#define FMI_VERSION {family[-1]}"]
    for k, model in enumerate(LOOP_ORDER):
        md = read_model_description(str(native[model]))
        lines.append(f'#define TOKEN_{k} "{md.guid}"')
        lines.append(f"#define OUT_VRS_{k} {{{', '.join(str(vr(model, n)) for n in outputs(model))}}}")
    conns = [f"{{{LOOP_ORDER.index(s)}, {outputs(s).index(sv)}, {LOOP_ORDER.index(d)}, {vr(d, dv)}}}"
             for s, sv, d, dv in CONNECTIONS]
    lines.append(f"#define CONNECTIONS {{{', '.join(conns)}}}")
    return "\n".join(lines) + "\n"


def build_static_loop(native: dict, family: str, folder: Path, flags=()) -> Path:
    """static_loop linked with the three FMUs' all.c, each compiled with its function prefix."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "loop_config.h").write_text(loop_config(native, family))
    macro = "FMI2_FUNCTION_PREFIX" if family == "fmi2" else "FMI3_FUNCTION_PREFIX"
    headers = STANDARD_FMI2_HEADERS if family == "fmi2" else None
    if headers is not None and not headers.is_dir():
        pytest.skip(f"needs the FMI 2.0 standard headers of FMI Library in {headers} (../shared/tools/fmil)")
    objects = []
    for model in LOOP_ORDER:
        src = extract_sources(native[model], folder / model)
        obj = folder / f"{model}.o"
        proc = compile_c(["-std=c99", "-O2", "-ffp-contract=off", *flags, f"-D{macro}={model}_", f"-I{src}", "-c",
                          "-o", obj, src / "all.c"], headers=headers)
        assert proc.returncode == 0, proc.stderr
        objects.append(obj)
    exe = folder / "static_loop"
    proc = compile_c(["-std=c99", "-O2", "-Wall", "-Wextra", *flags, f"-I{folder}", "-o", exe,
                      ROOT / "tests" / "fmu" / "c_host" / "static_loop.c", *objects, "-lm"], headers=headers)
    assert proc.returncode == 0, proc.stderr
    return exe


def fmpy_loop(native: dict, folder: Path, steps: int) -> np.ndarray:
    """The loop of static_loop.c with FMPy on the shipped binaries: per step every connected
    input from the last outputs, doStep trajectory, controller, plant, read the outputs."""
    slaves, getters, setters = [], [], []
    for model in LOOP_ORDER:
        md = read_model_description(str(native[model]))
        fmi3 = md.fmiVersion.startswith("3")
        unzip = extract(str(native[model]), str(folder / f"fmpy_{model}"))
        slave = (FMU3Slave if fmi3 else FMU2Slave)(guid=md.guid, unzipDirectory=unzip, modelIdentifier=model,
                                                   instanceName="loop")
        slave.instantiate()
        if fmi3:
            slave.enterInitializationMode(startTime=0.0)
        else:
            slave.setupExperiment(startTime=0.0)
            slave.enterInitializationMode()
        slave.exitInitializationMode()
        slaves.append(slave)
        getters.append(slave.getFloat64 if fmi3 else slave.getReal)
        setters.append(slave.setFloat64 if fmi3 else slave.setReal)
    out_vrs = [[vr(m, n) for n in outputs(m)] for m in LOOP_ORDER]
    out = [get(vrs) for get, vrs in zip(getters, out_vrs)]
    conns = [(LOOP_ORDER.index(s), outputs(s).index(sv), LOOP_ORDER.index(d), vr(d, dv)) for s, sv, d, dv in CONNECTIONS]
    rows = []
    for n in range(steps):
        for src, index, dst, dst_vr in conns:
            setters[dst]([dst_vr], [out[src][index]])
        for slave in slaves:
            slave.doStep(n * STEP, STEP)
        out = [get(vrs) for get, vrs in zip(getters, out_vrs)]
        rows.append([x for values in out for x in values])
    for slave in slaves:
        slave.terminate()
        slave.freeInstance()
    return np.array(rows)


@pytest.mark.parametrize("family", FAMILIES)
def test_three_source_fmus_link_into_one_program_with_prefixes_and_run_the_loop_bit_for_bit(
        native_built, family, tmp_path):
    steps = 2000  # 0.2 s of the closed loop at the 0.1 ms servo cycle
    exe = build_static_loop(native_built[family], family, tmp_path / "loop")
    proc = subprocess.run([str(exe), str(steps), repr(STEP)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""
    linked = np.array([[float(x) for x in line.split()] for line in proc.stdout.splitlines()])
    shipped = fmpy_loop(native_built[family], tmp_path, steps)
    assert linked.shape == shipped.shape == (steps, sum(len(outputs(m)) for m in LOOP_ORDER))
    plant_q = shipped[:, 24:27]  # the plant's q1..q3 (after 12 trajectory and 12 controller outputs)
    assert np.all(np.isfinite(shipped)) and np.abs(plant_q).max() > 1e-3  # the platform moved (mm)
    assert np.array_equal(linked.view(np.uint64), shipped.view(np.uint64))


FMIL_CHECK = ROOT.parent / "shared" / "tools" / "fmil" / "fmil_check"


@pytest.mark.needs_shared("tools/fmil/fmil_check")
@pytest.mark.parametrize("family", FAMILIES)
def test_a_build_that_follows_the_build_description_loads_in_fmil_and_runs_like_the_shipped_binary(
        native_built, family, tmp_path):
    """FMI Library loads a binary with RTLD_NOW: every symbol must resolve, so the libm the
    build description declares (external) must really be linked."""
    model = PLANT  # the plant calls sin, cos and sincos of libm
    fmu = native_built[family][model]
    configs = ET.fromstring(zipfile.ZipFile(fmu).read("sources/buildDescription.xml")).findall("BuildConfiguration")
    config = next(c for c in configs if c.get("platform") is None)  # Linux: no configuration of its own
    fileset = config.find("SourceFileSet")
    src = extract_sources(fmu, tmp_path / "src")
    lib = tmp_path / f"{model}.so"
    proc = compile_c(["-shared", "-fPIC", "-O2", *(fileset.get("compilerOptions") or "").split(),
                      f"-I{src}", "-o", lib, *(src / f.get("name") for f in fileset.findall("SourceFile")),
                      *(f"-l{x.get('name')}" for x in config.findall("Library") if x.get("external") == "true")])
    assert proc.returncode == 0, proc.stderr
    rebuilt = tmp_path / f"{model}.fmu"
    platform = "linux64" if family == "fmi2" else "x86_64-linux"
    with zipfile.ZipFile(fmu) as z, zipfile.ZipFile(rebuilt, "w") as out:
        for item in z.infolist():
            data = lib.read_bytes() if item.filename == f"binaries/{platform}/{model}.so" else z.read(item)
            out.writestr(item, data)
    runs = {}
    for name, path in (("shipped", fmu), ("rebuilt", rebuilt)):
        csv = tmp_path / f"{name}.csv"
        proc = subprocess.run([str(FMIL_CHECK), "alone", str(path), str(csv), "0.01", "1e-4"], capture_output=True,
                              text=True, timeout=120)
        expected = terminal_messages(path) if family == "fmi3" else Counter()  # FMIL's own gaps (fmil_gaps)
        assert fmil_messages(proc.stderr) == expected, proc.stderr
        assert proc.returncode == (1 if expected else 0), proc.stdout + proc.stderr
        assert "100 steps, {} warnings, {} errors".format(*warnings_and_errors(expected)) in proc.stdout, proc.stdout
        runs[name] = csv.read_text()
    assert runs["rebuilt"] == runs["shipped"] and len(runs["shipped"].splitlines()) == 102
