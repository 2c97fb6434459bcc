#!/usr/bin/env bash
# Build every FMU family and its SSP; every FMU must pass `fmpy validate`.
#  - build/: TAPMP_Plant.fmu, TAPMP_Controller.fmu, TAPMP_Trajectory.fmu (pythonfmu), TAPMP.ssp
#    and the closed-loop container TAPMP_ClosedLoop.fmu;
#  - build/native/fmi2/ and build/native/fmi3/: the self-contained native FMUs (C sources
#    inside, binaries for Linux, Windows and macOS on x86-64 and ARM) and a TAPMP.ssp each; fmi3 also
#    the clocked controller TAPMP_ControllerClocked.fmu and its loop TAPMP_Clocked.ssp.
# Every binary is compiled by zig cc from PyPI's ziglang package (installed with the package):
# no gcc, no mingw-w64. The one thing pip cannot provide is Python's C headers (Python.h, for
# the pythonfmu family's binary): if this Python has none, Debian's python3-dev is installed
# with apt-get (as root, or through sudo), else the script stops with one line naming it.
# Usage: bash build_fmus.sh [--host] [OUT_DIR]   (default: build/, relative to the repository root).
#  --host: the native FMUs with this machine's x86_64-linux binaries (and their C sources) only,
#  the quick start's choice: seconds on a new machine, where every platform takes minutes the
#  first time (Zig builds each target's C runtime once, the two Windows ones longest).
# Needs the package installed (pip install -e .); uses .venv/bin/python if present, else python3.
set -euo pipefail
cd "$(dirname "$0")"
PY=${PYTHON:-python3}
[ -x .venv/bin/python ] && PY=.venv/bin/python
platforms=(--all-platforms)
if [ "${1:-}" = "--host" ]; then
    platforms=(--platform x86_64-linux)
    shift
fi
OUT=${1:-build}

headers=$("$PY" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')
if [ ! -f "$headers/Python.h" ]; then
    if [ "$(id -u)" -eq 0 ]; then
        as_root=()
    elif command -v sudo >/dev/null 2>&1; then
        as_root=(sudo)
    else
        echo "build_fmus.sh: Python's C headers ($headers/Python.h) are missing and this user is not root and has no sudo: install Debian's python3-dev as root (apt-get install python3-dev) and run this again" >&2
        exit 1
    fi
    "${as_root[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y python3-dev \
        || { "${as_root[@]}" apt-get update && "${as_root[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y python3-dev; }
fi

"$PY" -m orchestrator build --out "$OUT" "${platforms[@]}"
echo "fmpy validate: every FMU"
# `fmpy validate` of every FMU, in one process (fmpy's validate_fmu is what the command runs)
"$PY" - "$OUT"/TAPMP_*.fmu "$OUT"/native/fmi2/TAPMP_*.fmu "$OUT"/native/fmi3/TAPMP_*.fmu <<'PYTHON'
import sys
from fmpy.validation import validate_fmu
failed = False
for fmu in sys.argv[1:]:
    problems = validate_fmu(fmu)
    print(f"fmpy validate: {fmu}: {'failed' if problems else 'ok'}", flush=True)  # a line per FMU: seconds each
    if problems:
        failed = True
        print(f"fmpy validate failed for {fmu}:", *problems, sep="\n  ", file=sys.stderr)
sys.exit(1 if failed else 0)
PYTHON
echo "FMUs and SSPs in $(cd "$OUT" && pwd) (pythonfmu) and $(cd "$OUT/native" && pwd) (native fmi2, fmi3)"
