"""The FMI Cross-Check layout of the native FMI 2.0 Co-Simulation FMUs (`tapmp build
--cross-check`, orchestrator.builder.fmu_extras.cross_check_tree): FMPy's own validator of
Cross-Check vendor repositories (fmpy.cross_check.validate_vendor_repo) finds no problem in it,
and FMPy's Cross-Check importer (fmpy.cross_check.cross_check) run on it passes every model, its
results validated by the same validator."""

import re
import zipfile
from pathlib import Path

from tests.interop import compatibility
import fmpy
import numpy as np
import pytest
from fmpy.cross_check.cross_check import cross_check
from fmpy.cross_check.validate_vendor_repo import validate_repo
from fmpy.util import read_csv

from orchestrator.cli import main
from orchestrator.builder.fmu_extras import cross_check_tree
from tapmp import __version__
from tapmp.interface import FMU_NAMES

PLATFORMS = ("darwin64", "linux64", "win64")


@pytest.fixture(scope="module")
def tree(native_built, tmp_path_factory):
    """(vendor folder, model folders written) of the native FMI 2.0 FMUs' Cross-Check layout."""
    out = tmp_path_factory.mktemp("cross_check")
    fmus = {m: native_built["fmi2"][m] for m in FMU_NAMES}
    return out, cross_check_tree(fmus, out)


def test_the_layout_holds_each_fmu_with_its_reference_experiment_for_every_platform(tree, native_built):
    out, written = tree
    assert sorted(str(p.relative_to(out)) for p in written) == sorted(
        f"fmus/2.0/cs/{p}/tapmp/{__version__}/{m}" for p in PLATFORMS for m in FMU_NAMES)
    for folder in written:
        model = folder.name
        expected = {f"{model}.fmu", f"{model}_ref.csv", f"{model}_ref.opt", "ReadMe.txt"}
        if model != "TAPMP_Trajectory":
            expected.add(f"{model}_in.csv")  # the trajectory has no inputs
        assert {p.name for p in folder.iterdir()} == expected
        assert (folder / f"{model}.fmu").read_bytes() == native_built["fmi2"][model].read_bytes()
        with zipfile.ZipFile(folder / f"{model}.fmu") as z:  # the FMU's own reference experiment
            assert (folder / f"{model}_ref.csv").read_bytes() == z.read(
                "extra/org.fmi-standard.fmi-ls-ref/paper_simulation_ref.csv")
        assert "10 ms of the paper's simulation" in (folder / "ReadMe.txt").read_text()


def test_fmpys_cross_check_validator_finds_no_problem(tree):
    out, written = tree
    assert validate_repo(str(out)) == (len(written), 0, [])


def fmpy_simulate(options):
    """What FMPy's Cross-Check importer runs per model: the FMU at the options' step with the
    _in.csv as input, the _ref.csv's columns as outputs."""
    inputs = read_csv(options["input_filename"]) if "input_filename" in options else None
    return fmpy.simulate_fmu(options["fmu_filename"], stop_time=options["stop_time"], step_size=options["step_size"],
                             output_interval=options["step_size"], input=inputs,
                             output=list(options["output_variable_names"]))


def test_fmpys_cross_check_importer_passes_every_model(tree, tmp_path):
    """fmpy.cross_check.cross_check validates each model's modelDescription (with its variable
    names), _ref.opt, _in.csv, _ref.csv and documentation, simulates it and compares the result
    with _ref.csv: every cell of its report is a success, every result 100 %. (Its result folders
    need plotly for their plots, so the report is read, and FMPy's results are written below.)"""
    out, written = tree
    report = tmp_path / "report.html"
    cross_check(str(out / "fmus"), str(report), None, fmpy_simulate, "FMPy", fmpy.__version__,
                lambda options: False, None)
    rows = report.read_text().split("<tr>")[2:]
    assert len(rows) == len(written)
    for row in rows:
        labels = re.findall(r'label-(\w+)"[^>]*>([^<]*)<', row)
        # XML, options, inputs, reference, documentation, simulation, result
        expected = ["success"] * 7
        if "TAPMP_Trajectory" in row:
            expected[2] = "default"  # "n/a": the trajectory has no inputs, so no _in.csv
        assert [kind for kind, _ in labels] == expected and labels[-1][1] == "100 %", row


def test_fmpys_results_in_the_cross_check_layout_pass_its_validator(tree, request):
    """FMPy's results of every model, written as a Cross-Check result
    (results/2.0/cs/<platform>/FMPy/<version>/tapmp/<version>/<model>/ with passed and
    <model>_out.csv), pass the validator's comparison with the reference."""
    out, written = tree
    largest = 0.0
    for folder in written:
        model = folder.name
        platform, version = folder.parts[-4], folder.parts[-2]
        options = {"fmu_filename": str(folder / f"{model}.fmu"), "stop_time": 0.01, "step_size": 1e-4,
                   "output_variable_names": read_csv(str(folder / f"{model}_ref.csv")).dtype.names[1:]}
        if (folder / f"{model}_in.csv").exists():
            options["input_filename"] = str(folder / f"{model}_in.csv")
        result = fmpy_simulate(options)
        target = out / "results" / "2.0" / "cs" / platform / "FMPy" / fmpy.__version__ / "tapmp" / version / model
        target.mkdir(parents=True)
        (target / "passed").touch()
        names = result.dtype.names
        lines = [",".join(f'"{n}"' for n in names)] + [",".join(repr(float(x)) for x in row) for row in result]
        (target / f"{model}_out.csv").write_text("\n".join(lines) + "\n")
        ref = read_csv(str(folder / f"{model}_ref.csv"))
        columns = list(ref.dtype.names[1:])
        largest = max(largest, compatibility.relative(np.array([result[c] for c in columns]).T,
                                                      np.array([ref[c] for c in columns]).T))
    assert validate_repo(str(out)) == (len(written), len(written), [])
    assert largest == 0.0  # FMPy replays the reference experiment bit for bit
    compatibility.record(
        request, tool="FMPy", version=compatibility.python_version("fmpy"), fmi="2.0", interface="CS",
        command=".venv/bin/tapmp build --cross-check --out results/cross-check-fmpy && .venv/bin/python "
                "tests/interop/rows/fmpy_cross_check.py results/cross-check-fmpy",
        difference=compatibility.difference(largest, "relative", "the FMUs' reference experiments (_ref.csv)"))


def test_tapmp_build_cross_check_writes_the_layout_alone_into_its_own_folder(tmp_path, capsys):
    out = tmp_path / "cross-check"
    assert main(["build", "--out", str(out), "--cross-check"]) == 0
    printed = capsys.readouterr().out
    folders = [Path(line.removeprefix("wrote ")) for line in printed.splitlines()
               if line.startswith("wrote ") and f"{out}/" in line]
    assert sorted(f.name for f in folders) == sorted(FMU_NAMES)  # linux64 only: the host's, the default
    assert all(f.parent.parent.parent.name == "linux64" for f in folders)
    assert validate_repo(str(out)) == (3, 0, [])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cross-check"]  # no family, no SSP, nothing else
    assert sorted(p.name for p in out.iterdir()) == ["fmus"]
    assert "native fmi3" not in printed and "pythonfmu" not in printed.lower()  # only the FMI 2.0 FMUs built


def test_a_signal_stops_tapmp_build_cross_check_and_its_compilers(tmp_path):
    """SIGTERM while the compilers run: the command ends with 143 (128 + 15), its compiler processes
    with it, and no layout is written."""
    import os
    import signal
    import subprocess
    import sys
    out = tmp_path / "cross-check"
    env = {**os.environ, "ZIG_GLOBAL_CACHE_DIR": str(tmp_path / "zig"), "TAPMP_CACHE": str(tmp_path / "cache")}
    proc = subprocess.Popen([sys.executable, "-m", "orchestrator", "build", "--cross-check", "--all-platforms",
                             "--out", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    for line in proc.stdout:  # a cold cache: minutes of compiling ahead
        if line.startswith("native: compiling"):
            break
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    assert "interrupted" in err and "Traceback" not in err
    assert not out.exists()
    assert _processes_with_environment(f"ZIG_GLOBAL_CACHE_DIR={tmp_path / 'zig'}") == []  # no compiler left


def _processes_with_environment(entry: str) -> list[int]:
    """The ids of this user's processes whose environment holds ``entry`` (NAME=value)."""
    found = []
    for proc in Path("/proc").iterdir():
        try:
            if proc.name.isdigit() and entry.encode() in (proc / "environ").read_bytes().split(b"\0"):
                found.append(int(proc.name))
        except OSError:
            continue  # another user's, or ended meanwhile
    return found
