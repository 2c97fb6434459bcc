"""Run an SSP in Ecos's `ecos` executable (C++, no Python in the process), shipped in the ecospy
wheel without the executable bit: copied executable into OUT, started there, it writes its CSV
(named after the SSP, 6 decimals) into OUT.

    .venv/bin/python tests/interop/rows/ecos_simulate.py results/export/paper.ssp --stop-time 0.2 \
        --parameter-set paper_simulation --out results/export/ecos
"""

import argparse
import os
import shutil
import subprocess
import sys
from pathlib import Path


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("ssp", type=Path, help="the SSP file")
    p.add_argument("--stop-time", type=float, default=0.2, help="s")
    p.add_argument("--step-size", type=float, default=1e-4, help="s")
    p.add_argument("--parameter-set", help="the SSP's parameter set to apply (Ecos applies none unless named)")
    p.add_argument("--out", type=Path, default=Path("results/ecos"), help="the folder of the CSV")
    args = p.parse_args(argv)
    if not args.ssp.is_file():
        p.error(f"ssp = {str(args.ssp)!r} is not a file: give the path of an .ssp file")
    import ecospy
    binaries = Path(ecospy.__file__).parent / "binaries"
    args.out.mkdir(parents=True, exist_ok=True)
    ecos = args.out / "ecos"
    shutil.copyfile(binaries / "ecos", ecos)
    ecos.chmod(0o755)
    command = [str(ecos.resolve()), "simulate", "--path", str(args.ssp.resolve()), "--stepSize", repr(args.step_size),
               "--stopTime", repr(args.stop_time), "--noParallel", "--logLevel", "warn"]
    if args.parameter_set:
        command += ["--parameterSet", args.parameter_set]
    env = {**os.environ, "LD_LIBRARY_PATH": str(binaries)}
    return subprocess.run(command, cwd=args.out, env=env).returncode


if __name__ == "__main__":
    sys.exit(main())
