"""The native FMUs (C, no Python at run time) in real hosts other than the orchestrator.

* Linux: small C hosts (tests/fmu/c_host/fmi2_host.c, fmi3_host.c), compiled here by the
  project's toolchain (zig cc, ctoolchain/__init__.py) and
  started with an empty environment (`env -i`), load the shipped .so files and must give
  FMPy's results exactly; the .so files need nothing but the C runtime.
* Windows: the same hosts, cross-compiled by the same toolchain (-static), run the shipped DLLs
  under wine and must give the Linux binaries' results; the DLLs import only Windows' own
  DLLs.
* Source FMU: sources/ alone, compiled from the file list the FMU declares, steps bit for
  bit like the shipped binary.
* Compliance: FMPy's validation and the FMI Compliance Checker (fmuCheck, FMI 2.0).
"""

import math
import os
import re
import shutil
import subprocess
import time
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

from tests.interop import compatibility
import fmpy
import lief
import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave
from fmpy.validation import validate_fmu

from ctoolchain import compile_c
from tapmp.interface import CONTROLLER, FMU_NAMES, PLANT, TRAJECTORY, VARIABLES

C_HOST = Path(__file__).parent / "c_host"
ROOT = Path(__file__).resolve().parents[2]
FMU_CHECK = ROOT.parent / "shared" / "tools" / "fmuCheck" / "fmuCheck.linux64"
HEADERS = Path(fmpy.__file__).parent / "c-code"
FAMILIES = ("fmi2", "fmi3")
BINARIES = {"fmi2": {"linux": "linux64", "windows": "win64"},
            "fmi3": {"linux": "x86_64-linux", "windows": "x86_64-windows"}}
RUNS = 20
STEP = 1e-4
# Fixed, non-trivial inputs: constant motor forces that move the platform (about 6 ... 20 cm
# and 0.9 rad in 0.2 s), and a fixed reference and measurement for the controller.
INPUTS = {PLANT: {"F1": 20.0, "F2": 10.0, "F3": 60.0},
          CONTROLLER: {"X_d": 1e-4, "Z_d": -2e-4, "B_d": 0.001, "dX_d": 0.02, "dZ_d": -0.01, "ddX_d": 0.5,
                       "q1": 1e-5, "q2": 2e-5, "q3": -1e-5},
          TRAJECTORY: {}}


def vr(model: str, name: str) -> int:
    """Value reference of ``name``: its index in the interface table."""
    return [v.name for v in VARIABLES[model]].index(name)


def outputs(model: str) -> list[str]:
    return [v.name for v in VARIABLES[model] if v.causality == "output"]


def unzip(fmu: Path, dest: Path) -> Path:
    with zipfile.ZipFile(fmu) as z:
        z.extractall(dest)
    for lib in (dest / "binaries").glob("*/*"):
        lib.chmod(0o755)
    return dest


def compile_host(family: str, out_dir: Path, windows: bool = False, platform: str | None = None) -> Path:
    """tests/fmu/c_host/<family>_host.c compiled by the project's toolchain for ``platform``
    (default x86_64-linux, or x86_64-windows if ``windows``; Windows executables static)."""
    platform = platform or ("x86_64-windows" if windows else "x86_64-linux")
    source = C_HOST / f"{family}_host.c"
    exe = out_dir / f"{family}_host_{platform}{'.exe' if 'windows' in platform else ''}"
    extra = ["-D__USE_MINGW_ANSI_STDIO=1"] if "windows" in platform else []
    return compile_c([source], exe, platform, shared=False, flags=["-O1", "-Wall", "-Wextra", "-Werror"],
                     extra=extra, includes=[HEADERS], libs=["dl"])


def host_args(model: str, steps: int) -> list[str]:
    """Command-line arguments of a C host after its FMU folder: inputs, "--", outputs."""
    return [model, str(steps), repr(STEP), *(f"{vr(model, n)}={x!r}" for n, x in INPUTS[model].items()), "--",
            *(str(vr(model, n)) for n in outputs(model))]


def run_linux_host(exe: Path, fmu_dir: Path, model: str, steps: int) -> subprocess.CompletedProcess:
    """The host in a process started with an empty environment (env -i)."""
    return subprocess.run(["env", "-i", str(exe), str(fmu_dir), *host_args(model, steps)],
                          capture_output=True, text=True, timeout=60)


def parse(stdout: str) -> list[float]:
    return [float(x) for x in stdout.split()]


def fmpy_run(fmu: Path, unzip_dir: Path, model: str, steps: int) -> np.ndarray:
    """FMPy (FMU2Slave / FMU3Slave) on ``unzip_dir``: the outputs after each of ``steps``
    steps of STEP from t = 0 (rows), with INPUTS set before initialization."""
    md = read_model_description(str(fmu))
    names = outputs(model)
    out_vrs = [vr(model, n) for n in names]
    in_vrs, in_values = [vr(model, n) for n in INPUTS[model]], list(INPUTS[model].values())
    cls = FMU2Slave if md.fmiVersion == "2.0" else FMU3Slave
    slave = cls(guid=md.guid, unzipDirectory=str(unzip_dir), modelIdentifier=model, instanceName="fmpy")
    slave.instantiate()
    rows = []
    try:
        if md.fmiVersion == "2.0":
            if in_vrs:
                slave.setReal(in_vrs, in_values)
            slave.setupExperiment(startTime=0.0)
            get = slave.getReal
        else:
            if in_vrs:
                slave.setFloat64(in_vrs, in_values)
            get = slave.getFloat64
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        for n in range(steps):
            slave.doStep(n * STEP, STEP)
            rows.append(get(out_vrs))
        slave.terminate()
    finally:
        slave.freeInstance()
    return np.array(rows)


# -- 1. Linux, no Python ---------------------------------------------------------------------

@pytest.mark.parametrize("model", FMU_NAMES)
@pytest.mark.parametrize("family", FAMILIES)
def test_native_fmu_in_a_c_host_with_an_empty_environment_gives_fmpys_outputs_every_time(
        native_built, family, model, tmp_path):
    exe = compile_host(family, tmp_path)
    fmu = native_built[family][model]
    fmu_dir = unzip(fmu, tmp_path / "fmu")
    steps = 1000
    expected = fmpy_run(fmu, unzip(fmu, tmp_path / "fmpy"), model, steps)[-1].tolist()
    assert all(math.isfinite(x) for x in expected)
    if model != TRAJECTORY:
        assert np.count_nonzero(expected) >= len(expected) // 2  # the inputs did something
    results = []
    for _ in range(RUNS):
        proc = run_linux_host(exe, fmu_dir, model, steps)
        results.append((proc.returncode, proc.stderr, parse(proc.stdout) if proc.returncode == 0 else None))
    assert [r[0] for r in results] == [0] * RUNS, [r[1] for r in results if r[0]]
    # no libpython in the process, no message from the FMU
    assert {r[1] for r in results} == {"libpython loaded: no\n"}
    assert all(r[2] == expected for r in results), (results[0][2], expected)


@pytest.mark.parametrize("family", FAMILIES)
def test_native_linux_binaries_need_only_the_c_runtime_and_no_libpython(native_built, family, tmp_path):
    needed = {}
    for model in FMU_NAMES:
        lib = unzip(native_built[family][model], tmp_path / model) / "binaries" / BINARIES[family]["linux"] / \
            f"{model}.so"
        dyn = subprocess.run(["readelf", "-d", str(lib)], check=True, capture_output=True, text=True).stdout
        needed[model] = set(re.findall(r"\(NEEDED\)\s+Shared library: \[([^\]]+)\]", dyn))
    assert all(not any("python" in n for n in libs) for libs in needed.values()), needed
    assert all(libs and libs <= {"libc.so.6", "libm.so.6"} for libs in needed.values()), needed  # measured: both


# -- 2. Windows, under wine ------------------------------------------------------------------

def wine_binary() -> str:
    for name in ("wine64", "wine"):
        if shutil.which(name):
            return shutil.which(name)
    return "/usr/lib/wine/wine64"  # Debian's wine64 package installs it here only


def windows_path(path: Path) -> str:
    """``path`` as wine sees it (drive Z: is the Unix root in a new prefix)."""
    return "Z:" + str(path).replace("/", "\\")


@pytest.mark.windows
@pytest.mark.parametrize("family", FAMILIES)
def test_windows_dlls_under_wine_step_2000_times_like_the_linux_binaries(native_built, family, tmp_path, request):
    steps = 2000
    linux_exe = compile_host(family, tmp_path)
    windows_exe = compile_host(family, tmp_path, windows=True)
    (tmp_path / "home").mkdir()
    env = {"PATH": os.environ["PATH"], "HOME": str(tmp_path / "home"), "WINEPREFIX": str(tmp_path / "wineprefix"),
           "WINEDEBUG": "-all", "WINEDLLOVERRIDES": "mscoree,mshtml="}  # no DISPLAY, no Mono / Gecko prompt
    results, seconds = {}, {}
    try:
        for model in (PLANT, CONTROLLER, TRAJECTORY):
            fmu_dir = unzip(native_built[family][model], tmp_path / model)
            linux = run_linux_host(linux_exe, fmu_dir, model, steps)
            assert linux.returncode == 0, linux.stderr
            start = time.perf_counter()
            win = subprocess.run([wine_binary(), str(windows_exe), windows_path(fmu_dir), *host_args(model, steps)],
                                 env=env, cwd=tmp_path, capture_output=True, text=True, timeout=300)
            seconds[model] = time.perf_counter() - start
            assert win.returncode == 0, win.stdout + win.stderr
            results[model] = (np.array(parse(linux.stdout)), np.array(parse(win.stdout)))
    finally:  # the prefix's wineserver, started by these runs
        subprocess.run(["wineserver", "-k"], env=env, capture_output=True, timeout=60)
    for model, (linux, win) in results.items():
        assert linux.shape == win.shape == (len(outputs(model)),)
        assert np.all(np.isfinite(win))
        assert np.all(np.abs(win - linux) <= 1e-12 * np.abs(linux)), (model, win - linux)
    assert np.abs(results[PLANT][0][:3]).min() > 0.01  # the platform has moved (cm), so this compares something
    assert np.all(np.abs(results[CONTROLLER][0][:3]) > 0.0)
    wine = subprocess.run([wine_binary(), "--version"], env=env, capture_output=True, text=True, timeout=60)
    compatibility.record(
        request, tool="wine", version=wine.stdout.split()[0].removeprefix("wine-"), fmi=f"{family[3]}.0",
        interface="CS", platform="x86_64-windows (wine on x86_64-linux)",
        command=compatibility.node_command(request),  # the hosts are compiled and run by this test
        difference=compatibility.difference(max(compatibility.relative(w, lx) for lx, w in results.values()),
                                            "relative", "the x86_64-linux binaries, after 2,000 steps"))
    # measured: identical bit for bit (0.0); first wine start ~10 s, then < 1 s per run
    print(family, "wine seconds", seconds,
          "max relative difference", {m: float(np.max(np.abs(w - lx) / np.maximum(np.abs(lx), 1e-300)))
                                      for m, (lx, w) in results.items()})


@pytest.mark.windows
@pytest.mark.parametrize("family", FAMILIES)
def test_windows_dlls_import_only_windows_system_dlls(native_built, family, tmp_path):
    imports = {}
    for model in FMU_NAMES:
        dll = unzip(native_built[family][model], tmp_path / model) / "binaries" / BINARIES[family]["windows"] / \
            f"{model}.dll"
        pe = lief.PE.parse(str(dll))
        assert pe.header.machine == lief.PE.Header.MACHINE_TYPES.AMD64
        imports[model] = {i.name.lower() for i in pe.imports}
    for model, names in imports.items():
        assert "kernel32.dll" in names, imports
        assert all(n in {"kernel32.dll", "msvcrt.dll", "ucrtbase.dll"} or n.startswith("api-ms-win-")
                   for n in names), imports  # measured: KERNEL32.dll and msvcrt.dll


# -- 3. Source FMU ---------------------------------------------------------------------------

def declared_sources(fmu: Path, family: str) -> tuple[list[str], list[str], list[str]]:
    """(C files, compiler options, libraries) as the FMU declares them for Linux: <SourceFiles>
    of the FMI 2.0 modelDescription.xml, sources/buildDescription.xml in FMI 3.0 (its
    configuration without a platform, the one for every platform but Windows)."""
    with zipfile.ZipFile(fmu) as z:
        if family == "fmi2":
            root = ET.fromstring(z.read("modelDescription.xml"))
            return [f.get("name") for f in root.findall("CoSimulation/SourceFiles/File")], [], []
        root = ET.fromstring(z.read("sources/buildDescription.xml"))
    files, options = [], []
    for config in [c for c in root.findall("BuildConfiguration") if c.get("platform") is None]:
        for fileset in config.findall("SourceFileSet"):
            options += (fileset.get("compilerOptions") or "").split()
            files += [f.get("name") for f in fileset.findall("SourceFile")]
    libraries = [lib.get("name") for c in root.findall("BuildConfiguration") if c.get("platform") is None
                 for lib in c.findall("Library")]
    return files, options, libraries


@pytest.mark.parametrize("model", FMU_NAMES)
@pytest.mark.parametrize("family", FAMILIES)
def test_sources_alone_compile_from_the_declared_file_list_and_step_bit_for_bit_like_the_shipped_binary(
        native_built, family, model, tmp_path):
    fmu = native_built[family][model]
    files, options, libraries = declared_sources(fmu, family)
    assert files and all(f.endswith(".c") for f in files)
    src = tmp_path / "source_only"  # an empty folder with nothing but sources/
    with zipfile.ZipFile(fmu) as z:
        for name in z.namelist():
            if name.startswith("sources/"):
                z.extract(name, src)
    sources = src / "sources"
    assert {p.name for p in sources.iterdir()} >= set(files)
    lib = tmp_path / f"{model}.so"
    # only what the FMU declares, and the importer's FMI headers: no -O2, default visibility
    compile_c([sources / f for f in files], lib, flags=["-ffp-contract=off", *options], includes=[sources, HEADERS],
              libs=[*libraries, "m"])
    shipped_dir = unzip(fmu, tmp_path / "shipped")
    rebuilt_dir = unzip(fmu, tmp_path / "rebuilt")
    target = rebuilt_dir / "binaries" / BINARIES[family]["linux"] / f"{model}.so"
    assert target.read_bytes() != lib.read_bytes()  # really another binary (no -O2, default visibility)
    shutil.copy(lib, target)
    shipped = fmpy_run(fmu, shipped_dir, model, 200)
    rebuilt = fmpy_run(fmu, rebuilt_dir, model, 200)
    assert shipped.shape == (200, len(outputs(model)))
    assert np.all(np.isfinite(shipped)) and np.abs(shipped).max() > 0.0
    assert np.array_equal(rebuilt.view(np.uint64), shipped.view(np.uint64))  # bit for bit, at every step


# -- 4. Compliance ---------------------------------------------------------------------------

@pytest.mark.parametrize("model", FMU_NAMES)
@pytest.mark.parametrize("family", FAMILIES)
def test_fmpy_validation_finds_no_problem_in_the_native_fmus(native_built, family, model):
    assert validate_fmu(str(native_built[family][model])) == []


def test_fmpy_validate_command_reports_no_problems_found(native_built, tmp_path):
    import sys
    for family in FAMILIES:
        for model in FMU_NAMES:
            proc = subprocess.run([sys.executable, "-m", "fmpy.cli", "validate", str(native_built[family][model])],
                                  capture_output=True, text=True, cwd=tmp_path, timeout=120)
            assert proc.returncode == 0 and proc.stdout.strip() == "No problems found.", (model, proc.stdout,
                                                                                          proc.stderr)


def run_fmu_check(fmu: Path, tmp_path: Path) -> tuple[subprocess.CompletedProcess, str, Path]:
    unpack = tmp_path / "unpack"
    unpack.mkdir()
    csv, log = tmp_path / "out.csv", tmp_path / "log.txt"
    # -k cs: the Co-Simulation interface (the plant offers Model Exchange too, which fmuCheck takes first)
    proc = subprocess.run([str(FMU_CHECK), "-k", "cs", "-h", "1e-4", "-s", "0.01", "-t", str(unpack), "-o", str(csv),
                           "-e", str(log), str(fmu)], capture_output=True, text=True, timeout=300, cwd=tmp_path)
    return proc, log.read_text(), csv


@pytest.mark.needs_shared("tools/fmuCheck/fmuCheck.linux64")
@pytest.mark.parametrize("kind", ["native", "pythonfmu"])
@pytest.mark.parametrize("model", FMU_NAMES)
def test_fmu_compliance_checker_passes_the_fmi2_fmu_without_warnings_or_errors(
        native_built, built, kind, model, tmp_path, request):
    fmu = native_built["fmi2"][model] if kind == "native" else built[model]
    proc, log, csv = run_fmu_check(fmu, tmp_path)
    summary = log[log.find("FMU check summary:"):]
    assert proc.returncode == 0, summary or log
    assert re.search(r"FMU reported:\s+0 warning\(s\) and error\(s\)", summary), log
    assert re.search(r"Checker reported:\s+0 Warning\(s\)\s+0 Error\(s\)", summary), log
    assert "Simulation finished successfully at time 0.01" in log
    with open(csv) as f:
        header = [h.strip('"') for h in f.readline().strip().split(",")]
    data = np.loadtxt(csv, delimiter=",", skiprows=1, ndmin=2)
    assert header == ["time", *outputs(model)]
    assert data.shape == (101, 1 + len(outputs(model))) and np.all(np.isfinite(data))  # t = 0, 1e-4 ... 0.01
    ours = fmpy.simulate_fmu(str(fmu), stop_time=0.01, output_interval=STEP)
    fmpy_rows = np.array([ours[n] for n in outputs(model)]).T
    compatibility.record(
        request, tool="fmuCheck", version=compatibility.readme_version("fmuCheck"), fmi="2.0", interface="CS",
        command=f"{compatibility.FMUCHECK} -k cs -h 1e-4 -s 0.01 {'build/native/fmi2/' if kind == 'native' else 'build/'}{model}.fmu",
        difference=compatibility.difference(compatibility.relative(data[:, 1:], fmpy_rows), "relative",
                                            "FMPy simulate_fmu (fmuCheck accumulates t += h)"))
