"""ModelStructure dependencies: every family's modelDescription.xml (pythonfmu, native FMI 2.0,
native FMI 3.0) and the container FMU's declare exactly tapmp.interface.dependencies, read back
with fmpy and with FMIL (fmil_check parse: no warning); and the declaration is what the FMUs
do: perturbing each known in Initialization Mode changes exactly the declared initial unknowns,
and no output follows an input set in Step Mode before doStep.
"""

import re
import subprocess
import zipfile
from collections import Counter
from pathlib import Path
from xml.etree import ElementTree as ET

import pytest
from fmpy import read_model_description

from tests.support.fmu_host import Host
from tests.support.fmil_gaps import fmil_messages, terminal_messages
from orchestrator.builder.build_native import state_derivative_dependencies
from tapmp.models import record
from orchestrator.builder.container import CONTAINER, container_dependencies
from tapmp.interface import CONTROLLER, FMU_NAMES, PLANT, TIME, TRAJECTORY, VARIABLES, dependencies
from tapmp.kinematics import inverse
from tapmp.params import DEFAULT_MODAL_GAINS

FMIL = Path(__file__).resolve().parents[3] / "shared" / "tools" / "fmil" / "fmil_check"
FAMILIES = ("python", "fmi2", "fmi3")


@pytest.fixture(scope="module")
def fmus(built, native_built):
    return {"python": built, "fmi2": native_built["fmi2"], "fmi3": native_built["fmi3"]}


def _declared(md, fmi3: bool) -> tuple[dict, dict]:
    """({output: knowns at communication points}, {initial unknown: knowns in Initialization
    Mode}) as fmpy reads them, by name."""
    def names(unknowns):
        return {u.variable.name: tuple(d.name for d in u.dependencies) for u in unknowns}
    return names(md.outputs), names(md.initialUnknowns)


def _expected(model: str, fmi3: bool) -> tuple[dict, dict]:
    keep = (lambda n: True) if fmi3 else (lambda n: n != TIME)  # FMI 2.0 FMUs declare no time
    deps = dependencies(model)
    order = {v.name: i for i, v in enumerate(VARIABLES[model], start=1)}
    order[TIME] = 0  # declared first (FMI 3.0)

    def ordered(names):
        return tuple(sorted((n for n in names if keep(n)), key=order.get))
    return ({o: ordered(d.step) for o, d in deps.items()}, {o: ordered(d.initial) for o, d in deps.items()})


@pytest.mark.parametrize("family", FAMILIES)
@pytest.mark.parametrize("model", FMU_NAMES)
def test_model_description_declares_the_interface(fmus, family, model):
    path = fmus[family][model]
    md = read_model_description(str(path))
    fmi3 = family == "fmi3"
    expected = _expected(model, fmi3)
    # the native plant's Model Exchange state derivatives (FMI 2.0 and 3.0): <Derivatives> or
    # <ContinuousStateDerivative>, and <InitialUnknowns>
    derivatives = state_derivative_dependencies(model) if family != "python" and record(model).me_states else {}
    expected[1].update({name: initial for name, (_, initial) in derivatives.items()})
    assert _declared(md, fmi3) == expected
    # the knowns in the FMU's own variable order (FMI 3.0 declares the forces F1..F3 before the states)
    assert {d.variable.name: sorted(k.name for k in d.dependencies) for d in md.derivatives} == {
        name: sorted(step) for name, (step, _) in derivatives.items()}
    root = ET.fromstring(zipfile.ZipFile(path).read("modelDescription.xml"))
    unknowns = root.find("ModelStructure").iter()
    listed = [u for u in unknowns if u.tag in ("Unknown", "Output", "InitialUnknown", "ContinuousStateDerivative")]
    assert len(listed) == 2 * sum(v.causality == "output" for v in VARIABLES[model]) + 2 * len(derivatives)
    for u in listed:  # every unknown says what it depends on; every listed known is "dependent"
        deps, kinds = u.get("dependencies"), u.get("dependenciesKind")
        assert deps is not None, ET.tostring(u)
        assert (kinds or "").split() == ["dependent"] * len(deps.split()), ET.tostring(u)


def test_no_output_depends_on_an_input_in_step_mode():
    """The definition itself: no direct feedthrough anywhere; the controller's initial outputs
    follow its inputs (computed from them in Initialization Mode), the plant's do not."""
    inputs = {m: {v.name for v in VARIABLES[m] if v.causality == "input"} for m in FMU_NAMES}
    for m in FMU_NAMES:
        for name, d in dependencies(m).items():
            assert not set(d.step) & inputs[m], (m, name)
    assert set(dependencies(CONTROLLER)["F1"].initial) >= inputs[CONTROLLER]
    assert all(not set(d.initial) & inputs[PLANT] for d in dependencies(PLANT).values())


def test_container_declares_the_closed_loop(built):
    """The container has no inputs: each output depends on time where the trajectory feeds it,
    and initially on the parameters that reach it through the connections."""
    md = read_model_description(str(built[CONTAINER]))
    expected = container_dependencies()
    order = {v.name: i for i, v in enumerate(md.modelVariables)}
    got_step, got_initial = _declared(md, True)
    assert got_step == {o: tuple(sorted(d.step, key=order.get)) for o, d in expected.items()}
    assert got_initial == {o: tuple(sorted(d.initial, key=order.get)) for o, d in expected.items()}
    assert got_step["trajectory.X_d"] == ("time",) and got_step["controller.F1"] == ()
    assert "plant.X0" in got_initial["controller.F1"] and "trajectory.radius" in got_initial["controller.F1"]


@pytest.mark.needs_shared("tools/fmil/fmil_check")
def test_fmil_parses_every_model_structure(fmus, built):
    """FMIL (the importer behind OpenModelica and PyFMI) reads every modelDescription with its
    dependencies without a warning. (What FMIL reads back: the test below.)"""
    paths = [str(fmus[f][m]) for f in FAMILIES for m in FMU_NAMES] + [str(built[CONTAINER])]
    proc = subprocess.run([str(FMIL), "parse", *paths], capture_output=True, text=True)
    # FMI 3.0: FMIL's messages on the valid terminalsAndIcons.xml only (tests/interop/test_fmil.py), exit 1
    fmi3 = [p for p in paths if p in {str(fmus["fmi3"][m]) for m in FMU_NAMES}]
    assert fmil_messages(proc.stderr) == sum((terminal_messages(p) for p in fmi3), Counter()), proc.stderr
    assert proc.returncode == (1 if fmi3 else 0), proc.stdout + proc.stderr
    assert proc.stdout.count("FMIL parse: 0 warnings, 0 errors") == len(paths) - len(fmi3), proc.stdout


FMIL_READER = Path(__file__).resolve().parent / "c_host" / "fmil_dependencies.c"
# The FMIL log lines of fmil_dependencies.c on a valid FMI 3.0 terminalsAndIcons.xml
FMIL_ON_TERMINALS_LOG = re.compile(
    r"\[FMIL FMI3XML\] (?:\[Line:\d+\] )?(?:Unknown element 'GraphicalRepresentation' in XML, skipping"
    r"|Skipping nested XML element '(?:CoordinateSystem|Icon)'|Attribute 'description' not processed by element "
    r"'Terminal' handle|Unknown attribute '(?:matchingRule|variableName|memberName|variableKind)=[^']*' in XML)")


@pytest.mark.needs_shared("tools/fmil/fmil_check")
def test_fmil_reads_the_declared_dependencies(fmus, built, tmp_path):
    """What FMIL 3.0.4 reads back (tests/fmu/c_host/fmil_dependencies.c on its API) equals the
    interface, with one limitation of FMIL's FMI 2.0 parser: a section (<Outputs> or
    <InitialUnknowns>) in which no unknown lists any known is read as "no dependency
    information" (fmi2_xml_zero_empty_dependencies), which is the case of every FMI 2.0 FMU's
    <Outputs> (no direct feedthrough, no independent variable declared); FMI 3.0 and the
    container (whose outputs list time) read back exactly."""
    include, lib = FMIL.parent / "include", FMIL.parent / "lib"
    exe = tmp_path / "fmil_dependencies"
    proc = subprocess.run(["gcc", "-std=c99", f"-I{include}", "-o", str(exe), str(FMIL_READER), f"-L{lib}",
                           "-lfmilib_shared", f"-Wl,-rpath,{lib}"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    cases = [(f, m, fmus[f][m]) for f in FAMILIES for m in FMU_NAMES] + [("container", CONTAINER, built[CONTAINER])]
    work = tmp_path / "unpacked"
    work.mkdir()
    proc = subprocess.run([str(exe), str(work), *(str(p) for _, _, p in cases)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    # FMIL's messages on the FMI 3.0 terminalsAndIcons.xml only (tests/interop/test_fmil.py)
    assert all(FMIL_ON_TERMINALS_LOG.fullmatch(line) for line in proc.stderr.splitlines()), proc.stderr
    read = {}
    for line in proc.stdout.splitlines():
        head, _, deps = line.partition(":")
        path, kind, name = head.rsplit(" ", 2)
        read.setdefault(path, {}).setdefault(kind, {})[name] = tuple(deps.split())
    container = container_dependencies()
    for family, model, path in cases:
        if family == "container":
            step = {o: tuple(sorted(d.step)) for o, d in container.items()}
            initial = {o: tuple(sorted(d.initial)) for o, d in container.items()}
            got = {k: {o: tuple(sorted(v)) for o, v in read[str(path)][k].items()} for k in "OI"}
        else:
            step, initial = _expected(model, family == "fmi3")
            if family in ("fmi2", "fmi3") and record(model).me_states:  # the Model Exchange state derivatives
                initial = {**initial, **{n: i for n, (_, i) in state_derivative_dependencies(model).items()}}
            got = read[str(path)]
        for kind, expected in (("O", step), ("I", initial)):
            if family in ("python", "fmi2") and not any(expected.values()):
                assert set(got[kind].values()) == {("ALL",)}, (family, model, kind)  # FMIL's limitation
            else:
                assert got[kind] == expected, (family, model, kind)


# --- what the FMUs do -----------------------------------------------------------------
REF = {"X_d": 1e-3, "Z_d": 2e-3, "B_d": 0.01, "dX_d": 0.02, "dZ_d": -0.01, "dB_d": 0.1,
       "ddX_d": 0.5, "ddZ_d": -0.3, "ddB_d": 2.0}
_Q = inverse(REF["X_d"], REF["Z_d"], REF["B_d"], 0.3)
CONTROLLER_POINT = {**REF, "q1": _Q[0] + 1e-5, "q2": _Q[1] - 2e-5, "q3": _Q[2] + 3e-5,
                    "dq1": 0.01, "dq2": 0.02, "dq3": -0.01}
PLANT_POINT = {"X0": 1e-3, "Z0": 2e-3, "B0": 0.01, "dX0": 0.01, "dZ0": 0.02, "dB0": 0.1, "noise_rms": 1e-6,
               "encoder_resolution": 0.0,  # so that a small change of noise_rms shows
               "F1": 1.0, "F2": -2.0, "F3": 3.0}


# Declared inputs that an output reads but that cancel in exact arithmetic, so a perturbation may
# move the output by round-off only: X_d in es_i = e_i - e_(i+1) (both e hold X_d, Eq. 2), and
# dZ_d in motor 2's command (motors 1 and 3 see +-dZ_d / sqrt(3): it leaves the modal means and c).
CANCELLING = {**{f"es{i}": {"X_d"} for i in (1, 2, 3)}, "F2": {"dZ_d"}, "u2": {"dZ_d"}}


def _perturbed(name: str, value, integer: bool):
    if name == "law":
        return (value + 1) % 3
    if integer:
        return 1 - value if name == "velocity_source" else value + 1
    if name == "force_limit":
        return 1e-3  # from 0 (no limit): every command is limited
    return value * (1 + 1e-3) if value else 1e-3


def _observed(path, tmp_path, model: str, point: dict, base: dict = {}) -> dict:  # noqa: B006
    """{initial unknown: knowns whose perturbation (one at a time, in Initialization Mode)
    changes it} for the FMU at ``path``, around ``point`` with parameters ``base``."""
    table = [v for v in VARIABLES[model] if v.causality in ("input", "parameter")]
    outputs = [v.name for v in VARIABLES[model] if v.causality == "output"]
    u = Host(path, tmp_path / f"{model}_{sorted(base.items())}_unzip".replace(" ", ""), "probe")
    try:
        u.set(base)
        u.enter_initialization()
        u.set(point)
        values = {v.name: point.get(v.name, base.get(v.name, v.start)) for v in table}
        y0 = u.get(outputs)
        found = {o: set() for o in outputs}
        for v in table:
            u.set({v.name: _perturbed(v.name, values[v.name], v.type == "Integer")})
            y = u.get(outputs)
            u.set({v.name: values[v.name]})
            assert u.get(outputs) == y0, v.name
            for o, a, b in zip(outputs, y0, y):
                if a != b:
                    found[o].add(v.name)
        assert u.errors() == []
        return found
    finally:
        u.close()


@pytest.mark.parametrize("family", ("python", "fmi2"))
def test_controller_initial_outputs_depend_on_exactly_the_declared_knowns(fmus, tmp_path, family):
    """Over the three laws, the knowns that move each initial output are the declared ones:
    none missing (nothing an importer is not told) and none extra but the inputs that cancel
    to round-off (CANCELLING)."""
    union = {}
    # PID-DC with different common and differential gains: K = k_c Pi_c + k_d Pi_d couples the motors
    pid = {"law": 2, "kp_c": 2 * DEFAULT_MODAL_GAINS["kp_c"], "kv_c": 2 * DEFAULT_MODAL_GAINS["kv_c"]}
    for base in ({"law": 0}, {"law": 1}, pid):
        for o, knowns in _observed(fmus[family][CONTROLLER], tmp_path, CONTROLLER, CONTROLLER_POINT,
                                   base).items():
            union.setdefault(o, set()).update(knowns)
    for o, d in dependencies(CONTROLLER).items():
        assert union[o] <= set(d.initial), (o, union[o] - set(d.initial))
        assert set(d.initial) - union[o] <= CANCELLING.get(o, set()), (o, set(d.initial) - union[o])


@pytest.mark.parametrize("family", ("python", "fmi2"))
def test_plant_initial_outputs_depend_on_exactly_the_declared_knowns(fmus, tmp_path, family):
    found = _observed(fmus[family][PLANT], tmp_path, PLANT, PLANT_POINT)
    assert found == {o: set(d.initial) for o, d in dependencies(PLANT).items()}


@pytest.mark.parametrize("family", ("python", "fmi3"))
def test_trajectory_initial_outputs_depend_on_declared_knowns_and_time(fmus, tmp_path, family):
    """The trajectory's declaration is a superset by design (every trajectory parameter):
    nothing outside it moves an output, and the start time moves every one of them."""
    found = _observed(fmus[family][TRAJECTORY], tmp_path, TRAJECTORY, {})
    declared = dependencies(TRAJECTORY)
    for o, knowns in found.items():
        assert knowns <= set(declared[o].initial), o
        assert TIME in declared[o].initial and TIME in declared[o].step
    moved = []
    for t0 in (0.0, 0.0123):
        u = Host(fmus[family][TRAJECTORY], tmp_path / f"t{t0}", "t")
        u.enter_initialization(t0)
        moved.append(u.get(list(declared)))
        u.close()
    assert all(a != b for a, b in zip(*moved))


@pytest.mark.parametrize("family", FAMILIES)
def test_outputs_do_not_follow_inputs_before_do_step(fmus, tmp_path, family):
    """Step Mode: setting every input changes no output until doStep (no direct feedthrough)."""
    for model, point in ((CONTROLLER, CONTROLLER_POINT), (PLANT, PLANT_POINT)):
        u = Host(fmus[family][model], tmp_path / f"{model}_step", "s")
        outputs = [v.name for v in VARIABLES[model] if v.causality == "output"]
        inputs = {v.name: point[v.name] for v in VARIABLES[model] if v.causality == "input"}
        u.enter_initialization()
        u.fmu.exitInitializationMode()
        y0 = u.get(outputs)
        u.set(inputs)
        assert u.get(outputs) == y0, (family, model)
        u.close()
