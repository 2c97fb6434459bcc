"""The C model (tapmp/c/tapmp_model.c) loaded into Python: the one implementation of the equations.

The plant's right-hand side and RK4 step, the control laws and the reference trajectory are
computed by the C functions of ``tapmp_model.c`` in every FMU family and in the FMI-free
loop (tapmp.closed_loop), so they cannot drift apart. :func:`load` gives cffi's ``ffi``
and the library ``lib`` (ABI mode: no compiler needed to load it). The declarations come
from ``tapmp_model.h`` itself (:func:`cdef_text`), so nothing is mirrored by hand.

The library is, in this order:
* bundled next to the sources (``tapmp/c/tapmp_model-<hash>.so``, written into the
  pythonfmu FMUs' resources at build time): an FMU never compiles at run time;
* compiled on first use by the project's toolchain (ctoolchain: zig cc, or $CC) into
  the cache folder ``$TAPMP_CACHE``, else ``$XDG_CACHE_HOME/tapmp``, else ``~/.cache/tapmp``,
  under a file lock so that concurrent processes (a study's workers) build it once. The cache
  folder and the library must belong to this user and be writable by no one else
  (ctoolchain.build_cached), else CacheTrustError and nothing is loaded.
Both names carry a hash of the C sources, so an edited model is never run from a stale library.

The range checks of the settings are generated C too (``tapmp_settings.h``, from the settings
table tapmp.interface), written beside the sources when the library is compiled and part of the
hash; :func:`settings` fills a model's settings struct by field name from that table and
:func:`check_settings` runs its check, so Python refuses what every FMU family refuses, alike.
"""

import hashlib
import re
import tempfile
from pathlib import Path

from .errors import UserError

C_DIR = Path(__file__).resolve().with_name("c")
SOURCE = C_DIR / "tapmp_model.c"
HEADER = C_DIR / "tapmp_model.h"
# the FMI-free closed loop stepped in C (tapmp.closed_loop.run): part of the library, not of the FMUs
LOOP_SOURCE = C_DIR / "tapmp_loop.c"
LOOP_HEADER = C_DIR / "tapmp_loop.h"
# the effort metric's high-pass filter (orchestrator.tool.highpass): part of the library, not of the FMUs
FILTER_SOURCE = C_DIR / "tapmp_filter.c"
FILTER_HEADER = C_DIR / "tapmp_filter.h"


class CModelError(RuntimeError, UserError):
    """The C model cannot be built or loaded; the message says why in one line."""


def cdef_text(header: str) -> str:
    """The declarations of ``header`` (tapmp_model.h's text) as cffi's cdef takes them: without
    comments, preprocessor lines and the TAPMP_LINKAGE macro."""
    text = re.sub(r"/\*.*?\*/", " ", header, flags=re.S)
    lines = [line for line in text.splitlines() if not line.lstrip().startswith("#")]
    return re.sub(r"\bTAPMP_LINKAGE\b", "", "\n".join(lines))


def header_number(name: str, header: Path = HEADER) -> float:
    """The value of ``#define NAME NUMBER`` in ``header`` (tapmp_model.h unless given; a constant
    cffi's ABI mode cannot read)."""
    m = re.search(rf"^#define {re.escape(name)} (\S+)", header.read_text(), flags=re.M)
    if m is None:
        raise CModelError(f"{header} defines no {name}")
    return float(m.group(1))


SETTINGS_HEADER = "tapmp_settings.h"  # the generated range checks that tapmp_model.c includes


def settings_header() -> str:
    """The text of the generated tapmp_settings.h (tapmp.interface.settings_check_source)."""
    from .interface import settings_check_source
    return settings_check_source()


def source_hash() -> str:
    """16 hex digits of the SHA-256 of tapmp_model.c, tapmp_model.h, the generated tapmp_settings.h,
    the closed loop tapmp_loop.c, tapmp_loop.h and the filter tapmp_filter.c, tapmp_filter.h."""
    data = b"\0".join((SOURCE.read_bytes(), HEADER.read_bytes(), settings_header().encode(),
                       LOOP_SOURCE.read_bytes(), LOOP_HEADER.read_bytes(),
                       FILTER_SOURCE.read_bytes(), FILTER_HEADER.read_bytes()))
    return hashlib.sha256(data).hexdigest()[:16]


def bundled_name() -> str:
    """File name of the prebuilt x86_64 Linux library of these sources (in tapmp/c/)."""
    return f"tapmp_model-{source_hash()}.so"


def compile_library(output: Path) -> Path:
    """Compile tapmp_model.c, tapmp_loop.c and tapmp_filter.c into the shared library ``output`` with the native FMUs' flags
    (ctoolchain.CFLAGS) but exported symbols; CModelError if the compiler fails."""
    from ctoolchain import CFLAGS, ToolchainError, compile_c
    # -fvisibility=hidden keeps an FMU's model functions private; here Python must call them
    flags = [f for f in CFLAGS if not f.startswith("-fvisibility")]
    with tempfile.TemporaryDirectory(prefix="tapmp_settings_") as generated:
        Path(generated, SETTINGS_HEADER).write_text(settings_header())
        try:
            return compile_c([SOURCE, LOOP_SOURCE, FILTER_SOURCE], output, flags=flags, includes=[C_DIR, Path(generated)], libs=["m"],
                             what="the C model")
        except ToolchainError as err:
            raise CModelError(str(err)) from None


def cached_library_path() -> Path:
    """Where the cache keeps the library of these sources for the current compiler and flags."""
    from ctoolchain import CFLAGS, cache_dir, compiler
    key = hashlib.sha256(f"{source_hash()}\0{' '.join(compiler())}\0{' '.join(CFLAGS)}".encode()).hexdigest()
    return cache_dir() / f"tapmp_model_{key[:16]}.so"


def _cached_library() -> Path:
    """The library in the cache folder, compiled there (under a file lock) unless present."""
    path = cached_library_path()
    try:
        from ctoolchain import build_cached
        return build_cached(path, compile_library)
    except OSError as err:
        raise CModelError(f"cannot write the compiled C model into {path.parent}: "
                               f"{err.strerror or err} (set TAPMP_CACHE to a writable folder)") from None


def library_path() -> Path:
    """The bundled library of these sources if present, else the cache's (built if needed)."""
    bundled = C_DIR / bundled_name()
    return bundled if bundled.is_file() else _cached_library()


_LOADED = None


def load():
    """(ffi, lib): cffi's FFI with the declarations of tapmp_model.h, tapmp_loop.h and
    tapmp_filter.h and the loaded C model."""
    global _LOADED
    if _LOADED is None:
        from cffi import FFI
        ffi = FFI()
        ffi.cdef(cdef_text(HEADER.read_text()))
        ffi.cdef(cdef_text(LOOP_HEADER.read_text()))
        ffi.cdef(cdef_text(FILTER_HEADER.read_text()))
        path = library_path()
        try:
            lib = ffi.dlopen(str(path))
            for name in dir(lib):  # every declared function, now: a stale or foreign file fails here
                getattr(lib, name)
        except (OSError, AttributeError) as err:
            raise CModelError(f"cannot load the compiled C model {path}: {' '.join(str(err).split())} "
                                   "(delete the file so that it is compiled again)") from None
        _LOADED = ffi, lib
    return _LOADED


def settings(model: str, values: dict):
    """A new cffi struct of ``model``'s settings (tapmp.interface.SETTINGS_STRUCT), every member
    filled by field name from the settings table: the value of its parameter in ``values`` (name
    -> value), else the parameter's start value. An Integer setting that is not an int in its
    range goes in as min - 1, which the range check refuses by name."""
    from .interface import SETTINGS_STRUCT, VARIABLES
    ffi = load()[0]
    s = ffi.new(f"{SETTINGS_STRUCT[model]} *")
    for v in VARIABLES[model]:
        if v.causality != "parameter":
            continue
        x = values.get(v.name, v.start)
        if v.type == "Integer":
            x = x if isinstance(x, int) and v.min <= x <= v.max else int(v.min) - 1
        else:
            x = float(x)
        *path, last = re.split(r"[.\[]", v.field.replace("]", ""))
        target = s
        for member in path:
            target = target[int(member)] if member.isdigit() else getattr(target, member)
        if last.isdigit():
            target[int(last)] = x
        else:
            setattr(target, last, x)
    return s


def check_settings(model: str, values: dict):
    """``model``'s settings struct filled from ``values`` (:func:`settings`) after its range check
    (tapmp_<model>_settings_check): ModelInputError for the first setting outside its range, as
    every FMU family refuses it."""
    from .interface import SETTINGS_STRUCT, VARIABLES
    s = settings(model, values)
    given = {v.name: values.get(v.name, v.start) for v in VARIABLES[model] if v.causality == "parameter"}
    require_in_ranges(f"{SETTINGS_STRUCT[model]}_check", s, values=given)
    return s


def require_in_ranges(check: str, *args, values: dict) -> None:
    """Run the C model's range check ``check`` (tapmp_plant_settings_check, ...)
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
