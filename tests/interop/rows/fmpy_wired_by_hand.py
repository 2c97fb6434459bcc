"""The three FMI 2.0 FMUs of an SSP in FMPy's FMU2Slave, connected as its SSD says, with their
defaults (no parameter set), outputs propagated in Initialization Mode, Jacobi steps of 0.1 ms up
to 0.2 s (the host of tests/interop/test_fmu_manipulation_toolbox.py, which compares it with
`tapmp run scenarios/paper_simulation.toml --set ordering='"jacobi"'`); prints the last row. Needs
pytest (the .venv of `bash tests/run.sh`): the host is the test module's.

    .venv/bin/python tests/interop/rows/fmpy_wired_by_hand.py build/native/fmi2/TAPMP.ssp
"""

import argparse
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))  # the repository root: the tests package


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("ssp", type=Path, help="an FMI 2.0 TAPMP.ssp")
    args = p.parse_args(argv)
    if not args.ssp.is_file():
        p.error(f"ssp = {str(args.ssp)!r} is not a file: give the path of an .ssp file")
    from tests.interop.test_fmu_manipulation_toolbox import NAMES, wired_by_hand
    with tempfile.TemporaryDirectory() as folder:
        rows = wired_by_hand(args.ssp, Path(folder), "propagated")
    print(dict(zip(NAMES, rows[-1].tolist())))
    return 0


if __name__ == "__main__":
    sys.exit(main())
