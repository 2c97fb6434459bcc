"""The one C toolchain (ctoolchain/__init__.py): every FMU family and platform builds
with no system compiler, $CC is honoured for the host platform, and a failing compiler or an
unknown platform is one line with exit code 2 and no half-written FMU."""

import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from orchestrator.builder.build_native import PLATFORM_DIRS
from ctoolchain import PLATFORMS
from tapmp.interface import FMU_NAMES

pytestmark = pytest.mark.slow  # builds every family for every platform with zig cc

ROOT = Path(__file__).resolve().parents[2]
VENV_BIN = Path(sys.executable).parent
# Every name under which a system C compiler or linker could be called.
COMPILERS = ("gcc", "cc", "c99", "clang", "ld", "x86_64-linux-gnu-gcc", "x86_64-w64-mingw32-gcc",
             "i686-w64-mingw32-gcc", "aarch64-linux-gnu-gcc")
EXPECTED_BINARIES = {
    "fmi2": {"linux64": ".so", "aarch64-linux": ".so", "win64": ".dll", "win32": ".dll", "darwin64": ".dylib"},
    "fmi3": {"x86_64-linux": ".so", "aarch64-linux": ".so", "x86_64-windows": ".dll", "x86-windows": ".dll",
             "x86_64-darwin": ".dylib", "aarch64-darwin": ".dylib"},
}


def shim_path(tmp_path: Path) -> tuple[dict, Path]:
    """An environment whose PATH starts with shims of every system compiler name that record
    their call in a log and fail, and has no CC: a call to any of them shows in the log."""
    shims, log = tmp_path / "shims", tmp_path / "compiler_calls.log"
    shims.mkdir()
    for name in COMPILERS:
        shim = shims / name
        shim.write_text(f'#!/bin/sh\necho "{name} $*" >> "{log}"\nexit 1\n')
        shim.chmod(0o755)
    env = {k: v for k, v in os.environ.items() if k != "CC"}
    env["PATH"] = f"{shims}:{VENV_BIN}:{os.environ['PATH']}"
    return env, log


def binaries_of(fmu: Path) -> set[str]:
    with zipfile.ZipFile(fmu) as z:
        return {n for n in z.namelist() if n.startswith("binaries/")}


def test_build_fmus_sh_builds_every_family_and_platform_without_a_system_compiler(tmp_path):
    env, log = shim_path(tmp_path)
    assert subprocess.run(["gcc", "--version"], env=env, capture_output=True).returncode == 1  # the shim
    log.unlink()
    out = tmp_path / "out"
    proc = subprocess.run(["bash", str(ROOT / "build_fmus.sh"), str(out)], env=env, capture_output=True,
                          text=True, timeout=1800)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert not log.exists(), log.read_text()  # no system compiler was called
    for model in ("TAPMP_Plant", "TAPMP_Controller", "TAPMP_Trajectory", "TAPMP_ClosedLoop"):
        assert (out / f"{model}.fmu").is_file()
    assert (out / "TAPMP.ssp").is_file()
    for family, folders in EXPECTED_BINARIES.items():
        assert (out / "native" / family / "TAPMP.ssp").is_file()
        for model in FMU_NAMES:
            expected = {f"binaries/{d}/{model}{suffix}" for d, suffix in folders.items()}
            assert binaries_of(out / "native" / family / f"{model}.fmu") == expected
    with zipfile.ZipFile(out / "TAPMP_Plant.fmu") as z:  # the pythonfmu family's binary, by zig cc
        assert "binaries/linux64/TAPMP_Plant.so" in z.namelist()


def test_every_platform_has_a_binaries_folder_in_both_fmi_versions():
    assert set(PLATFORM_DIRS["fmi2"]) == set(PLATFORM_DIRS["fmi3"]) == set(PLATFORMS)
    assert set(PLATFORM_DIRS["fmi2"].values()) == set(EXPECTED_BINARIES["fmi2"])
    assert set(PLATFORM_DIRS["fmi3"].values()) == set(EXPECTED_BINARIES["fmi3"])


def test_cc_is_used_for_the_host_platform_and_zig_for_the_others(tmp_path):
    log = tmp_path / "cc.log"
    wrapper = tmp_path / "mycc"  # a CC that records its call and compiles with zig cc
    wrapper.write_text(f'#!/bin/sh\necho "$*" >> "{log}"\n'
                       f'exec "{sys.executable}" -m ziglang cc -target x86_64-linux-gnu.2.17 "$@"\n')
    wrapper.chmod(0o755)
    env = dict(os.environ, CC=str(wrapper))
    proc = subprocess.run([sys.executable, "-m", "orchestrator.builder.build_native", "--out", str(tmp_path / "n"),
                           "--platform", "x86_64-linux", "--platform", "aarch64-linux"],
                          env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    calls = log.read_text().splitlines()
    # 3 models and the drive x 2 FMI versions and the clocked FMI 3.0 controller, x86_64-linux only, and the
    # C model's library (which computes the reference experiments' inputs) unless the cache holds it already
    assert len([c for c in calls if "/all.c" in c]) == 9, calls
    assert len(calls) in (9, 10), calls
    assert all("-target" not in c and "-ffp-contract=off" in c for c in calls)
    assert binaries_of(tmp_path / "n" / "fmi3" / "TAPMP_Plant.fmu") == {
        "binaries/x86_64-linux/TAPMP_Plant.so", "binaries/aarch64-linux/TAPMP_Plant.so"}


def failing_cc(tmp_path: Path) -> Path:
    cc = tmp_path / "failing-cc"
    cc.write_text('#!/bin/sh\necho "note: starting" >&2\necho "model.c:12:3: error: unknown type name \'dobule\'" >&2\n'
                  'echo "model.c:20:1: error: a second error" >&2\nexit 1\n')
    cc.chmod(0o755)
    return cc


def test_a_failing_compiler_is_one_line_naming_the_target_and_its_first_error_and_leaves_no_fmu(tmp_path):
    out = tmp_path / "n"
    (out / "fmi2").mkdir(parents=True)
    previous = out / "fmi2" / "TAPMP_Trajectory.fmu"
    previous.write_bytes(b"an FMU of an earlier build")
    env = dict(os.environ, CC=str(failing_cc(tmp_path)))
    proc = subprocess.run([sys.executable, "-m", "orchestrator.builder.build_native", "--out", str(out)],
                          env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1, proc.stderr
    assert proc.stderr.startswith("error: fmi2/TAPMP_Trajectory.fmu (x86_64-linux): ")
    assert proc.stderr.rstrip().endswith("failed: model.c:12:3: error: unknown type name 'dobule'")
    # nothing half written: the earlier FMU is untouched, no other file appeared
    assert sorted(p.name for p in out.rglob("*")) == ["TAPMP_Trajectory.fmu", "fmi2"]
    assert previous.read_bytes() == b"an FMU of an earlier build"


def test_tapmp_build_with_a_failing_cc_exits_2_with_one_line(tmp_path):
    env = dict(os.environ, CC=str(failing_cc(tmp_path)))
    out = tmp_path / "b"
    proc = subprocess.run([str(VENV_BIN / "tapmp"), "build", "--out", str(out), "--platform", "x86_64-linux"],
                          env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 2
    assert proc.stderr == ("error: the pythonfmu FMUs' front binary (x86_64-linux): "
                           f"{tmp_path / 'failing-cc'} failed: model.c:12:3: error: unknown type name 'dobule'\n")
    assert not list(out.rglob("*.fmu"))


def test_a_missing_cc_names_it(tmp_path):
    env = dict(os.environ, CC=str(tmp_path / "no-such-cc"))
    proc = subprocess.run([sys.executable, "-m", "orchestrator.builder.build_native", "--out", str(tmp_path / "n"),
                           "--platform", "x86_64-linux"], env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 2
    assert proc.stderr == (f"error: fmi2/TAPMP_Trajectory.fmu (x86_64-linux): C compiler "
                           f"'{tmp_path / 'no-such-cc'}' not found (unset CC to use zig cc from the ziglang package)\n")


@pytest.mark.parametrize("command", [[str(VENV_BIN / "tapmp"), "build"],
                                     [sys.executable, "-m", "orchestrator.builder.build_native"]])
def test_an_unknown_platform_is_one_line_with_exit_2_and_builds_nothing(tmp_path, command):
    out = tmp_path / "b"
    proc = subprocess.run([*command, "--out", str(out), "--platform", "x86_64-linux", "--platform", "riscv64-linux"],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 2
    assert proc.stderr == ("error: --platform = 'riscv64-linux' is invalid: allowed are x86_64-linux, aarch64-linux, "
                           "x86_64-windows, x86-windows, x86_64-darwin, aarch64-darwin\n")
    assert not out.exists()


def test_a_source_that_does_not_compile_names_the_platform_and_the_error_for_a_cross_target(tmp_path):
    from orchestrator.builder.build_native import NativeBuildError, build_native_fmu
    bad = tmp_path / "bad_model.c"
    bad.write_text("this is not C;\n")
    with pytest.raises(NativeBuildError) as err:
        build_native_fmu("TAPMP_Plant", "fmi3", tmp_path, model_source=bad, platforms=["aarch64-darwin"])
    message = str(err.value)
    assert "\n" not in message
    assert message.startswith("fmi3/TAPMP_Plant.fmu (aarch64-darwin): zig cc failed: ")
    assert "plant.c:1:1: error: " in message  # the model file of sources/, as the FMU ships it
    assert list(tmp_path.iterdir()) == [bad]
