"""The FMI runtime under the sanitizers, beyond the call sequences of test_fmu_memory.py:

* ThreadSanitizer: a C host (c_host/threads_host.c) runs two threads, each with instances of its
  own of one native FMU (FMI 2.0 and 3.0), creating and freeing instances and states all the
  time; the runtime's registry of live instances, which both change and read, reports no race.
* AddressSanitizer: uri_to_path (fmu_common/pyfront/uri.h, the pythonfmu FMUs'
  fmuResourceLocation) refuses a '%' without two hex digits after it, at the end and in the
  middle, and never reads past the terminating zero (c_host/uri_host.c).
"""

import os
import subprocess
from pathlib import Path

import pytest

from tests.support.ctools import SANITIZE, SANITIZER_ENV, compile_c, extract_sources
from tapmp.interface import FMU_NAMES

pytestmark = pytest.mark.slow  # sanitizer builds and child processes

ROOT = Path(__file__).resolve().parents[2]
C_HOST = ROOT / "tests" / "fmu" / "c_host"
PYFRONT_DIR = ROOT / "fmu_common" / "pyfront"
TSAN_EXIT = 66  # ThreadSanitizer's exit code after a report
ENV = {"PATH": os.environ["PATH"], **SANITIZER_ENV, "TSAN_OPTIONS": f"halt_on_error=0:exitcode={TSAN_EXIT}"}


@pytest.mark.parametrize("model", FMU_NAMES)
@pytest.mark.parametrize("family", ("fmi2", "fmi3"))
def test_two_threads_with_their_own_instances_run_clean_under_threadsanitizer(native_built, family, model,
                                                                              tmp_path):
    src = extract_sources(native_built[family][model], tmp_path)
    exe = tmp_path / "threads_host"
    proc = compile_c(["-std=c99", "-g", "-O1", "-fsanitize=thread", f"-I{src}", "-o", exe,
                      C_HOST / "threads_host.c", "-lm", "-lpthread"], kind="clang")
    assert proc.returncode == 0, proc.stderr
    run = subprocess.run([str(exe)], capture_output=True, text=True, timeout=300, env=ENV)
    assert "ThreadSanitizer" not in run.stderr, run.stderr[-6000:]
    assert run.returncode == 0 and run.stdout.strip() == "threads_host: all calls OK", run.stdout + run.stderr[-4000:]


URIS = {
    "file:///tmp/a%4": "refused",           # '%' and one hex digit at the end: read past the zero before
    "file:///tmp/a%": "refused",            # '%' at the end
    "file:///tmp/%G1": "refused",           # not a hex digit
    "file:///tmp/a%4xyz": "refused",        # one hex digit mid-string: swallowed the 'x' before
    "file:///tmp/a%00b": "refused",         # a zero byte cannot be part of a path
    "file:///tmp/a%20b%2F": "/tmp/a b/",
    "file://localhost/tmp/x": "/tmp/x",
    "file://host/x": "refused",             # another machine's file: was the relative path host/x
    "file://localhostx/y": "refused",       # not localhost either
    "file://localhost": "refused",          # this machine, but no path
    "file:/tmp/%c3%a9": "/tmp/\u00e9",
    "file:///" + "a" * 80: "refused",       # longer than the path buffer: refused, not cut
}


def test_uri_to_path_refuses_short_escapes_and_never_reads_past_the_end(tmp_path):
    exe = tmp_path / "uri_host"
    proc = compile_c(["-std=c99", "-Wall", "-Wextra", *SANITIZE, f"-I{PYFRONT_DIR}", "-o", exe,
                      C_HOST / "uri_host.c"])
    assert proc.returncode == 0, proc.stderr
    run = subprocess.run([str(exe), *URIS], capture_output=True, text=True, timeout=60, env=ENV)
    assert run.returncode == 0 and "Sanitizer" not in run.stderr, run.stderr
    assert run.stdout.splitlines() == [f"{uri} -> {path}" for uri, path in URIS.items()]


@pytest.mark.parametrize("kind", ["short_escape", "other_host"])
def test_a_malformed_resource_location_is_refused_at_instantiation_with_a_message(built, tmp_path, kind):
    """The pythonfmu FMU's binary itself, given fmuResourceLocation = 'file:///...%4' or a URI of the
    resources folder on another host, 'file://host/...'."""
    import ctypes

    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE
    from fmpy.logging import addLoggerProxy
    path = built["TAPMP_Plant"]
    md = read_model_description(str(path))
    slave = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(path), unzipdir=str(tmp_path / "u")),
                      modelIdentifier=md.coSimulation.modelIdentifier, instanceName="uri")
    messages = []
    callbacks = fmi2CallbackFunctions()
    callbacks.logger = fmi2CallbackLoggerTYPE(lambda env, inst, status, cat, msg: messages.append(msg.decode()))
    addLoggerProxy(ctypes.byref(callbacks))
    location = (tmp_path / "u" / "resources").as_uri()
    location = location + "%4" if kind == "short_escape" else location.replace("file://", "file://host", 1)
    component = slave.fmi2Instantiate(b"uri", 1, md.guid.encode(), location.encode(), ctypes.byref(callbacks),
                                      0, 0)
    assert not component
    assert any(f"fmuResourceLocation = '{location}' is invalid: allowed is a file:// URI of the FMU's resources "
               "folder on this machine (file:///path or file://localhost/path; each % followed by two hex digits, "
               "not %00)" in m for m in messages), messages
