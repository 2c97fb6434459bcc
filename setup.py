"""The binary wheels: TAPMP_WHEEL_PLATFORM=<platform> makes the wheel carry the C model
(tapmp/c/tapmp_model-HASH-PLATFORM.so) and the compiled stepping core
(orchestrator/engine/tapmp_stepper-HASH-PLATFORM.so) compiled by zig cc for that platform, and
tags it py3-none-<platform tag> (ctoolchain.prebuilt.WHEEL_TAGS). Without it the wheel (and the
sdist) holds the sources only, py3-none-any, and compiles on first use.

`python build_wheels.py` builds them all.
Everything else (metadata, packages, package data) is in pyproject.toml.
"""

import os
import sys
from pathlib import Path

from setuptools import Distribution, setup
from setuptools.command.bdist_wheel import bdist_wheel
from setuptools.command.build_py import build_py

ROOT = Path(__file__).resolve().parent
sys.path.insert(0, str(ROOT))  # the sources being built, not an installed tapmp
from ctoolchain import ZIGLANG  # noqa: E402 (ctoolchain needs nothing beyond the standard library)
from ctoolchain.prebuilt import WHEEL_TAGS  # noqa: E402

TARGET = os.environ.get("TAPMP_WHEEL_PLATFORM", "").strip()
if TARGET and TARGET not in WHEEL_TAGS:
    raise SystemExit(f"error: TAPMP_WHEEL_PLATFORM = {TARGET!r} is invalid: allowed are {', '.join(WHEEL_TAGS)}")
# Every shipped library's name (ctoolchain.prebuilt.prebuilt_name), whatever its hash and platform.
SHIPPED = ("tapmp/c/tapmp_model-*-*", "orchestrator/engine/tapmp_stepper-*-*")


def compile_shipped(build_lib: Path, platform: str) -> list[Path]:
    """Compile the C model and the stepping core for ``platform`` into the package tree
    ``build_lib`` under their shipped names; returns their paths."""
    from ctoolchain import compile_c
    from ctoolchain.prebuilt import digest, prebuilt_name
    from orchestrator.engine import stepper
    from tapmp import cmodel
    model = build_lib / "tapmp" / "c" / cmodel.bundled_name(platform)
    cmodel.compile_library(model, platform)
    core = build_lib / "orchestrator" / "engine" / prebuilt_name("tapmp_stepper", digest([stepper.SOURCE], stepper.CFLAGS),
                                                                 platform)
    compile_c([stepper.SOURCE], core, platform, flags=stepper.CFLAGS, libs=("m",), what="the compiled stepping core")
    return [model, core]


class BuildWithLibraries(build_py):
    """build_py, then (for a platform wheel) the compiled libraries into the build tree; a
    library left there by an earlier build of another platform or of other sources is removed
    first, so that a wheel carries its own platform's only."""

    def run(self):
        super().run()
        build_lib = Path(self.build_lib)
        for pattern in SHIPPED:
            for old in build_lib.glob(pattern):
                old.unlink()
        if TARGET:
            for path in compile_shipped(build_lib, TARGET):
                print(f"compiled {path.relative_to(build_lib)} for {TARGET}")


class PlatformWheel(bdist_wheel):
    """bdist_wheel tagged py3-none-<tag of TAPMP_WHEEL_PLATFORM>: the libraries are loaded with
    ctypes/cffi's ABI mode, so the wheel depends on the platform but on no Python ABI."""

    def get_tag(self):
        if not TARGET:
            return super().get_tag()
        return "py3", "none", WHEEL_TAGS[TARGET]


class PlatformDistribution(Distribution):
    """A distribution with platform code: its packages go into the wheel's root as platlib, not as
    purelib under .data (what setuptools does for a pure distribution with root_is_pure off)."""

    def has_ext_modules(self):
        return True


# A platform wheel's build needs the compiler, which pip installs into the isolated build
# environment (setuptools asks for setup_requires in get_requires_for_build_wheel); the compile
# itself imports nothing beyond the standard library.
setup(cmdclass={"build_py": BuildWithLibraries, "bdist_wheel": PlatformWheel},
      distclass=PlatformDistribution if TARGET else Distribution,
      setup_requires=[ZIGLANG] if TARGET else [])
