"""Compiling C in the tests: one place that picks the compiler, as
orchestrator/builder/build_native.py does ($CC, else gcc), so the tests can be switched to
another toolchain in one place."""

import os
import subprocess
from pathlib import Path

from orchestrator.builder.build_native import fmi_headers_dir

SANITIZE = ["-fsanitize=address,undefined", "-fno-sanitize-recover=all", "-fno-omit-frame-pointer", "-g"]
# Sanitizer options of every sanitized run: leaks are findings, so is any UBSan report.
SANITIZER_ENV = {"ASAN_OPTIONS": "detect_leaks=1:abort_on_error=0:exitcode=86",
                 "UBSAN_OPTIONS": "print_stacktrace=1:halt_on_error=1:exitcode=87"}


def c_compiler(kind: str = "cc") -> str:
    """The C compiler: ``kind`` "cc" is the one build_native.py uses ($CC, else gcc);
    "clang" is clang (libFuzzer and the clang warning check need it)."""
    if kind == "clang":
        return os.environ.get("TAPMP_CLANG", "clang")
    return os.environ.get("CC", "gcc")


def compile_c(args: list, kind: str = "cc", headers: Path | None = None) -> subprocess.CompletedProcess:
    """Run the compiler ``kind`` with ``args`` and -I for the FMI headers (``headers``, else
    FMPy's, which build_native.py uses); the CompletedProcess with its stderr, never raising."""
    cmd = [c_compiler(kind), f"-I{headers or fmi_headers_dir()}", *map(str, args)]
    return subprocess.run(cmd, capture_output=True, text=True)


def extract_sources(fmu: Path, dest: Path) -> Path:
    """sources/ of ``fmu`` alone into ``dest``; returns the sources folder."""
    import zipfile
    with zipfile.ZipFile(fmu) as z:
        for name in z.namelist():
            if name.startswith("sources/"):
                z.extract(name, dest)
    return dest / "sources"
