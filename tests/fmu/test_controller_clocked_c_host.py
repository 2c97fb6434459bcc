"""The clocked controller in a host without Python: a small C program (tests/fmu/c_host/fmi3_clocked_loop.c,
compiled here by the project's toolchain) runs plant + clocked controller + trajectory through the FMI 3.0
API, activating the clock at every tick, and gets the forces of the tapmp master's Event Mode run (the
controller with time events) bit for bit."""

import subprocess
import zipfile
from pathlib import Path

import fmpy
import numpy as np
import pytest

from orchestrator.engine.master import CoSimulation
from tapmp.interface import CONNECTIONS, CONTROLLER, ELEMENT, PLANT, TRAJECTORY
from tapmp.toolchain import compile_c

pytestmark = pytest.mark.slow  # builds the FMI 3.0 FMUs, compiles a C host and runs it as a child process

HOST_SOURCE = Path(__file__).parent / "c_host" / "fmi3_clocked_loop.c"
STEPS = 500  # 50 ms at T_s = 0.1 ms
PRINTED = ("controller.F1", "controller.F2", "controller.F3", "plant.q1", "plant.q2", "plant.q3")


@pytest.fixture(scope="module")
def fmi3(tmp_path_factory):
    from orchestrator.engine.build_native import build_native
    return build_native(tmp_path_factory.mktemp("native"), families=("fmi3",), log=lambda *_: None,
                        windows=False)["fmi3"]


@pytest.fixture(scope="module")
def host(tmp_path_factory):
    exe = tmp_path_factory.mktemp("c_host") / "fmi3_clocked_loop"
    headers = Path(fmpy.__file__).parent / "c-code"
    return compile_c([HOST_SOURCE], exe, shared=False, flags=["-O1", "-Wall", "-Werror"], includes=[headers],
                     libs=["dl"])


def unzip(fmu: Path, dest: Path) -> Path:
    with zipfile.ZipFile(fmu) as z:
        z.extractall(dest)
    for so in (dest / "binaries" / "x86_64-linux").glob("*.so"):
        so.chmod(0o755)
    return dest


def run_host(host, fmi3, tmp, steps=STEPS):
    from orchestrator.engine.build_native import CLOCKED
    order = (TRAJECTORY, CLOCKED, PLANT)  # the master's initialization order: trajectory, controller, plant
    index = {TRAJECTORY: 0, CONTROLLER: 1, PLANT: 2}
    elements = [f"{unzip(fmi3[m], tmp / m)}:{m}" for m in order]
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
    with CoSimulation(fmi3["ssp"], {}, 0.0, 1e-4, "gauss-seidel", event_mode=True) as sim:
        expected = [sim.row()]
        for _ in range(STEPS):
            sim.step()
            expected.append(sim.row())
        columns = sim.columns
    expected = np.array(expected)[:, [0] + [columns.index(c) for c in PRINTED]]
    np.testing.assert_array_equal(rows[:, 0], expected[:, 0])  # t0 + k T_s
    np.testing.assert_array_equal(rows, expected)
    assert np.abs(rows[:, 1:4]).max() > 1.0  # the forces move: the loop runs
