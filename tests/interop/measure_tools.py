"""Measure how far OMSimulator, fmusim and FMIL's fmil_check are from `tapmp run` and fmpy.

    .venv/bin/python tests/interop/measure_tools.py

Needs the built FMUs (bash build_fmus.sh) and ../shared/tools. Prints:

* OMSimulator on the paper scenario exported from each family's TAPMP.ssp (first 0.2 s), run
  as tests/interop/test_omsimulator.py runs it: the largest difference on the true motor positions [m],
  the encoder positions [m] and the commands [N] against the orchestrator (the engine of
  `tapmp run`) on OMSimulator's conventions (Jacobi, accumulated clock) and with `tapmp run`'s
  defaults (Gauss-Seidel, exact clock), and FMI 3.0 against FMI 2.0;
* each native FMU alone in OMSimulator, fmusim and fmil_check against fmpy's simulate_fmu: the
  largest difference of any output relative to that output's largest magnitude.
"""

import contextlib
import io
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent.parent)]  # the repository root: the tests package
from tests.support.runs import COMMANDS, MOTOR_POSITIONS, PAPER, orchestrator_rows, paper_scenario  # noqa: E402
from tests.support.shared import ROOT, SHARED  # noqa: E402
from fmpy import simulate_fmu  # noqa: E402
from tests.interop.measure_export import fmt, gaps  # noqa: E402
from tests.interop.test_fmusim import FMUSIM, START  # noqa: E402
from tests.interop.test_omsimulator import (FIXED_POINT, OMS, at_communication_points, read_mat,  # noqa: E402
                                            runnable)

from orchestrator.cli import main as tapmp  # noqa: E402
from tapmp.interface import FMU_NAMES  # noqa: E402

NAMES = MOTOR_POSITIONS + COMMANDS
SSPS = {"python": ROOT / "build" / "TAPMP.ssp", "fmi2": ROOT / "build" / "native" / "fmi2" / "TAPMP.ssp",
        "fmi3": ROOT / "build" / "native" / "fmi3" / "TAPMP.ssp"}


def relative(rows: np.ndarray, ref: np.ndarray) -> float:
    """Largest |difference| of any column relative to that column's largest |value|."""
    scale = np.abs(ref).max(axis=0)
    d = np.abs(rows - ref).max(axis=0)
    return float(max((d / s if s > 0 else d) for d, s in zip(d, scale)))


def run(args, cwd):
    proc = subprocess.run([str(a) for a in args], cwd=cwd, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc.stdout


def main() -> int:
    with tempfile.TemporaryDirectory(prefix="tapmp_measure_tools_") as tmp:
        tmp = Path(tmp)
        (tmp / "oms").mkdir()
        oms = runnable(SHARED / OMS, tmp / "oms")
        scenario = paper_scenario()
        finals = {}
        print("OMSimulator on the exported paper scenario, 0.2 s: true positions [m] / encoder [m] / commands [N]")
        for family, ssp in SSPS.items():
            out = tmp / f"{family}.ssp"
            with contextlib.redirect_stdout(io.StringIO()):
                assert tapmp(["export", str(PAPER), "--ssp", str(ssp), "--out", str(out), "--set", "stop_time=0.2"]) == 0
            folder = tmp / family
            folder.mkdir()
            run([oms, *(FIXED_POINT if family == "fmi3" else []), "--stopTime=0.2", "--resultFile=r.mat", out], folder)
            _, rows, _ = at_communication_points(read_mat(folder / "r.mat"), NAMES, "TAPMP.TAPMP.")
            finals[family] = rows
            own = orchestrator_rows(out, scenario, NAMES, "jacobi", clock="accumulated")
            default = orchestrator_rows(out, scenario, NAMES, "gauss-seidel")
            print(f"  {family:6s} vs orchestrator (jacobi, accumulated clock): {fmt(gaps(rows, own, NAMES))}; "
                  f"vs `tapmp run` defaults: {fmt(gaps(rows, default, NAMES))}")
        print(f"  fmi3 vs fmi2: {fmt(gaps(finals['fmi3'], finals['fmi2'], NAMES))}")
        print("Each native FMU alone, 0.2 s at 1e-4 s, largest difference relative to the output's magnitude, "
              "against fmpy simulate_fmu")
        for version in ("fmi2", "fmi3"):
            for model in FMU_NAMES:
                fmu = ROOT / "build" / "native" / version / f"{model}.fmu"
                folder = tmp / f"{version}_{model}"
                folder.mkdir()
                ref = simulate_fmu(str(fmu), stop_time=0.2, output_interval=1e-4)
                outputs = [n for n in ref.dtype.names if n != "time"]
                expected = np.array([ref[n] for n in outputs]).T
                run([oms, "--tempDir=.", "--resultFile=a.mat", "--mode=cs", "--stopTime=0.2", "--stepSize=1e-4", fmu],
                    folder)
                _, rows, _ = at_communication_points(read_mat(folder / "a.mat"), outputs, "")
                om = relative(rows, expected)
                start = START.get(model, {})
                args = [SHARED / FMUSIM, "--interface-type", "cs", "--stop-time", "0.2", "--output-interval", "0.0001",
                        "--output-file", "s.csv"]
                for name, value in start.items():
                    args += ["--start-value", name, repr(value)]
                run([*args, fmu], folder)
                sim = np.genfromtxt(folder / "s.csv", delimiter=",", names=True)
                ref_s = simulate_fmu(str(fmu), stop_time=0.2, output_interval=1e-4, start_values=start)
                fs = relative(np.array([sim[n] for n in outputs]).T, np.array([ref_s[n] for n in outputs]).T)
                run([SHARED / "tools" / "fmil" / "fmil_check", "alone", fmu, "f.csv", "0.2", "0.0001"], folder)
                fil = np.genfromtxt(folder / "f.csv", delimiter=",", names=True)
                fl = relative(np.array([fil[n] for n in outputs]).T, expected)
                print(f"  {version} {model:17s} OMSimulator {om:.2g}, fmusim {fs:.2g}, fmil_check {fl:.2g}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
