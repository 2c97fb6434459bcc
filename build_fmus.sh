#!/usr/bin/env bash
# Build TAPMP_Plant.fmu, TAPMP_Controller.fmu, TAPMP_Trajectory.fmu, TAPMP.ssp and the
# closed-loop container TAPMP_ClosedLoop.fmu; every FMU must pass `fmpy validate`.
# Usage: bash build_fmus.sh [OUT_DIR]   (default: build/). Needs the package installed
# (pip install -e .); uses .venv/bin/python if present, else python3.
set -euo pipefail
cd "$(dirname "$0")"
PY=${PYTHON:-python3}
[ -x .venv/bin/python ] && PY=.venv/bin/python
OUT=${1:-build}
"$PY" -m orchestrator build --out "$OUT"
for fmu in "$OUT"/TAPMP_*.fmu; do
    "$PY" -m fmpy.cli validate "$fmu" >/dev/null || { echo "fmpy validate failed for $fmu" >&2; "$PY" -m fmpy.cli validate "$fmu"; exit 1; }
done
echo "FMUs and SSP in $(cd "$OUT" && pwd)"
