"""The native FMUs' binaries for every platform, built by zig cc (ctoolchain/__init__.py).

* aarch64 Linux runs: the C hosts (tests/fmu/c_host), built for aarch64 by the same toolchain, step
  the aarch64 binaries 2,000 times under qemu-aarch64 (Debian's qemu-user, libc6-arm64-cross as
  the sysroot) and must give the x86_64 binaries' outputs.
* Every binary is checked structurally with lief: its format and architecture, that it exports
  exactly the FMI functions of the x86_64 Linux binary and nothing else, and what it needs
  (Linux: libc and libm of glibc <= 2.17; Windows: its own DLLs; macOS: libSystem alone).
  macOS binaries cannot run here: they are built and checked, not run. The Windows ones run
  under wine in test_native_hosts.py.
"""

import os
import re
import shutil
import struct
import subprocess
import zipfile
from pathlib import Path

from tests.interop import compatibility
import lief

lief.logging.disable()  # its notes on optional sections it skips
import numpy as np
import pytest

from tapmp.interface import CONTROLLER, FMU_NAMES, PLANT, TRAJECTORY
from tests.fmu.test_native_hosts import HEADERS, compile_host, host_args, outputs, parse, run_linux_host, unzip

pytestmark = pytest.mark.slow  # aarch64 binaries under qemu, every platform's binaries

FAMILIES = ("fmi2", "fmi3")
QEMU = "qemu-aarch64"
SYSROOT = Path("/usr/aarch64-linux-gnu")  # Debian's libc6-arm64-cross
X86_64_LINUX = {"fmi2": "linux64", "fmi3": "x86_64-linux"}
MACOS_LIBSYSTEM = "/usr/lib/libSystem.B.dylib"
# Defined by the Mach-O linker in every dylib (the image's own header and handle), not by the model.
MACHO_LINKER_SYMBOLS = {"__mh_dylib_header", "___dso_handle"}
CPU = {"x86_64": lief.MachO.Header.CPU_TYPE.X86_64, "arm64": lief.MachO.Header.CPU_TYPE.ARM64}


def fmi_functions(family: str) -> set[str]:
    """Every function of the FMI standard header (fmi2Functions.h or fmi3Functions.h)."""
    text = (HEADERS / f"{family}Functions.h").read_text()
    return set(re.findall(rf"{family.upper()}_Export\s+{family}\w+TYPE\s+({family}\w+)\s*;", text))


def member(fmu: Path, name: str) -> bytes:
    with zipfile.ZipFile(fmu) as z:
        return z.read(name)


def elf_exports(path_or_bytes) -> set[str]:
    elf = lief.ELF.parse(path_or_bytes if isinstance(path_or_bytes, str) else list(path_or_bytes))
    return {s.name for s in elf.exported_symbols}


@pytest.fixture(scope="module")
def linux_exports(native_built):
    """{family: {model: the functions the x86_64 Linux binary exports}}, the reference set."""
    return {family: {model: elf_exports(member(native_built[family][model],
                                               f"binaries/{X86_64_LINUX[family]}/{model}.so"))
                     for model in FMU_NAMES} for family in FAMILIES}


# -- aarch64 Linux, under qemu ----------------------------------------------------------------

@pytest.mark.parametrize("family", FAMILIES)
def test_aarch64_linux_binaries_under_qemu_step_2000_times_like_the_x86_64_binaries(native_built, family, tmp_path,
                                                                                   request):
    steps = 2000
    x86_exe = compile_host(family, tmp_path)
    arm_exe = compile_host(family, tmp_path, platform="aarch64-linux")
    assert lief.ELF.parse(str(arm_exe)).header.machine_type == lief.ELF.ARCH.AARCH64
    results = {}
    for model in (PLANT, CONTROLLER, TRAJECTORY):
        fmu = native_built[family][model]
        x86_dir = unzip(fmu, tmp_path / f"{model}_x86_64")
        arm_dir = unzip(fmu, tmp_path / f"{model}_aarch64")
        # The host opens binaries/<x86_64 folder>/MODEL.so: put the aarch64 binary there.
        shutil.copy(arm_dir / "binaries" / "aarch64-linux" / f"{model}.so",
                    arm_dir / "binaries" / X86_64_LINUX[family] / f"{model}.so")
        x86 = run_linux_host(x86_exe, x86_dir, model, steps)
        assert x86.returncode == 0, x86.stderr
        arm = subprocess.run([QEMU, "-L", str(SYSROOT), str(arm_exe), str(arm_dir), *host_args(model, steps)],
                             env={"PATH": os.environ["PATH"]}, capture_output=True, text=True, timeout=600)
        assert arm.returncode == 0, arm.stdout + arm.stderr
        results[model] = (np.array(parse(x86.stdout)), np.array(parse(arm.stdout)))
    for model, (x86, arm) in results.items():
        assert x86.shape == arm.shape == (len(outputs(model)),)
        assert np.all(np.isfinite(arm))
        assert np.all(np.abs(arm - x86) <= 1e-12 * np.abs(x86)), (model, arm - x86)
    assert np.abs(results[PLANT][0][:3]).min() > 0.01  # the platform has moved (cm): this compares something
    assert np.all(np.abs(results[CONTROLLER][0][:3]) > 0.0)
    qemu = subprocess.run([QEMU, "--version"], capture_output=True, text=True, timeout=60).stdout.split()
    compatibility.record(
        request, tool="qemu-user", version=qemu[2], fmi=f"{family[3]}.0", interface="CS",
        platform="aarch64-linux (qemu-aarch64 on x86_64-linux)",
        command=compatibility.node_command(request),  # the hosts are compiled and run by this test
        difference=compatibility.difference(max(compatibility.relative(a, x) for x, a in results.values()),
                                            "relative", "the x86_64-linux binaries, after 2,000 steps"))
    # measured: bit for bit (maximum relative difference 0.0)
    print(family, "aarch64 vs x86_64 max relative difference",
          {m: float(np.max(np.abs(a - x) / np.maximum(np.abs(x), 1e-300))) for m, (x, a) in results.items()},
          "bit-identical:", all(np.array_equal(x.view(np.uint64), a.view(np.uint64)) for x, a in results.values()))


# -- Linux -------------------------------------------------------------------------------------

@pytest.mark.parametrize("platform,machine", [("x86_64-linux", lief.ELF.ARCH.X86_64),
                                              ("aarch64-linux", lief.ELF.ARCH.AARCH64)])
@pytest.mark.parametrize("family", FAMILIES)
def test_linux_binaries_export_only_the_fmi_functions_and_need_glibc_2_17_at_most(
        native_built, linux_exports, family, platform, machine):
    folder = X86_64_LINUX[family] if platform == "x86_64-linux" else "aarch64-linux"
    for model in FMU_NAMES:
        elf = lief.ELF.parse(list(member(native_built[family][model], f"binaries/{folder}/{model}.so")))
        assert elf.header.file_type == lief.ELF.Header.FILE_TYPE.DYN
        assert elf.header.machine_type == machine
        exports = {s.name for s in elf.exported_symbols}
        assert exports == linux_exports[family][model]
        assert f"{family}DoStep" in exports and exports <= fmi_functions(family), exports - fmi_functions(family)
        assert set(elf.libraries) <= {"libc.so.6", "libm.so.6"}, elf.libraries
        versions = {s.symbol_version.symbol_version_auxiliary.name for s in elf.imported_symbols
                    if s.has_version and s.symbol_version.has_auxiliary_version}
        assert versions and all(re.fullmatch(r"GLIBC_2\.\d+(\.\d+)?", v) for v in versions), versions
        assert max(tuple(map(int, v[6:].split("."))) for v in versions) <= (2, 17), versions


# -- Windows -----------------------------------------------------------------------------------

@pytest.mark.windows
@pytest.mark.parametrize("platform,machine", [("x86_64-windows", lief.PE.Header.MACHINE_TYPES.AMD64),
                                              ("x86-windows", lief.PE.Header.MACHINE_TYPES.I386)])
@pytest.mark.parametrize("family", FAMILIES)
def test_windows_dlls_export_only_the_fmi_functions_and_import_only_windows_dlls(
        native_built, linux_exports, family, platform, machine):
    from orchestrator.builder.build_native import PLATFORM_DIRS
    for model in FMU_NAMES:
        pe = lief.PE.parse(list(member(native_built[family][model],
                                       f"binaries/{PLATFORM_DIRS[family][platform]}/{model}.dll")))
        assert pe.header.machine == machine
        assert pe.header.has_characteristic(lief.PE.Header.CHARACTERISTICS.DLL)
        assert {e.name for e in pe.exported_functions} == linux_exports[family][model]
        imports = {i.name.lower() for i in pe.imports}
        assert "kernel32.dll" in imports
        # the Universal C Runtime of Windows 10 and later (api-ms-win-crt-*), nothing else
        assert all(n == "kernel32.dll" or n.startswith("api-ms-win-crt-") for n in imports), imports


# -- macOS: built and checked, not run ---------------------------------------------------------

def fat_slices(data: bytes) -> list[tuple[int, int, int, int, int]]:
    """(cputype, cpusubtype, offset, size, align) of each slice of a universal Mach-O file,
    read from its big-endian header as Apple's <mach-o/fat.h> defines it."""
    magic, count = struct.unpack_from(">II", data)
    assert magic == 0xCAFEBABE
    return [struct.unpack_from(">IIIII", data, 8 + 20 * i) for i in range(count)]


def check_dylib(macho, cpu: str, expected_exports: set[str]) -> None:
    """One thin Mach-O dylib: its CPU, type, exports (the FMI functions) and imports (libSystem)."""
    assert macho.header.cpu_type == CPU[cpu]
    assert macho.header.file_type == lief.MachO.Header.FILE_TYPE.DYLIB
    assert macho.header.has(lief.MachO.Header.FLAGS.TWOLEVEL)  # every import bound to its library
    exports = {s.name for s in macho.exported_symbols} - MACHO_LINKER_SYMBOLS
    assert exports == {"_" + name for name in expected_exports}
    dylibs = [cmd.name for cmd in macho.commands if cmd.command == lief.MachO.LoadCommand.TYPE.LOAD_DYLIB]
    assert dylibs == [MACOS_LIBSYSTEM]
    bound = {s.binding_info.library.name for s in macho.imported_symbols
             if s.has_binding_info and s.binding_info.has_library}
    assert bound == {MACOS_LIBSYSTEM}
    assert list(macho.build_version.minos) == [11, 0, 0]  # runs on macOS 11 and later


@pytest.mark.parametrize("model", FMU_NAMES)
def test_fmi2_darwin64_is_one_universal_dylib_of_x86_64_and_arm64(native_built, linux_exports, model):
    data = member(native_built["fmi2"][model], f"binaries/darwin64/{model}.dylib")
    slices = fat_slices(data)
    assert [(c, s) for c, s, *_ in slices] == [(0x01000007, 3), (0x0100000C, 0)]  # x86_64, arm64 (ALL)
    end = 8 + 20 * len(slices)
    for _, _, offset, size, align in slices:
        assert offset % (1 << align) == 0 and offset >= end and offset + size <= len(data)
        assert struct.unpack_from("<I", data, offset)[0] == 0xFEEDFACF  # a 64-bit Mach-O in each slice
        end = offset + size
    fat = lief.MachO.parse(list(data))
    assert fat.size == 2
    for macho, cpu in zip(fat, ("x86_64", "arm64")):
        check_dylib(macho, cpu, linux_exports["fmi2"][model])


@pytest.mark.parametrize("platform,cpu", [("x86_64-darwin", "x86_64"), ("aarch64-darwin", "arm64")])
@pytest.mark.parametrize("model", FMU_NAMES)
def test_fmi3_darwin_dylibs_are_thin_dylibs_of_their_architecture(native_built, linux_exports, model, platform, cpu):
    data = member(native_built["fmi3"][model], f"binaries/{platform}/{model}.dylib")
    assert struct.unpack_from("<I", data)[0] == 0xFEEDFACF
    fat = lief.MachO.parse(list(data))
    assert fat.size == 1
    check_dylib(fat.at(0), cpu, linux_exports["fmi3"][model])
    ids = [cmd.name for cmd in fat.at(0).commands if cmd.command == lief.MachO.LoadCommand.TYPE.ID_DYLIB]
    assert ids == [f"{model}.dylib"]  # its install name, as the FMU names it
