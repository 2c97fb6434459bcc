"""FMI Library (FMIL 3.0.4, the importer behind OpenModelica and PyFMI) reads every FMU of every
family without a warning but about FMI 3.0 terminals (below), through ``fmil_check`` (../shared/tools/fmil, a small C program on
FMIL): ``parse`` reports every FMIL log message of level warning or worse and exits non-zero on
any; ``alone`` instantiates an FMU and steps it, recording its outputs at every communication point.
What FMIL reads back of the dependencies: tests/fmu/test_dependencies.py.

FMIL 3.0.4 knows only part of the FMI 3.0 terminalsAndIcons schema: what it says about the native
FMI 3.0 FMUs' valid terminalsAndIcons.xml is expected exactly, and nothing else
(tests/support/fmil_gaps.py).
"""

import re
import subprocess
from collections import Counter

from tests.interop import compatibility
import numpy as np
import pytest
from tests.support.shared import shared
from tests.support.fmil_gaps import fmil_messages, terminal_messages, warnings_and_errors
from fmpy import simulate_fmu

from orchestrator.builder.container import CONTAINER
from tapmp.interface import FMU_NAMES

FMIL_CHECK = "tools/fmil/fmil_check"
# the rows' commands: fmil_check exits 1 on any message, as on FMIL's known gaps on the FMI 3.0 terminals
EXIT_1 = {"2.0": "", "3.0": ' || echo "exit code $?"'}
pytestmark = pytest.mark.needs_shared(FMIL_CHECK)


def every_fmu(built, native_built) -> dict:
    """{label: path} of every FMU: pythonfmu, native FMI 2.0 and 3.0, and the container."""
    fmus = {f"python/{m}": built[m] for m in FMU_NAMES}
    fmus[f"python/{CONTAINER}"] = built[CONTAINER]
    for version in ("fmi2", "fmi3"):
        fmus.update({f"{version}/{m}": native_built[version][m] for m in FMU_NAMES})
    return fmus


def test_fmil_parses_every_fmu_of_every_family_with_no_warning_but_on_fmi3_terminals(built, native_built, tmp_path, request):
    fmus = every_fmu(built, native_built)
    proc = subprocess.run([str(shared(FMIL_CHECK)), "parse", *map(str, fmus.values())], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)
    # FMIL's warnings and errors go to stderr: only those on the FMI 3.0 terminals (exit 1 on any)
    fmi3 = [path for label, path in fmus.items() if label.startswith("fmi3")]
    assert fmil_messages(proc.stderr) == sum((terminal_messages(p) for p in fmi3), Counter()), proc.stderr
    assert proc.returncode == 1, proc.stdout + proc.stderr
    reports = proc.stdout.split("\n/")
    assert len(reports) == len(fmus) == 10
    for (label, path), report in zip(fmus.items(), reports):
        assert path.name in report.splitlines()[0], (label, report)
        expected = terminal_messages(path) if label.startswith("fmi3") else Counter()
        warnings, errors = warnings_and_errors(expected)
        assert f"FMIL parse: {warnings} warnings, {errors} errors" in report, (label, report)
        version = "3.0" if label.startswith("fmi3") else "2.0"
        assert f"FMI {version}" in report, (label, report)
    # what FMIL read back: the container's 39 outputs, the plant's 15, in both versions
    assert re.search(r"variables \d+, outputs 39, initial unknowns 39", reports[3]), reports[3]
    for label, report in zip(fmus, reports):
        if label.endswith("TAPMP_Plant"):
            derivatives = 6 if label in ("fmi2/TAPMP_Plant", "fmi3/TAPMP_Plant") else 0  # Model Exchange's state derivatives
            assert f"outputs 15, initial unknowns {15 + derivatives}" in report, (label, report)
    for version, folder in (("2.0", "build/"), ("2.0", "build/native/fmi2/"), ("3.0", "build/native/fmi3/")):
        compatibility.record(request, tool="FMIL", version=compatibility.readme_version("fmil"), fmi=version,
                             interface="CS", command=f"{compatibility.FMIL_CHECK} parse {folder}*.fmu" + EXIT_1[version],
                             difference="none (reads the FMUs' XML only): no warning or error" if version == "2.0"
                             else "none (reads the FMUs' XML only): errors and warnings only on the valid "
                             "terminalsAndIcons.xml, whose elements FMIL does not know")


@pytest.mark.parametrize("model", FMU_NAMES)
@pytest.mark.parametrize("version", ["fmi2", "fmi3"])
def test_fmil_steps_each_native_fmu_alone_as_fmpy_does(native_built, version, model, tmp_path, request):
    fmu = native_built[version][model]
    proc = subprocess.run([str(shared(FMIL_CHECK)), "alone", str(fmu), "out.csv", "0.2", "0.0001"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)
    expected = terminal_messages(fmu) if version == "fmi3" else Counter()
    assert fmil_messages(proc.stderr) == expected, proc.stderr
    assert proc.returncode == (1 if expected else 0), proc.stdout + proc.stderr
    warnings, errors = warnings_and_errors(expected)
    assert f"2000 steps, {warnings} warnings, {errors} errors" in proc.stdout, proc.stdout
    result = np.genfromtxt(tmp_path / "out.csv", delimiter=",", names=True)  # written with %.17g
    ours = simulate_fmu(str(fmu), stop_time=0.2, output_interval=1e-4)
    assert len(result) == len(ours) == 2001 and set(result.dtype.names) == set(ours.dtype.names)  # t = 0 ... 0.2
    for name in result.dtype.names:
        assert np.array_equal(result[name], ours[name]), name
    assert max(abs(result[n][-1]) for n in result.dtype.names if n != "time") > 1e-3
    compatibility.record(
        request, tool="FMIL", version=compatibility.readme_version("fmil"), fmi=version[3] + ".0", interface="CS",
        command=f"{compatibility.FMIL_CHECK} alone {compatibility.family_path(version, model)} out.csv 0.2 0.0001"
                + EXIT_1[version[3] + ".0"],
        result="passed" if version == "fmi2" else "passed (FMIL logs the terminals' elements it does not know)",
        difference=compatibility.difference(0.0, "", "FMPy simulate_fmu"))  # array_equal above
