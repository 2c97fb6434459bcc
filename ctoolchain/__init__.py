"""The one C compiler of the project: Zig's ``zig cc`` from PyPI's ``ziglang`` package.

Every C file of the project (the native FMUs for every platform, the pythonfmu family's
binary, the test hosts, the benchmark master) is compiled through :func:`compile_c`, so a
machine needs no system compiler: ``pip install`` brings the compiler, its libc headers
(glibc, mingw-w64, macOS) and the import libraries for every target.

``CC`` is honoured for the host platform (x86_64 Linux): ``CC=gcc`` builds those binaries
with gcc instead; cross targets always use Zig, which is the only compiler that has them.

Platforms (``PLATFORMS``) are named as FMI 3.0 names them (``x86_64-linux``, ...); every
binary is built with the same flags: -O2, C99, no fast-math, no fused multiply-add
(-ffp-contract=off), so that every platform steps bit for bit like the Python model.
"""

import os
import shlex
import shutil
import struct
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

from .errors import UserError

# FMI 3.0 platform name -> Zig target. Linux against glibc 2.17 (CentOS 7, 2014) so that the
# binaries load on every Linux of the last decade; Windows with mingw-w64's start-up code linked
# in and the Universal C Runtime of Windows 10 and later (api-ms-win-crt-*); macOS against
# Zig's libSystem stubs, for macOS 11 (the first on Apple silicon) and later.
PLATFORMS = {
    "x86_64-linux": "x86_64-linux-gnu.2.17",
    "aarch64-linux": "aarch64-linux-gnu.2.17",
    "x86_64-windows": "x86_64-windows-gnu",
    "x86-windows": "x86-windows-gnu",
    "x86_64-darwin": "x86_64-macos.11.0",
    "aarch64-darwin": "aarch64-macos.11.0",
}
ZIGLANG = "ziglang==0.17.1"  # the compiler pyproject.toml depends on
HOST = "x86_64-linux"  # the platform the builds run on, and the pythonfmu family's (binaries/linux64)
SUFFIX = {"linux": ".so", "windows": ".dll", "darwin": ".dylib"}
# No -ffast-math and no fused multiply-add: the C model must give the Python model's doubles.
CFLAGS = ["-O2", "-std=c99", "-ffp-contract=off", "-fvisibility=hidden", "-Wall", "-g0"]


class ToolchainError(RuntimeError):
    """Compiling failed; the message is one line naming the target and the compiler's first error."""


def os_of(platform: str) -> str:
    """"linux", "windows" or "darwin" of a platform name in PLATFORMS."""
    return platform.split("-", 1)[1]


def check_platform(platform: str) -> str:
    """``platform`` if it is in PLATFORMS, else ValueError naming the allowed ones."""
    if platform not in PLATFORMS:
        raise ValueError(f"platform = {platform!r} is invalid: allowed are {', '.join(PLATFORMS)}")
    return platform


def _has_ziglang() -> bool:
    import importlib.util
    return importlib.util.find_spec("ziglang") is not None


def zig_command() -> list[str]:
    """The command that runs ``zig cc`` from the ziglang package of this interpreter: its zig
    executable directly (no Python start per compile), else ``python -m ziglang``."""
    import importlib.util
    spec = importlib.util.find_spec("ziglang")
    if spec and spec.origin:
        zig = Path(spec.origin).parent / ("zig.exe" if os.name == "nt" else "zig")
        if zig.is_file() and os.access(zig, os.X_OK):
            return [str(zig), "cc"]
    return [sys.executable, "-m", "ziglang", "cc"]


def zig_cache() -> Path:
    """Zig's cache of compiled C runtimes and objects: $ZIG_GLOBAL_CACHE_DIR, else Zig's own default
    ($XDG_CACHE_HOME/zig, else ~/.cache/zig), which depends on no install path."""
    if os.environ.get("ZIG_GLOBAL_CACHE_DIR"):
        return Path(os.environ["ZIG_GLOBAL_CACHE_DIR"])
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "zig"


def zig_environment() -> dict:
    """The environment of a zig cc process: Zig's global cache (:func:`zig_cache`) for everything,
    also what Zig would otherwise put in a local .zig-cache beside a build.zig above the working
    folder, so the checkout, every venv and the wheel share one cache: a platform's C runtime is
    built once per machine, and an unchanged file compiles once."""
    cache = str(zig_cache())
    return {**os.environ, "ZIG_GLOBAL_CACHE_DIR": cache,
            "ZIG_LOCAL_CACHE_DIR": os.environ.get("ZIG_LOCAL_CACHE_DIR") or cache}


def compiler(platform: str = HOST) -> list[str]:
    """The compiler command for ``platform``: $CC for the host platform if set, else zig cc
    with the platform's target."""
    check_platform(platform)
    cc = os.environ.get("CC", "").strip()
    if cc and platform == HOST:
        return shlex.split(cc)
    return [*zig_command(), "-target", PLATFORMS[platform]]


def first_error(stderr: str) -> str:
    """The compiler's first error line (else its first non-empty line) of ``stderr``."""
    lines = [line.strip() for line in stderr.splitlines() if line.strip()]
    for line in lines:
        if "error" in line.lower():
            return line
    return lines[0] if lines else "no message"


def compile_c(sources, output: Path, platform: str = HOST, *, shared: bool = True,
              includes=(), flags=None, extra=(), libs=(), what: str | None = None) -> Path:
    """Compile C ``sources`` into ``output`` (a shared library, or an executable if not
    ``shared``) for ``platform`` with the project's flags (``flags`` replaces CFLAGS,
    ``extra`` is added, ``libs`` are library names to link such as "m" or "dl").

    Raises ToolchainError with one line naming ``what`` (default: the output's name), the
    platform and the compiler's first error. The output appears only when complete.
    """
    output = Path(output)
    kind = os_of(platform)
    cmd = compiler(platform)
    args = [*cmd, *(CFLAGS if flags is None else flags), *extra, *(f"-I{Path(i).resolve()}" for i in includes)]
    if shared:
        args.append("-shared")
        if kind == "linux":
            args.append("-fPIC")
    elif kind == "windows":
        args.append("-static")
    # -o names the file in the private folder: a dylib records that name as its install name
    args += ["-o", output.name, *(str(Path(s).resolve()) for s in sources)]
    # libm, libdl and libpthread are part of the C runtime on Windows and macOS
    args += [f"-l{lib}" for lib in libs if kind == "linux" or lib not in ("m", "dl", "pthread")]
    label = what or output.name
    if cmd[1:3] == ["-m", "ziglang"] and not _has_ziglang():  # say how to get a compiler, not Python's traceback
        raise ToolchainError(f"{label} ({platform}): no C compiler: the ziglang package is not installed "
                             f"(pip install {ZIGLANG}){' or set CC to a C compiler' if platform == HOST else ''}")
    # In a private folder: the linker's by-products (a DLL's import library) stay there, and
    # the output appears under its name only when complete.
    with tempfile.TemporaryDirectory(prefix="tapmp_cc_") as tmp:
        try:
            proc = _run_compiler(args, tmp, label, platform)
        except FileNotFoundError:
            raise ToolchainError(f"{label} ({platform}): C compiler {cmd[0]!r} not found "
                                 "(unset CC to use zig cc from the ziglang package)") from None
        built = Path(tmp) / output.name
        if proc.returncode != 0 or not built.is_file():
            name = "zig cc" if platform != HOST or not os.environ.get("CC", "").strip() else cmd[0]
            raise ToolchainError(f"{label} ({platform}): {name} failed: {first_error(proc.stderr or proc.stdout)}")
        partial = output.with_name(f".{output.name}.{os.getpid()}.partial")
        shutil.copyfile(built, partial)
    partial.chmod(0o755)
    partial.replace(output)
    return output


# The compiler processes running now, so that a stopped build ends them at once (stop_compilers)
# instead of waiting minutes for a target's C runtime; after a stop no compiler starts until
# allow_compilers.
_COMPILERS: set = set()
_COMPILERS_LOCK = threading.Lock()
_STOPPED = threading.Event()


def _run_compiler(args, cwd, label: str, platform: str) -> subprocess.CompletedProcess:
    """Run one compiler command in ``cwd`` (its own process group, which :func:`stop_compilers` kills)."""
    with _COMPILERS_LOCK:
        if _STOPPED.is_set():
            raise ToolchainError(f"{label} ({platform}): the build was stopped")
        proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=cwd,
                                env=zig_environment(), start_new_session=True)
        _COMPILERS.add(proc)
    try:
        out, err = proc.communicate()
    finally:
        with _COMPILERS_LOCK:
            _COMPILERS.discard(proc)
    if _STOPPED.is_set():
        raise ToolchainError(f"{label} ({platform}): the build was stopped")
    return subprocess.CompletedProcess(args, proc.returncode, out, err)


def stop_compilers() -> None:
    """Kill every compiler process :func:`compile_c` runs now (with its children) and start no other."""
    import signal
    with _COMPILERS_LOCK:
        _STOPPED.set()
        running = list(_COMPILERS)
    for proc in running:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass


def allow_compilers() -> None:
    """Let :func:`compile_c` start compilers again after :func:`stop_compilers`."""
    _STOPPED.clear()


def cache_dir() -> Path:
    """Folder of libraries compiled on first use: $TAPMP_CACHE, $XDG_CACHE_HOME/tapmp or ~/.cache/tapmp."""
    if os.environ.get("TAPMP_CACHE"):
        return Path(os.environ["TAPMP_CACHE"])
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "tapmp"


class CacheTrustError(RuntimeError, UserError):
    """The cache folder, a folder above it or a library in it could be changed by another user;
    the message names the path and what is wrong in one line."""


CACHE_FIX = "set TAPMP_CACHE to a folder of your own that only you can write (chmod 700)"


def _owner(uid: int) -> str:
    """``uid`` with its user name where the system knows one."""
    import pwd
    try:
        return f"uid {uid} ({pwd.getpwuid(uid).pw_name})"
    except KeyError:
        return f"uid {uid}"


def _distrust(path: Path, st: os.stat_result, *, ancestor: bool) -> str | None:
    """What makes ``path`` (stat ``st``) unsafe to load code through, or None: another user owns
    it (for a folder above the cache, root may own it too), or its group or others may write it
    (a folder above the cache may be world-writable with the sticky bit, as /tmp is: there no one
    can rename or remove another user's entries)."""
    import stat
    me = os.geteuid()
    if st.st_uid != me and not (ancestor and st.st_uid == 0):
        return f"{path} belongs to {_owner(st.st_uid)}, not to this user ({_owner(me)})"
    if ancestor and st.st_mode & stat.S_ISVTX:
        return None
    if st.st_mode & 0o022:
        who = "its group and others" if st.st_mode & 0o022 == 0o022 else \
            "its group" if st.st_mode & 0o020 else "others"
        return f"{path} is writable by {who} (mode {stat.S_IMODE(st.st_mode):04o})"
    return None


def private_folder(folder: Path) -> Path:
    """``folder`` (the cache) resolved, created with mode 0700 if missing, after checking that
    no other user can change it or what it holds: it and every folder above it belong to this
    user (or, above it, to root) and are writable by no one else (above it, a sticky folder such
    as /tmp may be world-writable). CacheTrustError names the first offending path; OSError if it
    cannot be created."""
    folder = Path(folder).expanduser().absolute()
    if not hasattr(os, "geteuid"):  # Windows: no POSIX owners and modes to check
        folder.mkdir(parents=True, exist_ok=True)
        return folder
    if not folder.exists():
        folder.mkdir(parents=True, exist_ok=True)
        folder.chmod(0o700)  # whatever the umask: the folder code is loaded from is private
    folder = folder.resolve()
    if not folder.is_dir():
        raise CacheTrustError(f"the compiled-code cache {folder} is not a folder: {CACHE_FIX}")
    for p in (folder, *folder.parents):
        problem = _distrust(p, p.stat(), ancestor=p != folder)
        if problem:
            where = "the compiled-code cache" if p == folder else f"a folder above the compiled-code cache {folder}"
            raise CacheTrustError(f"{where}: {problem}, so another user could plant a library there "
                                  f"that tapmp would run: {CACHE_FIX}")
    return folder


def check_private_file(path: Path) -> Path:
    """``path``, a library in the private cache folder, if it is a regular file (not a symbolic
    link) of this user that no one else may write; else CacheTrustError naming it."""
    import stat
    if not hasattr(os, "geteuid"):
        return path
    st = os.lstat(path)
    if not stat.S_ISREG(st.st_mode):
        raise CacheTrustError(f"the compiled-code cache: {path} is not a regular file (a symbolic link or other), "
                              f"so it could lead to a library another user planted: delete it, or {CACHE_FIX}")
    problem = _distrust(path, st, ancestor=False)
    if problem:
        raise CacheTrustError(f"the compiled-code cache: {problem}, so it may be a library another user planted; "
                              f"tapmp does not load it: delete it, or {CACHE_FIX}")
    return path


# What tapmp writes into its cache: libraries named <kind>_<hash>.so, a lock file beside each, and
# a library being written (build_cached's temporary name). Anything else there is left alone.
CACHE_PATTERNS = ("tapmp_*.so", ".tapmp_*.lock", ".tapmp_*.*.so")


def clean_cache(sources) -> list[Path]:
    """Remove from the cache folder the libraries and lock files older than the newest of ``sources``
    (the C files they are compiled from): those of earlier sources, other checkouts and
    environments, which tapmp would compile again if it needed them. The folder is checked first
    (:func:`private_folder`: CacheTrustError if another user could write it); only regular files
    and symbolic links matching CACHE_PATTERNS are removed, nothing is followed. Returns the
    removed paths."""
    import stat
    folder = cache_dir()
    if not folder.exists():
        return []
    folder = private_folder(folder)
    newest = max(Path(s).stat().st_mtime for s in sources)
    removed = []
    for pattern in CACHE_PATTERNS:
        for path in sorted(folder.glob(pattern)):
            st = os.lstat(path)
            if st.st_mtime < newest and not stat.S_ISDIR(st.st_mode):
                path.unlink(missing_ok=True)
                removed.append(path)
    return removed


def build_cached(path: Path, compile_into) -> Path:
    """``path`` (a library in the cache), compiled by ``compile_into(tmp_path)`` unless present;
    returns the path to load (in the resolved cache folder).

    Before anything is loaded or built, the cache folder is checked as ssh checks its keys
    (:func:`private_folder`, :func:`check_private_file`): a library another user could have
    written is never returned (CacheTrustError). A file lock beside it makes concurrent builds
    (a study's workers) wait for the first one, and the library appears under its name only once
    complete (written to a temporary file, then renamed). OSError if the folder cannot be
    written; compile_into's errors pass through."""
    path = private_folder(Path(path).parent) / Path(path).name
    if os.path.lexists(path):
        return check_private_file(path)
    from filelock import FileLock
    with FileLock(str(path.parent / f".{path.stem}.lock")):
        if not os.path.lexists(path):
            fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=path.suffix)
            os.close(fd)
            try:
                compile_into(Path(tmp))
                os.chmod(tmp, 0o755)
                os.replace(tmp, path)
            finally:
                Path(tmp).unlink(missing_ok=True)
    return check_private_file(path)


# -- universal (fat) Mach-O ----------------------------------------------------------------

FAT_MAGIC = 0xCAFEBABE
CPU_TYPE = {0x01000007: "x86_64", 0x0100000C: "arm64"}
_CPU = {"x86_64": (0x01000007, 3), "arm64": (0x0100000C, 0)}  # (cputype, cpusubtype ALL)
_ALIGN = 14  # 16 KiB, the page size of arm64 macOS; lipo aligns both slices to it too


def macho_cpu(data: bytes) -> str:
    """"x86_64" or "arm64" of a thin 64-bit Mach-O file (ValueError otherwise)."""
    if len(data) < 8 or struct.unpack_from("<I", data)[0] != 0xFEEDFACF:
        raise ValueError("not a 64-bit little-endian Mach-O file")
    cputype = struct.unpack_from("<I", data, 4)[0]
    if cputype not in CPU_TYPE:
        raise ValueError(f"Mach-O cputype {cputype:#x} is neither x86_64 nor arm64")
    return CPU_TYPE[cputype]


def universal_macho(thin: list[bytes]) -> bytes:
    """A universal ("fat") Mach-O file of the thin 64-bit Mach-O files ``thin``, as lipo
    writes it: big-endian fat header, one fat_arch per slice, slices aligned to 16 KiB."""
    header = struct.pack(">II", FAT_MAGIC, len(thin))
    offset = 1 << _ALIGN
    arch_entries, body = b"", b""
    for data in thin:
        cputype, subtype = _CPU[macho_cpu(data)]
        arch_entries += struct.pack(">IIIII", cputype, subtype, offset, len(data), _ALIGN)
        padded = data + b"\0" * (-len(data) % (1 << _ALIGN))
        body += padded
        offset += len(padded)
    head = header + arch_entries
    return head + b"\0" * ((1 << _ALIGN) - len(head)) + body
