"""FMPy's results of every model of a Cross-Check tree (`tapmp build --cross-check --out TREE`),
written as a Cross-Check result (TREE/results/2.0/cs/<platform>/FMPy/<version>/tapmp/<version>/<model>/
with passed and <model>_out.csv) and validated by FMPy's validator of vendor repositories; prints
the validator's count (models, results, problems) and exits 1 on a problem. As
tests/interop/test_cross_check.py runs it: each FMU on its _in.csv, the _ref.csv's columns as outputs.

    .venv/bin/python tests/interop/rows/fmpy_cross_check.py results/cross-check
"""

import argparse
import sys
from pathlib import Path

import fmpy
from fmpy.cross_check.validate_vendor_repo import validate_repo
from fmpy.util import read_csv


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("tree", type=Path, help="the folder `tapmp build --cross-check --out` wrote")
    args = p.parse_args(argv)
    models = sorted(d for d in (args.tree / "fmus").glob("2.0/cs/*/tapmp/*/*") if d.is_dir())
    if not models:
        p.error(f"tree = {str(args.tree)!r} holds no fmus/2.0/cs/<platform>/tapmp/<version>/<model>/ folder: "
                "give the folder `tapmp build --cross-check --out` wrote")
    for folder in models:
        model, platform, version = folder.name, folder.parts[-4], folder.parts[-2]
        ref = read_csv(str(folder / f"{model}_ref.csv"))
        inputs = read_csv(str(folder / f"{model}_in.csv")) if (folder / f"{model}_in.csv").exists() else None
        result = fmpy.simulate_fmu(str(folder / f"{model}.fmu"), stop_time=0.01, step_size=1e-4,
                                   output_interval=1e-4, input=inputs, output=list(ref.dtype.names[1:]))
        target = args.tree / "results" / "2.0" / "cs" / platform / "FMPy" / fmpy.__version__ / "tapmp" / version / model
        target.mkdir(parents=True, exist_ok=True)
        (target / "passed").touch()
        lines = [",".join(f'"{n}"' for n in result.dtype.names)]
        lines += [",".join(repr(float(x)) for x in row) for row in result]
        (target / f"{model}_out.csv").write_text("\n".join(lines) + "\n")
    counts = validate_repo(str(args.tree))
    print(counts)
    return 1 if counts[2] else 0


if __name__ == "__main__":
    sys.exit(main())
