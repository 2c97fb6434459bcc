"""FMI Library (FMIL 3.0.4, the importer behind OpenModelica and PyFMI) reads every FMU of every
family without a warning, through ``fmil_check`` (../shared/tools/fmil, a small C program on
FMIL): ``parse`` reports every FMIL log message of level warning or worse and exits non-zero on
any; ``alone`` instantiates an FMU and steps it, recording its outputs at every communication point.
What FMIL reads back of the dependencies: tests/fmu/test_dependencies.py.
"""

import re
import subprocess

import numpy as np
import pytest
from conftest import shared
from fmil_gaps import fmil_counts, fmil_problems
from fmpy import simulate_fmu

from orchestrator.engine.container import CONTAINER
from tapmp.interface import FMU_NAMES

FMIL_CHECK = "tools/fmil/fmil_check"
pytestmark = pytest.mark.needs_shared(FMIL_CHECK)


def every_fmu(built, native_built) -> dict:
    """{label: path} of every FMU: pythonfmu, native FMI 2.0 and 3.0, and the container."""
    fmus = {f"python/{m}": built[m] for m in FMU_NAMES}
    fmus[f"python/{CONTAINER}"] = built[CONTAINER]
    for version in ("fmi2", "fmi3"):
        fmus.update({f"{version}/{m}": native_built[version][m] for m in FMU_NAMES})
    return fmus


def test_fmil_parses_every_fmu_of_every_family_with_no_warning_or_error(built, native_built, tmp_path):
    fmus = every_fmu(built, native_built)
    proc = subprocess.run([str(shared(FMIL_CHECK)), "parse", *map(str, fmus.values())], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)
    log = proc.stdout + proc.stderr  # FMIL's warnings and errors go to stderr
    # nothing but FMIL 3.0.4's gaps in reading the FMI 3.0 terminalsAndIcons.xml (tests/fmu/fmil_gaps.py),
    # which make fmil_check exit 1
    assert fmil_problems(proc.stderr) == [] and fmil_counts(log) == (0, 0), log
    assert proc.returncode == (1 if proc.stderr else 0), log
    reports = proc.stdout.split("\n/")
    assert len(reports) == len(fmus) == 10
    for (label, path), report in zip(fmus.items(), reports):
        assert path.name in report.splitlines()[0], (label, report)
        if not label.startswith("fmi3"):
            assert "FMIL parse: 0 warnings, 0 errors" in report, (label, report)
        version = "3.0" if label.startswith("fmi3") else "2.0"
        assert f"FMI {version}" in report, (label, report)
    # what FMIL read back: the container's 39 outputs, the plant's 15, in both versions
    assert re.search(r"variables \d+, outputs 39, initial unknowns 39", reports[3]), reports[3]
    for label, report in zip(fmus, reports):
        if label.endswith("TAPMP_Plant"):
            assert "outputs 15, initial unknowns 15" in report, (label, report)


@pytest.mark.parametrize("model", FMU_NAMES)
@pytest.mark.parametrize("version", ["fmi2", "fmi3"])
def test_fmil_steps_each_native_fmu_alone_as_fmpy_does(native_built, version, model, tmp_path):
    fmu = native_built[version][model]
    proc = subprocess.run([str(shared(FMIL_CHECK)), "alone", str(fmu), "out.csv", "0.2", "0.0001"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)
    log = proc.stdout + proc.stderr
    assert "2000 steps," in proc.stdout and proc.returncode == (1 if proc.stderr else 0), log
    assert fmil_problems(proc.stderr) == [] and fmil_counts(log) == (0, 0), log
    result = np.genfromtxt(tmp_path / "out.csv", delimiter=",", names=True)  # written with %.17g
    ours = simulate_fmu(str(fmu), stop_time=0.2, output_interval=1e-4)
    assert len(result) == len(ours) == 2001 and set(result.dtype.names) == set(ours.dtype.names)  # t = 0 ... 0.2
    for name in result.dtype.names:
        assert np.array_equal(result[name], ours[name]), name
    assert max(abs(result[n][-1]) for n in result.dtype.names if n != "time") > 1e-3
