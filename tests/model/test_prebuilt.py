"""The libraries a binary wheel ships (ctoolchain/prebuilt.py): named by stem, source hash and
platform, found for this process's platform before the compiled-code cache, and taken without
calling any compiler (tests/project/test_wheel.py installs real wheels)."""

import shutil
from pathlib import Path

import pytest

from ctoolchain.prebuilt import WHEEL_TAGS, digest, find_prebuilt, host_platform, prebuilt_name
from ctoolchain import PLATFORMS
from orchestrator.engine import stepper
from tapmp import cmodel

HASH = "0123456789abcdef"


def test_every_platform_has_a_wheel_tag_and_this_machine_is_x86_64_linux():
    assert set(WHEEL_TAGS) == set(PLATFORMS)
    assert host_platform() == "x86_64-linux"  # the suite's machine (ctoolchain.HOST)


def test_the_name_carries_the_stem_the_hash_and_the_platform_with_its_suffix():
    assert prebuilt_name("tapmp_model", HASH, "x86_64-linux") == f"tapmp_model-{HASH}-x86_64-linux.so"
    assert prebuilt_name("tapmp_stepper", HASH, "x86-windows") == f"tapmp_stepper-{HASH}-x86-windows.dll"
    assert prebuilt_name("tapmp_model", HASH, "aarch64-darwin") == f"tapmp_model-{HASH}-aarch64-darwin.dylib"
    with pytest.raises(ValueError, match=r"^platform = 'riscv64-linux' is invalid: allowed are x86_64-linux, "):
        prebuilt_name("tapmp_model", HASH, "riscv64-linux")


def test_only_this_platforms_library_of_these_sources_is_found(tmp_path):
    assert find_prebuilt(tmp_path, "tapmp_model", HASH) is None
    (tmp_path / prebuilt_name("tapmp_model", HASH, "aarch64-linux")).write_bytes(b"\x7fELF")
    (tmp_path / prebuilt_name("tapmp_model", "fedcba9876543210", "x86_64-linux")).write_bytes(b"\x7fELF")
    assert find_prebuilt(tmp_path, "tapmp_model", HASH) is None  # another platform's, other sources'
    mine = tmp_path / prebuilt_name("tapmp_model", HASH, "x86_64-linux")
    mine.write_bytes(b"\x7fELF")
    assert find_prebuilt(tmp_path, "tapmp_model", HASH) == mine


def test_the_digest_changes_with_any_byte_of_the_sources_and_with_the_flags(tmp_path):
    source = tmp_path / "a.c"
    source.write_text("int f(void) { return 1; }\n")
    first = digest([source], ["-O2"])
    assert len(first) == 16 and first == digest([source], ["-O2"])
    assert digest([source], ["-O1"]) != first
    source.write_text("int f(void) { return 2; }\n")
    assert digest([source], ["-O2"]) != first


def forbid_compiling(tmp_path, monkeypatch) -> Path:
    """An empty compiled-code cache and a $CC that records its call and fails: the path of its log."""
    log = tmp_path / "cc.log"
    cc = tmp_path / "cc"
    cc.write_text(f'#!/bin/sh\necho "$*" >> "{log}"\nexit 1\n')
    cc.chmod(0o755)
    monkeypatch.setenv("CC", str(cc))
    monkeypatch.setenv("TAPMP_CACHE", str(tmp_path / "cache"))
    return log


def test_the_stepping_core_shipped_beside_its_source_is_loaded_and_nothing_compiles(tmp_path, monkeypatch):
    package = tmp_path / "engine"
    package.mkdir()
    source = Path(shutil.copy(stepper.SOURCE, package / "stepper.c"))
    shipped = package / prebuilt_name("tapmp_stepper", digest([source], stepper.CFLAGS), "x86_64-linux")
    shutil.copyfile(stepper.build(), shipped)  # the real core, from the checkout's cache (compiled there if needed)
    log = forbid_compiling(tmp_path, monkeypatch)
    monkeypatch.setattr(stepper, "SOURCE", source)
    assert stepper.build() == shipped
    assert not log.exists() and not (tmp_path / "cache").exists()


def test_the_c_model_shipped_beside_its_sources_comes_before_the_cache_and_nothing_compiles(tmp_path, monkeypatch):
    package = tmp_path / "c"
    package.mkdir()
    shipped = package / cmodel.bundled_name("x86_64-linux")
    shutil.copyfile(cmodel.library_path(), shipped)  # the checkout's, from its cache
    log = forbid_compiling(tmp_path, monkeypatch)
    monkeypatch.setattr(cmodel, "C_DIR", package)
    assert cmodel.library_path() == shipped
    assert not log.exists() and not (tmp_path / "cache").exists()


def test_the_compiler_named_in_the_no_compiler_message_is_the_one_the_package_depends_on():
    import tomllib
    from ctoolchain import ZIGLANG
    root = Path(__file__).resolve().parents[2]
    assert ZIGLANG in tomllib.loads((root / "pyproject.toml").read_text())["project"]["dependencies"]
