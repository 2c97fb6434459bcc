"""Libraries compiled when a binary wheel is built, shipped inside the package beside their sources.

A platform wheel (setup.py, ``TAPMP_WHEEL_PLATFORM``) carries, for its one platform, each library
the package would otherwise compile on first use, named ``STEM-HASH-PLATFORM.SUFFIX``: HASH is the
caller's hash of the sources and flags, so a library of other sources is never taken, and PLATFORM
(a name of ctoolchain.PLATFORMS) keeps a library of another platform from being loaded. Such a
library is installed with the package's code and trusted like it (whoever can write it can write
the package's .py files too): it is not checked as the compiled-code cache is.
"""

import platform as _platform
import struct
import sys
from pathlib import Path

from . import PLATFORMS, SUFFIX, check_platform, os_of

# Python's sys.platform -> the OS part of a platform name; platform.machine() -> its CPU part
_OS = {"linux": "linux", "win32": "windows", "darwin": "darwin"}
_CPU = {"x86_64": "x86_64", "amd64": "x86_64", "aarch64": "aarch64", "arm64": "aarch64",
        "x86": "x86", "i386": "x86", "i686": "x86"}

# The wheel's platform tag of each platform: py3-none-TAG, since the libraries are loaded with
# ctypes/cffi's ABI mode, not as CPython extensions (no Python ABI in them). Linux: manylinux2014
# (glibc 2.17, the version ctoolchain links against); macOS 11 (ctoolchain's minimum).
WHEEL_TAGS = {
    "x86_64-linux": "manylinux_2_17_x86_64.manylinux2014_x86_64",
    "aarch64-linux": "manylinux_2_17_aarch64.manylinux2014_aarch64",
    "x86_64-windows": "win_amd64",
    "x86-windows": "win32",
    "x86_64-darwin": "macosx_11_0_x86_64",
    "aarch64-darwin": "macosx_11_0_arm64",
}


def host_platform() -> str | None:
    """The platform name (of PLATFORMS) of this Python process, or None if it is none of them.
    A 32-bit Python on 64-bit Windows is x86-windows: it loads 32-bit DLLs only."""
    os_name = _OS.get(sys.platform)
    cpu = _CPU.get(_platform.machine().lower())
    if os_name is None or cpu is None:
        return None
    if os_name == "windows" and struct.calcsize("P") == 4:
        cpu = "x86"
    name = f"{cpu}-{os_name}"
    return name if name in PLATFORMS else None


def prebuilt_name(stem: str, digest: str, platform: str) -> str:
    """File name of the library ``stem`` of sources hashed ``digest`` for ``platform``."""
    return f"{stem}-{digest}-{check_platform(platform)}{SUFFIX[os_of(platform)]}"


def find_prebuilt(folder: Path, stem: str, digest: str) -> Path | None:
    """The library ``stem`` of sources ``digest`` for this process's platform shipped in
    ``folder`` (a package folder), or None if the package has none (a source install, an
    editable install, a wheel of another platform)."""
    host = host_platform()
    if host is None:
        return None
    path = Path(folder) / prebuilt_name(stem, digest, host)
    return path if path.is_file() else None


def digest(files, flags=()) -> str:
    """16 hex digits of the SHA-256 of the contents of ``files`` and the compiler ``flags``: the
    HASH of a shipped library compiled from them with those flags."""
    import hashlib
    h = hashlib.sha256()
    for f in files:
        h.update(Path(f).read_bytes() + b"\0")
    h.update("\0".join(flags).encode())
    return h.hexdigest()[:16]
