"""The clocked controller in a host without Python: a small C program (tests/fmu/c_host/fmi3_clocked_loop.c,
compiled here by the project's toolchain) runs plant + clocked controller + trajectory through the FMI 3.0
API, activating the clock at every tick, and gets the forces of the tapmp master's Event Mode run (the
controller with time events) bit for bit."""

import subprocess
import zipfile
from pathlib import Path

import numpy as np
import pytest

from orchestrator.engine.master import CoSimulation, RunOptions
from tapmp.interface import CONNECTIONS, CONTROLLER, ELEMENT, PLANT, TRAJECTORY
from tests.support.c_hosts import compile_c_host, unzip_fmu
from tests.support.native_fmi3_runs import fmi3  # noqa: F401 (a fixture)

pytestmark = pytest.mark.slow  # builds the FMI 3.0 FMUs, compiles a C host and runs it as a child process

HOST_SOURCE = Path(__file__).parent / "c_host" / "fmi3_clocked_loop.c"
STEPS = 500  # 50 ms at T_s = 0.1 ms
PRINTED = ("controller.F1", "controller.F2", "controller.F3", "plant.q1", "plant.q2", "plant.q3")


@pytest.fixture(scope="module")
def host(tmp_path_factory):
    return compile_c_host(HOST_SOURCE, tmp_path_factory.mktemp("c_host") / "fmi3_clocked_loop", werror=True)


def run_host(host, fmi3, tmp, steps=STEPS):
    from orchestrator.builder.build_native import CLOCKED
    order = (TRAJECTORY, CLOCKED, PLANT)  # the master's initialization order: trajectory, controller, plant
    index = {TRAJECTORY: 0, CONTROLLER: 1, PLANT: 2}
    elements = [f"{unzip_fmu(fmi3[m], tmp / m)}:{m}" for m in order]
    links = [f"{index[s]}.{o}:{index[d]}.{i}" for s, o, d, i in CONNECTIONS]
    by_element = {ELEMENT[m]: index[m] for m in index}
    printed = [f"{by_element[c.split('.')[0]]}.{c.split('.')[1]}" for c in PRINTED]
    done = subprocess.run([str(host), str(steps), *elements, "--", *links, "--", *printed], capture_output=True,
                          text=True, timeout=120, env={"PATH": "/usr/bin:/bin"})
    return done


def test_c_host_ticking_the_clock_gives_the_masters_event_mode_forces_bit_for_bit(fmi3, host, tmp_path):
    done = run_host(host, fmi3, tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stderr == ""  # no warning, nothing logged
    rows = np.array([[float(x) for x in line.split()] for line in done.stdout.splitlines()])
    assert rows.shape == (STEPS + 1, 1 + len(PRINTED))
    with CoSimulation(fmi3["ssp"], {}, RunOptions(start_time=0.0, step_size=1e-4, ordering="gauss-seidel",
                                                  event_mode=True)) as sim:
        expected = [sim.row()]
        for _ in range(STEPS):
            sim.step()
            expected.append(sim.row())
        columns = sim.columns
    expected = np.array(expected)[:, [0] + [columns.index(c) for c in PRINTED]]
    np.testing.assert_array_equal(rows[:, 0], expected[:, 0])  # t0 + k T_s
    np.testing.assert_array_equal(rows, expected)
    assert np.abs(rows[:, 1:4]).max() > 1.0  # the forces move: the loop runs


def test_the_loop_with_every_fmu_and_the_host_under_address_and_ub_sanitizers_runs_clean(fmi3, host, tmp_path):
    """The three FMUs compiled from their sources/ and the host, all with AddressSanitizer and UBSan: the
    clock's calls (GetIntervalDecimal, SetClock, UpdateDiscreteStates) and the loop report nothing, leak
    nothing, and give the shipped binaries' rows."""
    import os
    from tests.support.ctools import SANITIZE, SANITIZER_ENV, compile_c as cc, extract_sources
    from orchestrator.builder.build_native import CLOCKED
    exe = tmp_path / "loop_asan"
    proc = cc([*SANITIZE, "-std=c99", "-o", exe, HOST_SOURCE, "-ldl"])
    assert proc.returncode == 0, proc.stderr
    sanitized = tmp_path / "sanitized"
    for model in (TRAJECTORY, CLOCKED, PLANT):
        folder = sanitized / model
        src = extract_sources(fmi3[model], folder)
        with zipfile.ZipFile(fmi3[model]) as z:
            z.extract("modelDescription.xml", folder)
        lib = folder / "binaries" / "x86_64-linux" / f"{model}.so"
        lib.parent.mkdir(parents=True)
        proc = cc([*SANITIZE, "-std=c99", "-ffp-contract=off", "-shared", "-fPIC", f"-I{src}", "-o", lib,
                   src / "all.c", "-lm"])
        assert proc.returncode == 0, proc.stderr
    index = {TRAJECTORY: 0, CONTROLLER: 1, PLANT: 2}
    links = [f"{index[s]}.{o}:{index[d]}.{i}" for s, o, d, i in CONNECTIONS]
    args = [str(exe), "100", *(f"{sanitized / m}:{m}" for m in (TRAJECTORY, CLOCKED, PLANT)), "--", *links, "--",
            "1.F1", "1.F2", "1.F3", "2.q1"]
    run = subprocess.run(args, capture_output=True, text=True, timeout=300,
                         env={"PATH": os.environ["PATH"], **SANITIZER_ENV})
    assert "Sanitizer" not in run.stderr and "runtime error" not in run.stderr, run.stderr[-4000:]
    assert run.returncode == 0, run.stderr[-4000:]
    shipped = run_host(host, fmi3, tmp_path / "shipped", steps=100)
    assert shipped.returncode == 0, shipped.stderr
    expected = [" ".join(line.split()[:4] + line.split()[4:5]) for line in shipped.stdout.splitlines()]
    assert run.stdout.splitlines() == expected
