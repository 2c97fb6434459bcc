"""`tapmp export`: the scenario travels with the SSP, and other tools run it as `tapmp run` does.

The paper scenario (first 0.2 s) with its reference at twice the frequency (0.8 Hz; the paper's
own values are every FMU's defaults, which a tool ignoring the parameter sets would run too) is
exported with the real CLI from the pythonfmu SSP, then run by libcosim, Ecos (library and `ecos` executable), FMPy's simulate_ssp and
`fmpy simulate` on the container FMU with nothing but what the export wrote: the SSP's
parameter sets, its DefaultExperiment, and FILE.start-values.txt. Each is compared with
the orchestrator (the engine of `tapmp run`) on that master's conventions. The scenario starts on
its trajectory, moving at 50 mm/s: with the plant's default initial state instead (25 mm/s, the
paper's reference) the motors end up micrometres away, which every test checks too.
"""

import shutil
import stat
import subprocess
import sys
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

from tests.interop import compatibility
import numpy as np
import pytest
from tests.support.runs import COMMANDS, MOTOR_POSITIONS, PAPER, orchestrator_rows, paper_scenario

from orchestrator.cli import main
from orchestrator.builder import families
from orchestrator.builder.container import CONTAINER
from orchestrator.builder.ssp import OSP
from orchestrator.tool.export import SSD_MEMBER
from tapmp.interface import INITIAL_STATE as DEFAULT_STATE

DEFAULT_DX0 = DEFAULT_STATE[3]  # m/s: the plant's default, the paper reference's start (25 mm/s)

NAMES = MOTOR_POSITIONS + COMMANDS
SSD_NS = {"ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
          "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon", "osp": OSP}
INITIAL_STATE = ("X0", "Z0", "B0", "dX0", "dZ0", "dB0")
# What the export carries beyond the FMUs' defaults (the paper scenario itself restates them)
FASTER = ("trajectory.f_xz=0.8", "trajectory.f_B=0.8")


@pytest.fixture(scope="module")
def exported(built, tmp_path_factory):
    """(scenario, exported SSP, start-values file, printed text) of `tapmp export` on the paper
    scenario shortened to 0.2 s."""
    out = tmp_path_factory.mktemp("export") / "paper.ssp"
    import contextlib
    import io
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["export", str(PAPER), "--out", str(out), "--ssp", str(built["ssp"]),
                     "--set", "stop_time=0.2", *(a for kv in FASTER for a in ("--set", kv))]) == 0
    return paper_scenario(0.2, *FASTER), out, out.with_suffix(".start-values.txt"), buf.getvalue()


@pytest.fixture(scope="module")
def without_initial_state(built):
    """The orchestrator's Jacobi rows of the same scenario with the plant starting from its
    default initial state (the paper reference's, no X0 ... dB0 given): what a tool would give
    if the initial state were not exported."""
    sc = paper_scenario(0.2, *FASTER).with_changes(start_on_trajectory=False)
    return orchestrator_rows(built["ssp"], sc, NAMES, "jacobi")


def assert_initial_state_matters(rows, rest, first=0):
    """The tool's positions are micrometres from the run without the initial state."""
    n = min(len(rows), len(rest) - first)
    gap = np.abs(rows[:n, :3] - rest[first:first + n, :3]).max()
    assert gap > 1e-6, gap  # m; measured 1.1e-5 m (simulate_ssp: 1.6e-5 m), tests/interop/measure_export.py


def ssd_root(ssp):
    with zipfile.ZipFile(ssp) as z:
        return ET.fromstring(z.read(SSD_MEMBER))


def experiment(ssp):
    """(start time, stop time, step) [s] from the exported SSD's DefaultExperiment."""
    exp = ssd_root(ssp).find("ssd:DefaultExperiment", SSD_NS)
    step = exp.find("ssd:Annotations/ssc:Annotation/osp:Algorithm/osp:FixedStepAlgorithm", SSD_NS)
    return float(exp.get("startTime")), float(exp.get("stopTime")), float(step.get("baseStepSize"))


# ---------------------------------------------------------------- what the export writes

def test_the_parameter_sets_hold_every_value_the_scenario_sets_bound_to_each_element(exported):
    """fmpy's SSP reader validates the SSD and every .ssv against the SSP 1.0 schemas and
    reads the bindings back: each element has one, and together they are exactly the values
    `tapmp run` sets (bit for bit, with their FMI types), the initial state included."""
    from fmpy.ssp.ssd import read_ssd
    scenario, ssp, _, _ = exported
    ssd = read_ssd(str(ssp))  # validates against the schemas
    expected = scenario.parameters()
    got = {}
    for component in ssd.system.elements:
        (binding,) = component.parameterBindings
        assert binding.source == f"resources/{component.name}.ssv" and not binding.prefix
        (pset,) = binding.parameterValues
        assert pset.name == scenario.name
        got[component.name] = {p.name: (int(p.value) if p.type == "Integer" else float(p.value))
                               for p in pset.parameters}
        types = {p.name: p.type for p in pset.parameters}
        assert all(types[n] == ("Integer" if isinstance(v, int) else "Real")
                   for n, v in expected[component.name].items()), types
    assert got == expected
    assert set(INITIAL_STATE) <= set(got["plant"]) and got["plant"]["dX0"] == pytest.approx(2 * DEFAULT_DX0, rel=1e-12)
    assert got["controller"]["law"] == 0 and len([n for n in got["controller"] if n[-1] in "123"]) == 15
    assert experiment(ssp) == (0.0, 0.2, 1e-4)


def test_start_values_are_written_next_to_the_ssp_and_printed(exported):
    scenario, ssp, values, printed = exported
    pairs = values.read_text().split()
    names, texts = pairs[0::2], pairs[1::2]
    expected = {f"{e}.{n}": v for e, t in scenario.parameters().items() for n, v in t.items()}
    assert dict(zip(names, map(float, texts))) == expected and len(names) == len(expected)
    assert f"plant.dX0 {2 * DEFAULT_DX0!r}" in values.read_text()  # the reference at twice the frequency
    assert " ".join(pairs) in printed and str(ssp) in printed and str(values) in printed


def test_the_native_fmi3_ssp_exports_with_fmi3_types(native_built, tmp_path, capsys):
    """The FMI 3.0 family declares Float64/Int32: the .ssv says Real/Integer all the same."""
    from fmpy.ssp.ssd import read_ssd
    out = tmp_path / "fmi3.ssp"
    assert main(["export", str(PAPER), "--out", str(out), "--ssp", str(native_built["fmi3"]["ssp"])]) == 0
    ssd = read_ssd(str(out))
    types = {(c.name, p.name): p.type for c in ssd.system.elements
             for p in c.parameterBindings[0].parameterValues[0].parameters}
    assert types[("controller", "law")] == "Integer" and types[("plant", "X0")] == "Real"
    assert experiment(out) == (0.0, 2.5, 1e-4)


def test_role_tables_are_bound_to_renamed_elements_and_libcosim_runs_them(built, tmp_path, capsys):
    """On an SSP whose elements are named otherwise (ref, ctl, axis) the scenario's [trajectory],
    [controller] and [plant] tables go to the elements whose FMUs are those models, as in the
    master; libcosim then gives the original system's results bit for bit."""
    from tests.engine.master.test_master_any_ssp import RENAME, rewrite_ssp
    renamed = rewrite_ssp(built["ssp"], tmp_path / "renamed.ssp", rename=RENAME)
    out = tmp_path / "renamed_export.ssp"
    assert main(["export", str(PAPER), "--out", str(out), "--ssp", str(renamed), "--set", "stop_time=0.05"]) == 0
    with zipfile.ZipFile(out) as z:
        assert {n for n in z.namelist() if n.endswith(".ssv")} == {f"resources/{e}.ssv" for e in RENAME.values()}
    names = tuple(f"{RENAME[n.split('.')[0]]}.{n.split('.')[1]}" for n in NAMES)
    rows = run_libcosim_exported(out, names)
    ours = orchestrator_rows(built["ssp"], paper_scenario(0.05), NAMES, "jacobi", clock="nanoseconds")[1:]
    assert rows.shape == (500, 9) and np.array_equal(rows, ours)


# ---------------------------------------------------------------- libcosim

def run_libcosim_exported(ssp, names):
    """libcosim's values of ``names`` at t_1 ... t_n, from the SSP alone: no parameter and no
    step size given (libcosim takes them from the bindings and the OSP annotation)."""
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver
    start, stop, step = experiment(ssp)
    n = int(round((stop - start) / step))
    log_output_level(CosimLogLevel.WARNING)
    execution = CosimExecution.from_ssp_file(str(ssp))  # no step size: the SSP's own
    observer = CosimObserver.create_last_value()
    execution.add_observer(observer)
    index = {s.name.decode(): s.index for s in execution.slave_infos()}
    refs = {e: {v.name.decode(): v.reference for v in execution.slave_variables(i)} for e, i in index.items()}
    rows = np.zeros((n, len(names)))
    for k in range(n):
        assert execution.step(1)
        for j, name in enumerate(names):
            element, var = name.split(".")
            rows[k, j] = observer.last_real_values(index[element], [refs[element][var]])[0]
    assert execution.status().current_time == n * round(step * 1e9)
    return rows


def test_libcosim_runs_the_exported_ssp_alone_bit_identical_on_its_nanosecond_clock(built, exported,
                                                                                  without_initial_state, request):
    """libcosim applies each component's first parameter set from the SSD (its default set) and
    takes the step size from the DefaultExperiment's OSP annotation: nothing is set by hand."""
    scenario, ssp, _, _ = exported
    rows = run_libcosim_exported(ssp, NAMES)
    assert rows.shape == (2000, 9)
    ours = orchestrator_rows(built["ssp"], scenario, NAMES, "jacobi", clock="nanoseconds")[1:]
    assert np.array_equal(rows, ours), dict(zip(NAMES, np.abs(rows - ours).max(axis=0)))
    assert_initial_state_matters(rows, without_initial_state, first=1)
    compatibility.record(
        request, tool="libcosim", version=compatibility.python_version("libcosimpy"), fmi="2.0", interface="SSP 1.0, CS",
        command=compatibility.export('build/TAPMP.ssp', 'results/export/paper.ssp') + ' && ' + compatibility.python_c("from libcosimpy.CosimExecution import CosimExecution; e = CosimExecution.from_ssp_file('results/export/paper.ssp'); print(e.step(2000))"),
        difference=compatibility.difference(compatibility.largest(rows, ours), "", "tapmp run, ordering=jacobi, clock=nanoseconds"))


# ---------------------------------------------------------------- Ecos

def run_ecos_exported(ssp, names, parameter_set):
    from ecospy import EcosSimulation
    start, stop, step = experiment(ssp)
    sim = EcosSimulation(ssp_path=str(ssp), step_size=step)
    try:
        assert sim.init(start, parameter_set=parameter_set)
        ids = [n.replace(".", "::", 1) for n in names]
        rows = [[sim.get_real(i) for i in ids]]
        for _ in range(int(round((stop - start) / step))):
            sim.step()
            rows.append([sim.get_real(i) for i in ids])
        sim.terminate()
    finally:
        sim.free()
    return np.array(rows)


def test_ecos_runs_the_exported_ssp_with_its_named_parameter_set_bit_identical(built, exported,
                                                                              without_initial_state, request):
    """Ecos applies an SSP parameter set when it is named at init (``parameter_set=`` in
    ecospy, ``--parameterSet`` of `ecos simulate`): the scenario's name."""
    scenario, ssp, _, _ = exported
    rows = run_ecos_exported(ssp, NAMES, scenario.name)
    ours = orchestrator_rows(built["ssp"], scenario, NAMES, "jacobi", clock="accumulated")
    assert rows.shape == ours.shape == (2001, 9)
    assert np.array_equal(rows, ours), dict(zip(NAMES, np.abs(rows - ours).max(axis=0)))
    assert_initial_state_matters(rows, without_initial_state)
    compatibility.record(
        request, tool="Ecos", version=compatibility.python_version("ecospy"), fmi="2.0", interface="SSP 1.0, CS",
        command=compatibility.export('build/TAPMP.ssp', 'results/export/paper.ssp') + ' && ' + compatibility.python_c("from ecospy import EcosSimulation; s = EcosSimulation(ssp_path='results/export/paper.ssp', step_size=1e-4); s.init(0.0, parameter_set='paper_simulation'); s.step(2000); print(s.get_real('plant::q1_true')); s.terminate(); s.free()"),
        difference=compatibility.difference(compatibility.largest(rows, ours), "", "tapmp run, ordering=jacobi, clock=accumulated"))


def test_ecos_without_the_parameter_set_name_keeps_the_fmus_start_values(exported):
    """Ecos does not apply an SSP's parameter set unless it is named (so the docs name it)."""
    from ecospy import EcosSimulation
    scenario, ssp, _, _ = exported
    values = {}
    for pset in (None, scenario.name):
        sim = EcosSimulation(ssp_path=str(ssp), step_size=1e-4)
        try:
            assert sim.init(0.0, parameter_set=pset)
            values[pset] = (sim.get_real("plant::dX0"), sim.get_real("plant::k_pull"))
            sim.terminate()
        finally:
            sim.free()
    assert values[scenario.name] == (scenario.parameters()["plant"]["dX0"], 200.0)
    assert values[None] == (DEFAULT_DX0, 200.0) and values[None] != values[scenario.name]


def run_ecos_executable(ssp, parameter_set, folder, names):
    """`ecos simulate --parameterSet NAME` started in ``folder`` (it writes its CSV into the
    working directory); the values of ``names`` at t_0 ... t_n from that CSV (6 decimals)."""
    import os

    import ecospy
    start, stop, step = experiment(ssp)
    binaries = Path(ecospy.__file__).parent / "binaries"
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    exe = folder / "ecos"  # the wheel installs it without the executable bit
    shutil.copy(binaries / "ecos", exe)
    exe.chmod(exe.stat().st_mode | stat.S_IXUSR)
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTHON")}
    env["LD_LIBRARY_PATH"] = str(binaries)
    proc = subprocess.run([str(exe), "simulate", "--path", str(ssp), "--startTime", repr(start), "--stepSize",
                           repr(step), "--stopTime", repr(stop), "--parameterSet", parameter_set, "--noParallel",
                           "--logLevel", "warn"], cwd=folder, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    (csv,) = folder.glob("*.csv")
    with open(csv) as f:
        header = [h.strip().split("[")[0].replace("::", ".") for h in f.readline().split(",")]
    data = np.loadtxt(csv, delimiter=",", skiprows=1)
    return data[:, [header.index(n) for n in names]]


def test_the_ecos_executable_runs_the_exported_ssp_writing_where_it_is_started(built, exported, tmp_path, request):
    """`ecos simulate --parameterSet NAME` in a folder of the user's choice; its CSV has 6
    decimals, so the commands (hundreds of N) are compared to 5e-7 N."""
    scenario, ssp, _, _ = exported
    got = run_ecos_executable(ssp, scenario.name, tmp_path / "ecos_out", COMMANDS)
    assert [p.name for p in (tmp_path / "ecos_out").glob("*.csv")] == [f"{ssp.stem}.csv"]  # named after the SSP
    ours = orchestrator_rows(built["ssp"], scenario, COMMANDS, "jacobi", clock="accumulated")
    assert got.shape == ours.shape == (2001, 3)
    assert np.abs(got - ours).max() <= 5.1e-7, np.abs(got - ours).max()  # N (the CSV's rounding)
    rest = orchestrator_rows(built["ssp"], scenario.with_changes(start_on_trajectory=False), COMMANDS,
                             "jacobi", clock="accumulated")
    assert np.abs(got - rest).max() > 1.0  # N: without the initial state the commands differ
    compatibility.record(
        request, tool="Ecos", version=compatibility.python_version("ecospy"), fmi="2.0", interface="SSP 1.0, CS",
        command=compatibility.export("build/TAPMP.ssp", "results/export/paper.ssp") + " && .venv/bin/python "
                "tests/interop/rows/ecos_simulate.py results/export/paper.ssp --stop-time 0.2 --parameter-set "
                "paper_simulation --out results/export/ecos",
        difference=compatibility.difference(compatibility.largest(got, ours), "N",
                                            "tapmp run, ordering=jacobi, clock=accumulated (6-decimal CSV)"))


# ---------------------------------------------------------------- FMPy simulate_ssp

def bound_parameter_set(ssp):
    """The SSP's parameter bindings as one fmpy ParameterSet of "element.variable" names:
    fmpy's reader parses the bindings, but simulate_ssp applies only its parameter_set argument."""
    from fmpy.ssp.ssd import Parameter, ParameterSet, read_ssd
    ssd = read_ssd(str(ssp))
    return ParameterSet(name="bound", parameters=[
        Parameter(name=f"{c.name}.{p.name}", type=p.type, value=p.value)
        for c in ssd.system.elements for b in c.parameterBindings for s in b.parameterValues for p in s.parameters])


def run_fmpy_ssp_exported(ssp, names):
    """simulate_ssp over the SSP's DefaultExperiment with its bound parameters; the values of
    ``names`` after each of its steps (2,001 for 0.2 s: the accumulated time stays below 0.2)."""
    from fmpy.ssp.simulation import simulate_ssp
    start, stop, step = experiment(ssp)
    result = simulate_ssp(str(ssp), start_time=start, stop_time=stop, step_size=step,
                          parameter_set=bound_parameter_set(ssp))
    return np.array([result[n] for n in names]).T


def test_fmpy_simulate_ssp_with_the_bound_parameter_set_is_bit_identical(built, exported, without_initial_state,
                                                                         request):
    scenario, ssp, _, _ = exported
    rows = run_fmpy_ssp_exported(ssp, NAMES)
    sc = scenario.with_changes(stop_time=scenario.stop_time + scenario.step)  # it runs 2,001 steps
    ours = orchestrator_rows(built["ssp"], sc, NAMES, "jacobi", clock="accumulated", connection_start="zero")
    assert rows.shape == (2001, 9)
    assert np.array_equal(rows, ours[1:]), dict(zip(NAMES, np.abs(rows - ours[1:]).max(axis=0)))
    assert_initial_state_matters(rows, without_initial_state, first=1)
    compatibility.record(
        request, tool="FMPy", version=compatibility.python_version("fmpy"), fmi="2.0", interface="SSP 1.0, CS",
        command=compatibility.export("build/TAPMP.ssp", "results/export/paper.ssp") + " && .venv/bin/python "
                "tests/interop/rows/fmpy_simulate_ssp.py results/export/paper.ssp --stop-time 0.2",
        difference=compatibility.difference(compatibility.largest(rows, ours[1:]), "", "tapmp run, ordering=jacobi, clock=accumulated, connection_start=zero"))


def test_fmpy_simulate_ssp_ignores_the_bindings_by_itself(exported):
    """Without the parameter_set argument simulate_ssp runs the FMUs on their start values: the
    plant starts on the paper's reference at 25 mm/s, so after one step it is 2.5 um along, not
    the exported scenario's 5 um (50 mm/s x 0.1 ms)."""
    from fmpy.ssp.simulation import simulate_ssp
    _, ssp, _, _ = exported
    bare = simulate_ssp(str(ssp), stop_time=2e-4, step_size=1e-4)
    bound = simulate_ssp(str(ssp), stop_time=2e-4, step_size=1e-4, parameter_set=bound_parameter_set(ssp))
    assert bound["plant.X"][0] == pytest.approx(2 * DEFAULT_DX0 * 1e-4, rel=0.01)
    assert bare["plant.X"][0] == pytest.approx(DEFAULT_DX0 * 1e-4, rel=0.01)


# ---------------------------------------------------------------- the container FMU

def run_container(container, ssp, values, names, out):
    """`fmpy simulate` on the container FMU with the exported start values, stop time and step;
    the values of ``names`` at t_0 ... t_n (fmpy writes shortest round-trip floats)."""
    _, stop, step = experiment(ssp)
    fmpy = Path(sys.executable).with_name("fmpy")
    proc = subprocess.run([str(fmpy), "simulate", str(container), "--stop-time", repr(stop),
                           "--output-interval", repr(step), "--start-values", *Path(values).read_text().split(),
                           "--output-variables", *names, "--output-file", str(out)],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    header = [n.strip('"') for n in Path(out).read_text().splitlines()[0].split(",")]
    data = np.loadtxt(out, delimiter=",", skiprows=1)
    return data[:, [header.index(n) for n in names]]


def test_fmpy_simulate_on_the_container_with_the_exported_start_values_is_bit_identical(
        built, exported, tmp_path, without_initial_state, request):
    scenario, ssp, values, _ = exported
    rows = run_container(built[CONTAINER], ssp, values, NAMES, tmp_path / "closed_loop.csv")
    ours = orchestrator_rows(built["ssp"], scenario, NAMES, "jacobi")
    assert rows.shape == ours.shape == (2001, 9)
    assert np.array_equal(rows, ours), dict(zip(NAMES, np.abs(rows - ours).max(axis=0)))
    assert_initial_state_matters(rows, without_initial_state)
    compatibility.record(
        request, tool="FMPy", version=compatibility.python_version("fmpy"), fmi="2.0", interface="CS (container FMU)",
        command=compatibility.export("build/TAPMP.ssp", "results/export/paper.ssp") + " && .venv/bin/fmpy simulate "
                "build/TAPMP_ClosedLoop.fmu --stop-time 0.2 --output-interval 0.0001 --start-values "
                "$(cat results/export/paper.start-values.txt)",
        difference=compatibility.difference(compatibility.largest(rows, ours), "", "tapmp run, ordering=jacobi"))


# ---------------------------------------------------------------- bad input

def _one_error_line(capsys):
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: "), err
    return err


def test_an_unknown_scenario_is_one_line_exit_2(built, tmp_path, capsys):
    assert main(["export", str(tmp_path / "nope.toml"), "--out", str(tmp_path / "x.ssp"),
                 "--ssp", str(built["ssp"])]) == 2
    line = _one_error_line(capsys)
    assert "nope.toml' is neither a file nor a shipped scenario" in line, line
    assert not (tmp_path / "x.ssp").exists()


def test_existing_output_is_refused_without_overwrite(built, tmp_path, capsys):
    out = tmp_path / "p.ssp"
    args = ["export", str(PAPER), "--out", str(out), "--ssp", str(built["ssp"])]
    assert main(args) == 0
    before = out.read_bytes()
    assert main(args + ["--set", "plant.k_pull=0"]) == 2
    assert f"{out} already exists: pass --overwrite" in _one_error_line(capsys)
    assert out.read_bytes() == before
    out.unlink()  # the start values alone also block
    assert main(args) == 2 and "start-values.txt already exists" in _one_error_line(capsys)
    assert main(args + ["--overwrite", "--set", "plant.k_pull=0"]) == 0
    assert "plant.k_pull 0.0" in out.with_suffix(".start-values.txt").read_text()


def test_a_family_that_is_not_built_is_one_line_exit_2(tmp_path, capsys, monkeypatch):
    missing = tmp_path / "build" / "native" / "fmi2" / "TAPMP.ssp"
    monkeypatch.setitem(families.FAMILIES, "native", missing)  # as on a fresh clone before build_fmus.sh
    assert main(["export", str(PAPER), "--out", str(tmp_path / "x.ssp"), "--fmus", "native"]) == 2
    err = _one_error_line(capsys)
    assert "native FMUs are not built" in err and "build_fmus.sh" in err


@pytest.mark.parametrize("out, message", [("x.zip", "allowed is a file name ending in .ssp")])
def test_an_output_name_without_ssp_suffix_is_refused(built, tmp_path, capsys, out, message):
    assert main(["export", str(PAPER), "--out", str(tmp_path / out), "--ssp", str(built["ssp"])]) == 2
    assert message in _one_error_line(capsys)


def test_a_source_that_is_no_ssp_is_named(tmp_path, capsys):
    bad = tmp_path / "bad.ssp"
    bad.write_text("not a zip")
    assert main(["export", str(PAPER), "--out", str(tmp_path / "x.ssp"), "--ssp", str(bad)]) == 2
    assert f"SSP file {bad} cannot be read" in _one_error_line(capsys)
