"""The C host programs of tests/fmu/c_host compiled by the project's toolchain, and an FMU unzipped
for them to load."""

import zipfile
from pathlib import Path

import fmpy

from ctoolchain import compile_c

FMI_HEADERS = Path(fmpy.__file__).parent / "c-code"  # FMPy's FMI 2.0 and 3.0 headers


def compile_c_host(source: Path, exe: Path, werror: bool = False) -> Path:
    """The C host ``source`` compiled for this machine into the executable ``exe`` (-O1 -Wall, and
    -Werror if ``werror``; FMPy's FMI headers, linked with libdl); returns ``exe``."""
    flags = ["-O1", "-Wall", *(["-Werror"] if werror else [])]
    return compile_c([source], exe, shared=False, flags=flags, includes=[FMI_HEADERS], libs=["dl"])


def unzip_fmu(fmu: Path, dest: Path) -> Path:
    """``fmu`` extracted into ``dest``, its shared libraries (binaries/<platform>/*.so) made
    executable, as a C host loads them; returns ``dest``."""
    with zipfile.ZipFile(fmu) as z:
        z.extractall(dest)
    for so in (dest / "binaries").glob("*/*.so"):
        so.chmod(0o755)
    return dest
