#!/usr/bin/env bash
# Build every FMU family and its SSP; every FMU must pass `fmpy validate`.
#  - build/: TAPMP_Plant.fmu, TAPMP_Controller.fmu, TAPMP_Trajectory.fmu (pythonfmu), TAPMP.ssp
#    and the closed-loop container TAPMP_ClosedLoop.fmu;
#  - build/native/fmi2/ and build/native/fmi3/: the self-contained native FMUs (C sources
#    inside, Linux and, with mingw-w64 installed, Windows binaries) and a TAPMP.ssp each.
# Usage: bash build_fmus.sh [OUT_DIR]   (default: build/, relative to the repository root).
# Needs the package installed (pip install -e .); uses .venv/bin/python if present, else python3.
set -euo pipefail
cd "$(dirname "$0")"
PY=${PYTHON:-python3}
[ -x .venv/bin/python ] && PY=.venv/bin/python
OUT=${1:-build}
"$PY" -m orchestrator build --out "$OUT"
"$PY" -m orchestrator.engine.build_native --out "$OUT/native"
for fmu in "$OUT"/TAPMP_*.fmu "$OUT"/native/fmi2/TAPMP_*.fmu "$OUT"/native/fmi3/TAPMP_*.fmu; do
    "$PY" -m fmpy.cli validate "$fmu" >/dev/null || { echo "fmpy validate failed for $fmu" >&2; "$PY" -m fmpy.cli validate "$fmu"; exit 1; }
done
echo "FMUs and SSPs in $(cd "$OUT" && pwd) (pythonfmu) and $(cd "$OUT/native" && pwd) (native fmi2, fmi3)"
