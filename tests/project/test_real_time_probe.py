"""The measuring instruments of the real-time benchmarks: the probe FMU (benchmarks/probe/) that notes the wall
time of each doStep, placed into a copy of an SSP, and the C host of benchmarks/bench_controller_time.py
(benchmarks/controller_time.c): its refusals, and that every FMI variant it times computes the same forces
as the control law alone."""

import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import simulate_fmu

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))

from probe.probe import build_probe, lateness, read_record, with_probe  # noqa: E402

FMIL = "tools/fmil/fmil_check"


@pytest.fixture(scope="module")
def probe(tmp_path_factory):
    """The probe FMU writing to record.txt beside it."""
    folder = tmp_path_factory.mktemp("probe")
    return build_probe(folder / "TAPMP_Probe.fmu", folder / "record.txt")


@pytest.mark.needs_shared(FMIL)
def test_the_probe_fmu_passes_fmil_check(probe):
    from tests.support.shared import shared
    done = subprocess.run([str(shared(FMIL)), "parse", str(probe)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "FMIL parse: 0 warnings, 0 errors" in done.stdout


def test_the_probe_notes_one_line_per_dostep_with_its_time_and_step_written_whole(probe, tmp_path):
    record = probe.parent / "record.txt"
    result = simulate_fmu(str(probe), stop_time=0.005, step_size=1e-4, output_interval=1e-4, fmi_type="CoSimulation")
    rows = read_record(record)
    assert len(rows) == 50 and not record.with_name("record.txt.part").exists()
    np.testing.assert_allclose(rows[:, 0], np.arange(50) * 1e-4, rtol=0, atol=1e-15)
    assert np.all(rows[:, 1] == pytest.approx(1e-4)) and np.all(np.diff(rows[:, 2]) >= 0)
    assert list(result["steps"][1:]) == list(range(1, 51))  # its output counts the doSteps
    late = lateness(rows, 1.0)  # FMPy paces nothing: every doStep is early against real time
    assert late["steps"] == 50 and late["overruns"] == 0 and late["lateness_s"]["max"] <= 0.0
    assert late["achieved_factor"] > 1.0


def test_the_probes_lateness_is_its_wall_time_against_the_schedule():
    rows = np.array([[0.0, 0.1, 0.0], [0.1, 0.1, 0.30e9], [0.2, 0.1, 0.40e9], [0.3, 0.1, 0.45e9]])
    # schedule at factor 2: 0, 0.05, 0.10, 0.15 s; wall 0, 0.30, 0.40, 0.45 s
    late = lateness(rows, 2.0)
    assert late["lateness_s"]["max"] == pytest.approx(0.30)
    assert late["lateness_s"]["p50"] == pytest.approx(np.percentile([0, 0.25, 0.30, 0.30], 50))
    assert late["overruns"] == 3 and late["achieved_factor"] == pytest.approx(0.3 / 0.45)


def test_read_record_refuses_an_empty_record(tmp_path):
    (tmp_path / "r.txt").write_text("")
    with pytest.raises(ValueError, match="the probe recorded no doStep"):
        read_record(tmp_path / "r.txt")


def test_with_probe_adds_one_unconnected_component_and_keeps_everything_else(probe, native_built, tmp_path):
    ssp = native_built["fmi2"]["ssp"]
    out = with_probe(ssp, probe, tmp_path / "probed.ssp")
    with zipfile.ZipFile(ssp) as a, zipfile.ZipFile(out) as b:
        assert set(b.namelist()) == set(a.namelist()) | {"resources/TAPMP_Probe.fmu"}
        assert all(a.read(n) == b.read(n) for n in a.namelist() if n != "SystemStructure.ssd")
        ssd, before = b.read("SystemStructure.ssd").decode(), a.read("SystemStructure.ssd").decode()
    assert ssd.count("<ssd:Component ") == before.count("<ssd:Component ") + 1
    assert 'name="probe"' in ssd and 'Element="probe"' not in ssd  # no connection names it


HOST_SOURCE = ROOT / "benchmarks" / "controller_time.c"


@pytest.fixture(scope="module")
def host(native_built, tmp_path_factory):
    """The C host compiled, the controllers unzipped, the recorded inputs and the settings bytes."""
    import bench_controller_time as bench
    folder = tmp_path_factory.mktemp("ctime")
    fmi2, fmi3 = native_built["fmi2"], native_built["fmi3"]
    dirs = {"fmi2": bench.unzip(fmi2["TAPMP_Controller"], folder / "c2"),
            "fmi3": bench.unzip(fmi3["TAPMP_Controller"], folder / "c3"),
            "clocked": bench.unzip(fmi3["TAPMP_ControllerClocked"], folder / "cc")}
    exe = bench.compile_host(dirs["fmi2"] / "sources", folder / "controller_time")
    bench.recorded_inputs(fmi2["ssp"], folder / "inputs.bin")
    bench.settings_bytes(folder / "settings.bin")
    return exe, dirs, folder


def run(exe, *args):
    return subprocess.run([str(exe), *map(str, args)], capture_output=True, text=True, timeout=120)


def test_every_variant_the_host_times_computes_the_forces_of_the_control_law_alone(host, tmp_path):
    exe, dirs, folder = host
    for law in (0, 1, 2):
        printed = {}
        for mode, path in (("fmi2", dirs["fmi2"]), ("fmi3", dirs["fmi3"]), ("fmi3-clocked", dirs["clocked"]),
                           ("law", folder / "settings.bin")):
            done = run(exe, mode, path, folder / "inputs.bin", 300, law, tmp_path / "ns.bin")
            assert done.returncode == 0 and done.stderr == "", done.stderr
            printed[mode] = [float(x) for x in done.stdout.split()]
            ns = np.fromfile(tmp_path / "ns.bin", dtype=np.int64)
            assert len(ns) == 300 and np.all(ns > 0)
        # the last sample's F1..F3, bit for bit: the FMUs run the law and nothing changes it
        assert printed["fmi2"] == printed["fmi3"] == printed["fmi3-clocked"] == printed["law"]
        assert max(abs(f) for f in printed["law"]) > 1.0
    # the event-mode controller samples at the end of each step: after 300 steps, the sample of t = 300 h
    done = run(exe, "fmi3-event", dirs["fmi3"], folder / "inputs.bin", 299, 0, tmp_path / "ns.bin")
    law = run(exe, "law", folder / "settings.bin", folder / "inputs.bin", 300, 0, tmp_path / "ns.bin")
    assert done.returncode == 0 and done.stdout == law.stdout


@pytest.mark.parametrize("args, message", [
    (("bogus", "{c2}", "{inputs}", 10, 0), "MODE = 'bogus' is invalid: allowed is one of fmi2, fmi3, fmi3-event, "
                                            "fmi3-clocked, law"),
    (("fmi2", "{c2}", "{inputs}", 0, 0), "SAMPLES = '0' is invalid: allowed is an integer in [1, 1000000000]"),
    (("fmi2", "{c2}", "{inputs}", "1e3", 0), "SAMPLES = '1e3' is invalid: allowed is an integer in [1, 1000000000]"),
    (("fmi2", "{c2}", "{inputs}", 10, 3), "LAW = '3' is invalid: allowed is 0 (SC-DC), 1 (APD-DC) or 2 (PID-DC)"),
    (("fmi2", "{c3}", "{inputs}", 10, 0), "PATH = '{c3}' is invalid: allowed is an FMI 2.0 FMU for MODE fmi2"),
    (("fmi3-clocked", "{c3}", "{inputs}", 10, 0), "MODE = 'fmi3-clocked' needs an FMU with a <Clock>"),
    (("fmi2", "{c2}", "{settings}", 10, 0), "INPUTS = '{settings}' is invalid: allowed is a file of rows of 15 "
                                            "doubles, at least one row"),
    (("law", "{inputs}", "{inputs}", 10, 0), "PATH = '{inputs}' is invalid: allowed is a file of 264 bytes"),
])
def test_the_host_refuses_bad_input_with_one_line_and_exit_2_writing_nothing(host, tmp_path, args, message):
    exe, dirs, folder = host
    names = {"c2": dirs["fmi2"], "c3": dirs["fmi3"], "inputs": folder / "inputs.bin", "settings": folder / "settings.bin"}
    done = run(exe, *(str(a).format(**names) for a in args), tmp_path / "ns.bin")
    assert done.returncode == 2
    assert done.stderr.startswith("controller_time: " + message.format(**names)), done.stderr
    assert len(done.stderr.splitlines()) == 1 and not (tmp_path / "ns.bin").exists()


@pytest.mark.parametrize("args, message", [
    (["--samples", "0"], "error: argument --samples: '0' is invalid: allowed is an integer in [1, 1000000000]"),
    (["--native", "{tmp}"], "error: --native = {tmp} has no fmi2/TAPMP_Controller.fmu: run `tapmp build` first or "
                            "pass --build"),
])
def test_bench_controller_time_refuses_bad_input_with_exit_2_and_writes_no_json(tmp_path, args, message):
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_controller_time.py"),
                           *(a.format(tmp=tmp_path) for a in args), "--json", str(tmp_path / "t.json")],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines()[-1].endswith(message.format(tmp=tmp_path))  # argparse: "PROG: error: ..."
    assert not (tmp_path / "t.json").exists()
