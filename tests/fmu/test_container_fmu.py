"""TAPMP_ClosedLoop.fmu: trajectory, controller and plant in one FMU (fmpy's container runtime).

The runtime steps the nested FMUs Jacobi-style at 0.1 ms and, at
fmi2ExitInitializationMode, copies every connection once while the FMUs are still in
Initialization Mode. So the plant's first step runs on the force the controller
reports in Initialization Mode, which it computes from q_d and q as soon as they are
set (fmu_common/c/values.c: initial unknowns); before that fix it ran on 0 N.
"""

import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
from tests.support.runs import COMMANDS, MOTOR_POSITIONS, orchestrator_rows, paper_scenario
from fmpy import read_model_description

from orchestrator.builder.container import CONTAINER
from tapmp.interface import ELEMENT, FMU_NAMES, VARIABLES

FMPY = Path(sys.executable).with_name("fmpy")  # the fmpy command of this environment
NAMES = MOTOR_POSITIONS + COMMANDS


def fmpy_cli(*args, check=True):
    proc = subprocess.run([str(FMPY), *map(str, args)], capture_output=True, text=True, timeout=300)
    assert not check or proc.returncode == 0, proc.stderr
    return proc


@pytest.mark.slow
def test_every_fmu_and_the_container_pass_fmpy_validate(built):
    for model in (*FMU_NAMES, CONTAINER):
        proc = fmpy_cli("validate", built[model])
        assert "No problems found" in proc.stdout, (model, proc.stdout)


def test_container_exposes_time_first_and_every_output_and_parameter_with_its_unit(built):
    md = read_model_description(str(built[CONTAINER]))
    first = md.modelVariables[0]
    assert (first.name, first.valueReference, first.causality, first.unit) == ("time", 0, "independent", "s")
    assert [v.valueReference for v in md.modelVariables] == list(range(len(md.modelVariables)))
    got = {v.name: v for v in md.modelVariables[1:]}
    expected = {f"{ELEMENT[m]}.{v.name}": v for m in FMU_NAMES for v in VARIABLES[m]
                if v.causality in ("output", "parameter")}
    assert set(got) == set(expected)
    for name, v in expected.items():
        assert (got[name].causality, got[name].type) == (v.causality, v.type), name
        assert (got[name].unit or "") == (v.unit if v.type == "Real" else ""), name
        assert got[name].description.endswith(v.description), name
    outputs = {u.variable.name for u in md.outputs}
    assert outputs == {n for n, v in expected.items() if v.causality == "output"}
    assert md.coSimulation.modelIdentifier == "container_fmu"
    names = zipfile.ZipFile(built[CONTAINER]).namelist()
    assert "binaries/linux64/container_fmu.so" in names and "resources/container.json" in names
    assert {f"resources/{ELEMENT[m]}/binaries/linux64/{m}.so" for m in FMU_NAMES} <= set(names)


@pytest.mark.slow
def test_fmpy_simulate_runs_the_container_equal_to_the_orchestrator_jacobi_ordering(built, tmp_path):
    """`fmpy simulate` on the container, with the paper scenario's parameters as start
    values, equals the orchestrator's Jacobi ordering bit for bit at every 0.1 ms."""
    scenario = paper_scenario()
    start = [x for element, table in scenario.parameters().items() for name, value in table.items()
             for x in (f"{element}.{name}", repr(value))]
    out = tmp_path / "container.csv"
    fmpy_cli("simulate", built[CONTAINER], "--stop-time", scenario.stop_time, "--output-interval",
             scenario.step, "--start-values", *start, "--output-variables", *NAMES, "--output-file", out)
    header = [n.strip('"') for n in out.read_text().splitlines()[0].split(",")]
    assert header[0] == "time" and sorted(header[1:]) == sorted(NAMES)
    data = np.loadtxt(out, delimiter=",", skiprows=1)  # fmpy writes shortest round-trip floats
    got = data[:, [0] + [header.index(n) for n in NAMES]]
    ours = orchestrator_rows(built["ssp"], scenario, NAMES, "jacobi")
    assert got.shape == (2001, 10)
    assert np.array_equal(got[:, 0], scenario.start_time + np.arange(2001) * scenario.step)
    assert np.array_equal(got[:, 1:], ours), dict(zip(NAMES, np.abs(got[:, 1:] - ours).max(axis=0)))
    assert np.abs(got[-1, 1:4]).min() > 1e-3  # the platform has moved (mm), so this compares something
    gs = orchestrator_rows(built["ssp"], scenario, NAMES[:3], "gauss-seidel")
    assert np.abs(got[:, 1:4] - gs).max() > 1e-8  # and the ordering is told apart (m)


def test_container_with_a_broken_parameter_fails_with_the_nested_message(built, tmp_path):
    proc = fmpy_cli("simulate", built[CONTAINER], "--stop-time", 0.001, "--output-interval", 1e-4,
                    "--start-values", "plant.m_p", "-1", "--output-file", tmp_path / "x.csv", check=False)
    assert proc.returncode != 0
    assert "m_p = -1" in proc.stdout + proc.stderr
