"""The C model (tapmp/c/tapmp_model.c) loaded into Python: the one implementation of the equations.

The plant's right-hand side and RK4 step, the control laws and the reference trajectory are
computed by the C functions of ``tapmp_model.c`` in every FMU family and in the FMI-free
loop (tapmp.closed_loop), so they cannot drift apart. :func:`load` gives cffi's ``ffi``
and the library ``lib`` (ABI mode: no compiler needed to load it). The declarations come
from ``tapmp_model.h`` itself (:func:`cdef_text`), so nothing is mirrored by hand.

The library is, in this order:
* bundled next to the sources (``tapmp/c/tapmp_model-<hash>.so``, written into the
  pythonfmu FMUs' resources at build time): an FMU never compiles at run time;
* compiled on first use by the project's toolchain (tapmp.toolchain: zig cc, or $CC) into
  the cache folder ``$TAPMP_CACHE``, else ``$XDG_CACHE_HOME/tapmp``, else ``~/.cache/tapmp``,
  under a file lock so that concurrent processes (a study's workers) build it once. The cache
  folder and the library must belong to this user and be writable by no one else
  (tapmp.toolchain.build_cached), else CacheTrustError and nothing is loaded.
Both names carry a hash of the C sources, so an edited model is never run from a stale library.
"""

import hashlib
import re
from pathlib import Path

C_DIR = Path(__file__).resolve().with_name("c")
SOURCE = C_DIR / "tapmp_model.c"
HEADER = C_DIR / "tapmp_model.h"


class NativeModelError(RuntimeError):
    """The C model cannot be built or loaded; the message says why in one line."""


def cdef_text(header: str) -> str:
    """The declarations of ``header`` (tapmp_model.h's text) as cffi's cdef takes them: without
    comments, preprocessor lines and the TAPMP_LINKAGE macro."""
    text = re.sub(r"/\*.*?\*/", " ", header, flags=re.S)
    lines = [line for line in text.splitlines() if not line.lstrip().startswith("#")]
    return re.sub(r"\bTAPMP_LINKAGE\b", "", "\n".join(lines))


def header_number(name: str) -> float:
    """The value of ``#define NAME NUMBER`` in tapmp_model.h (a constant cffi's ABI mode cannot read)."""
    m = re.search(rf"^#define {re.escape(name)} (\S+)", HEADER.read_text(), flags=re.M)
    if m is None:
        raise NativeModelError(f"{HEADER} defines no {name}")
    return float(m.group(1))


def source_hash() -> str:
    """16 hex digits of the SHA-256 of tapmp_model.c and tapmp_model.h."""
    return hashlib.sha256(SOURCE.read_bytes() + b"\0" + HEADER.read_bytes()).hexdigest()[:16]


def bundled_name() -> str:
    """File name of the prebuilt x86_64 Linux library of these sources (in tapmp/c/)."""
    return f"tapmp_model-{source_hash()}.so"


def compile_library(output: Path) -> Path:
    """Compile tapmp_model.c into the shared library ``output`` with the native FMUs' flags
    (tapmp.toolchain.CFLAGS) but exported symbols; NativeModelError if the compiler fails."""
    from .toolchain import CFLAGS, ToolchainError, compile_c
    # -fvisibility=hidden keeps an FMU's model functions private; here Python must call them
    flags = [f for f in CFLAGS if not f.startswith("-fvisibility")]
    try:
        return compile_c([SOURCE], output, flags=flags, includes=[C_DIR], libs=["m"], what="the C model")
    except ToolchainError as err:
        raise NativeModelError(str(err)) from None


def cached_library_path() -> Path:
    """Where the cache keeps the library of these sources for the current compiler and flags."""
    from .toolchain import CFLAGS, cache_dir, compiler
    key = hashlib.sha256(f"{source_hash()}\0{' '.join(compiler())}\0{' '.join(CFLAGS)}".encode()).hexdigest()
    return cache_dir() / f"tapmp_model_{key[:16]}.so"


def _cached_library() -> Path:
    """The library in the cache folder, compiled there (under a file lock) unless present."""
    path = cached_library_path()
    try:
        from .toolchain import build_cached
        return build_cached(path, compile_library)
    except OSError as err:
        raise NativeModelError(f"cannot write the compiled C model into {path.parent}: "
                               f"{err.strerror or err} (set TAPMP_CACHE to a writable folder)") from None


def library_path() -> Path:
    """The bundled library of these sources if present, else the cache's (built if needed)."""
    bundled = C_DIR / bundled_name()
    return bundled if bundled.is_file() else _cached_library()


_LOADED = None


def load():
    """(ffi, lib): cffi's FFI with tapmp_model.h's declarations and the loaded C model."""
    global _LOADED
    if _LOADED is None:
        from cffi import FFI
        ffi = FFI()
        ffi.cdef(cdef_text(HEADER.read_text()))
        path = library_path()
        try:
            lib = ffi.dlopen(str(path))
            for name in dir(lib):  # every declared function, now: a stale or foreign file fails here
                getattr(lib, name)
        except (OSError, AttributeError) as err:
            raise NativeModelError(f"cannot load the compiled C model {path}: {' '.join(str(err).split())} "
                                   "(delete the file so that it is compiled again)") from None
        _LOADED = ffi, lib
    return _LOADED


def require_in_ranges(check: str, *args, values: dict) -> None:
    """Run the C model's range check ``check`` (tapmp_params_check, tapmp_plant_config_check, ...)
    on ``args``; ModelInputError for the first offender it reports (KinematicDomainError for a
    value outside the kinematic domain), with its value as given in ``values`` (name -> value,
    so that the message shows it as the caller wrote it)."""
    from .errors import KinematicDomainError, ModelInputError
    ffi, lib = load()
    name, value, allowed = ffi.new("const char **"), ffi.new("double *"), ffi.new("const char **")
    kind = getattr(lib, check)(*args, name, value, allowed)
    if kind:
        field = ffi.string(name[0]).decode()
        error = KinematicDomainError if kind == 3 else ModelInputError
        raise error(field, values[field], ffi.string(allowed[0]).decode())
