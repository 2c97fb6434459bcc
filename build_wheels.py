"""Build tapmp-cosim's binary wheels: one per platform, each carrying the C model and the compiled
stepping core compiled by zig cc for it (setup.py, TAPMP_WHEEL_PLATFORM), so that `pip install`
on that platform never compiles.

    python build_wheels.py [--platform P ...] [--out dist] [--overwrite]

Default: every platform of ctoolchain.prebuilt.WHEEL_TAGS into dist/. Any Python 3.10+ with pip
runs it: pip builds each wheel in an isolated environment with setuptools and the ziglang package,
or in this Python's environment if it has both (setuptools >= 77: the `test` extra), which saves
installing the 100 MB compiler once per wheel.
The sources are copied into a temporary folder first, so setuptools' build folder never mixes with
the project's build/ (the FMUs). A wheel already in the output folder is kept unless --overwrite.
Exit 2 with one line on bad input or a failed build.
"""

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent
SKIP = shutil.ignore_patterns(".git", ".venv", "build", "results", "__pycache__", "*.egg-info", ".pytest_cache",
                              ".hypothesis", "dist", "*.so", "*.dll", "*.dylib")


def has_build_requirements() -> bool:
    """Whether this Python has what a platform wheel's build needs: setuptools >= 77 and ziglang."""
    import importlib.util
    from importlib import metadata
    try:
        major = int(metadata.version("setuptools").split(".")[0])
    except metadata.PackageNotFoundError:
        return False
    return major >= 77 and importlib.util.find_spec("ziglang") is not None


def main(argv=None) -> int:
    sys.path.insert(0, str(ROOT))
    from ctoolchain.prebuilt import WHEEL_TAGS
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--platform", action="append", help=f"one of {', '.join(WHEEL_TAGS)} (repeatable; default: all)")
    parser.add_argument("--out", default="dist", help="folder of the wheels (default: dist)")
    parser.add_argument("--overwrite", action="store_true", help="replace a wheel of the same name in --out")
    args = parser.parse_args(argv)
    platforms = args.platform or list(WHEEL_TAGS)
    for p in platforms:
        if p not in WHEEL_TAGS:
            print(f"error: --platform = {p!r} is invalid: allowed are {', '.join(WHEEL_TAGS)}", file=sys.stderr)
            return 2
    out = Path(args.out)
    isolation = ["--no-build-isolation"] if has_build_requirements() else []
    with tempfile.TemporaryDirectory(prefix="tapmp_wheels_") as tmp:
        src, dist = Path(tmp) / "src", Path(tmp) / "dist"
        shutil.copytree(ROOT, src, ignore=SKIP)
        for platform in platforms:
            env = {**os.environ, "TAPMP_WHEEL_PLATFORM": platform}
            proc = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", *isolation, "-q",
                                   "-w", str(dist), str(src)], env=env, capture_output=True, text=True)
            if proc.returncode != 0:
                lines = [line for line in (proc.stderr + proc.stdout).splitlines() if "error" in line.lower()]
                print(f"error: the {platform} wheel failed: {lines[0].strip() if lines else proc.returncode}",
                      file=sys.stderr)
                return 2
        wheels = sorted(dist.glob("*.whl"))
        existing = [w.name for w in wheels if (out / w.name).exists()]
        if existing and not args.overwrite:
            print(f"error: {out / existing[0]} exists: pass --overwrite to replace it", file=sys.stderr)
            return 2
        out.mkdir(parents=True, exist_ok=True)
        for wheel in wheels:
            shutil.copyfile(wheel, out / f".{wheel.name}.partial")
            (out / f".{wheel.name}.partial").replace(out / wheel.name)  # whole or absent
            print(f"{out / wheel.name} ({wheel.stat().st_size / 1e6:.1f} MB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
