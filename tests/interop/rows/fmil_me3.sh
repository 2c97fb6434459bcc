#!/usr/bin/env bash
# Compile tests/interop/fmil_me3.c against ../shared/tools/fmil (the FMI Library 3.0.4) and run it on
# an FMI 3.0 plant: FMIL loads it for Model Exchange, the host integrates it with RK4 at 0.1 ms for
# 0.2 s and writes OUT/me.csv (t and the six states).
#   bash tests/interop/rows/fmil_me3.sh build/native/fmi3/TAPMP_Plant.fmu results/fmil_me3
set -euo pipefail
fmu=${1:?usage: fmil_me3.sh FMU OUT}
out=${2:?usage: fmil_me3.sh FMU OUT}
fmil=$(cd ../shared/tools/fmil && pwd)
mkdir -p "$out/unpack"
out=$(cd "$out" && pwd)  # absolute: FMIL loads the unpacked binary by this path
fmu=$(realpath "$fmu")
fmi_headers=$(.venv/bin/python -c 'import fmpy, pathlib; print(pathlib.Path(fmpy.__file__).parent / "c-code")')
${CC:-gcc} -O2 -I"$fmi_headers" -I"$fmil/include" -o "$out/fmil_me3" tests/interop/fmil_me3.c \
    -L"$fmil/lib" -lfmilib_shared -Wl,-rpath,"$fmil/lib" -lm
"$out/fmil_me3" "$fmu" "$out/unpack" "$out/me.csv" 0.2 0.0001
