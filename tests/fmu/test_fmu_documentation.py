"""What every native FMU carries for a user who has only the FMU: an FMI-LS-REF manifest and
FMI 3.0 terminals valid against the standard's schemas (../shared/schemas, remote schema
addresses resolved to those files), the paper scenario's parameter set, a reference experiment
that fmusim and FMPy replay, documentation/index.html that headless Chromium renders with every
image, and the license."""

import subprocess
import zipfile
from pathlib import Path

import numpy as np
import pytest
from tests.support.runs import PAPER
from tests.support.shared import ROOT, shared

from orchestrator.builder import fmu_extras
from orchestrator.builder.fmu_extras import LS_REF, SCENARIO
from tapmp.interface import ELEMENT, FMU_NAMES, VARIABLES

pytestmark = pytest.mark.slow  # builds the native FMUs; runs fmusim and Chromium
FAMILIES = ("fmi2", "fmi3")
CASES = [(f, m) for f in FAMILIES for m in FMU_NAMES]


@pytest.fixture(scope="module")
def host_built(tmp_path_factory):
    """The native FMUs with this machine's binary only (what the extras need is the same)."""
    from orchestrator.builder.build_native import build_native
    return build_native(tmp_path_factory.mktemp("native_host"), log=lambda *_: None, windows=False)


def member(fmu, name) -> bytes:
    with zipfile.ZipFile(fmu) as z:
        return z.read(name)


def schema(path: Path):
    """The XSD at ``path`` with the remote addresses of the FMI schemas resolved to the files in
    ../shared/schemas/fmi3."""
    from lxml import etree

    fmi3 = shared("schemas/fmi3")

    class Local(etree.Resolver):
        def resolve(self, url, pubid, context):
            if url.startswith("https://") and url.endswith(".xsd"):
                return self.resolve_filename(str(fmi3 / url.rsplit("/", 1)[1]), context)
            return None

    parser = etree.XMLParser()
    parser.resolvers.add(Local())
    return etree.XMLSchema(etree.parse(str(path), parser))


def assert_valid(xsd, data: bytes):
    from lxml import etree
    doc = etree.fromstring(data)
    assert xsd.validate(doc), xsd.error_log


@pytest.mark.needs_shared("schemas/fmi-ls-ref/fmi3LayeredStandardReferenceManifest.xsd")
def test_every_native_fmus_ls_ref_manifest_is_valid_and_names_files_the_fmu_has(host_built):
    xsd = schema(shared("schemas/fmi-ls-ref/fmi3LayeredStandardReferenceManifest.xsd"))
    for family, model in CASES:
        fmu = host_built[family][model]
        data = member(fmu, f"{LS_REF}/fmi-ls-manifest.xml")
        assert_valid(xsd, data)
        from xml.etree import ElementTree as ET
        with zipfile.ZipFile(fmu) as z:
            names = set(z.namelist())
        roles = {}
        for r in ET.fromstring(data).iter("Related"):
            target = str(Path(LS_REF, r.get("source")).resolve().relative_to(Path(LS_REF).resolve().parents[1]))
            assert target in names, (family, model, target)
            roles.setdefault(r.get("role"), []).append(r.get("source"))
        assert roles["parameter"] == [f"{SCENARIO}.ssv"] and roles["result"] == [f"{SCENARIO}_ref.csv"]
        assert (f"{SCENARIO}_in.csv" in roles["experiment/validation"]) == (model != "TAPMP_Trajectory")


@pytest.mark.needs_shared("schemas/fmi3/fmi3TerminalsAndIcons.xsd")
def test_fmi3_terminals_are_valid_and_group_each_motor_and_the_pose(host_built):
    from xml.etree import ElementTree as ET
    xsd = schema(shared("schemas/fmi3/fmi3TerminalsAndIcons.xsd"))
    for model in FMU_NAMES:
        fmu = host_built["fmi3"][model]
        data = member(fmu, "terminalsAndIcons/terminalsAndIcons.xml")
        assert_valid(xsd, data)
        terminals = {t.get("name"): [m.get("variableName") for m in t] for t in ET.fromstring(data).iter("Terminal")}
        signals = [v.name for v in VARIABLES[model] if v.causality != "parameter"]
        assert sorted(n for ms in terminals.values() for n in ms) == sorted(signals)  # each signal once
        assert set(terminals) == ({"motor1", "motor2", "motor3", "pose"})
        assert member(fmu, "terminalsAndIcons/icon.png")[:8] == b"\x89PNG\r\n\x1a\n"
        assert b"<svg" in member(fmu, "terminalsAndIcons/icon.svg")


@pytest.mark.needs_shared("schemas/fmi3/fmi3ModelDescription.xsd")
def test_fmi3_model_descriptions_are_valid_against_the_schema(host_built):
    xsd = schema(shared("schemas/fmi3/fmi3ModelDescription.xsd"))
    for model in FMU_NAMES:
        assert_valid(xsd, member(host_built["fmi3"][model], "modelDescription.xml"))


def test_the_parameter_set_is_the_paper_scenario_and_every_fmu_parameter(host_built):
    """Each FMU's .ssv holds every parameter at its start value; those are the values
    scenarios/paper_simulation.toml gives (parsed by FMPy's SSV reader)."""
    from fmpy.ssp.ssd import read_ssv

    from orchestrator.tool.scenario import load
    scenario = load(PAPER).parameters()
    for family, model in CASES:
        path = Path(host_built[family][model]).with_suffix(".ssv")
        path.write_bytes(member(host_built[family][model], f"{LS_REF}/{SCENARIO}.ssv"))
        ssv = read_ssv(str(path), validate=True)
        values = {p.name: float(p.value) for p in ssv.parameters}
        assert set(values) == {v.name for v in VARIABLES[model] if v.causality == "parameter"}
        for name, value in scenario[ELEMENT[model]].items():
            assert values[name] == value, (model, name)


def test_the_stimulus_is_what_the_fmus_receive_in_the_paper_closed_loop():
    """closed_loop_stimulus from the defaults equals tapmp.closed_loop on the paper scenario's
    own models: the plant's commands are the ones the Gauss-Seidel loop applies."""
    from orchestrator.tool.scenario import load
    from tapmp.closed_loop import simulate

    plant, ctrl, traj = load(PAPER).plain_models()
    applied = []
    simulate(plant, ctrl, traj, 0.0, 20, 1e-4, "gauss-seidel", record=lambda t, ref, F, q, qt: applied.append(F))
    stimulus = fmu_extras.closed_loop_stimulus(20)
    assert [tuple(r[1:]) for r in stimulus["TAPMP_Plant"][:20]] == [tuple(F) for F in applied[1:]]
    assert max(abs(x) for r in stimulus["TAPMP_Plant"] for x in r[1:]) > 1.0  # N


def reference_files(fmu, folder: Path, model):
    folder.mkdir(parents=True, exist_ok=True)
    out = {}
    for suffix in ("_ref.csv", "_in.csv"):
        name = f"{LS_REF}/{SCENARIO}{suffix}"
        if suffix == "_in.csv" and model == "TAPMP_Trajectory":
            continue
        out[suffix] = folder / f"{SCENARIO}{suffix}"
        out[suffix].write_bytes(member(fmu, name))
    return out


def assert_reproduces(got_names, got_rows, ref_names, ref_rows, tolerance):
    got, ref = np.array(got_rows), np.array(ref_rows)
    assert got.shape == ref.shape, (got.shape, ref.shape)
    for j, name in enumerate(ref_names):
        k = got_names.index(name)
        scale = max(np.abs(ref[:, j]).max(), 1e-300)
        assert np.abs(got[:, k] - ref[:, j]).max() <= tolerance * scale, (name, np.abs(got[:, k] - ref[:, j]).max())


@pytest.mark.parametrize("family,model", CASES)
def test_fmpy_replays_each_reference_experiment_exactly(host_built, family, model, tmp_path):
    from fmpy import simulate_fmu
    from fmpy.util import read_csv

    fmu = host_built[family][model]
    files = reference_files(fmu, tmp_path, model)
    ref_names, ref_rows = fmu_extras.read_csv(files["_ref.csv"].read_bytes())
    res = simulate_fmu(str(fmu), stop_time=fmu_extras.REFERENCE_STOP, step_size=1e-4, output_interval=1e-4,
                       input=read_csv(str(files["_in.csv"])) if "_in.csv" in files else None)
    names = list(res.dtype.names)
    assert_reproduces(names, [list(r) for r in res], ref_names, ref_rows, 0.0)  # the same doubles


@pytest.mark.interop
@pytest.mark.needs_shared("tools/fmusim/bin/fmusim")
@pytest.mark.parametrize("family,model", CASES)
def test_fmusim_replays_each_reference_experiment(host_built, family, model, tmp_path):
    """fmusim interpolates the stimulus itself and prints 16 significant digits: within 1e-9 of
    each output's largest value."""
    fmu = host_built[family][model]
    files = reference_files(fmu, tmp_path, model)
    out = tmp_path / "out.csv"
    cmd = [str(shared("tools/fmusim/bin/fmusim")), "--interface-type", "cs", "--stop-time",
           repr(fmu_extras.REFERENCE_STOP), "--output-interval", "1e-4", "--output-file", str(out)]
    if "_in.csv" in files:
        cmd += ["--input-file", str(files["_in.csv"])]
    proc = subprocess.run([*cmd, str(fmu)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    names, rows = fmu_extras.read_csv(out.read_bytes())
    ref_names, ref_rows = fmu_extras.read_csv(files["_ref.csv"].read_bytes())
    assert_reproduces(names, rows, ref_names, ref_rows, 1e-9)


def test_documentation_lists_every_variable_and_the_license_is_the_repositorys(host_built):
    for family, model in CASES:
        fmu = host_built[family][model]
        page = member(fmu, "documentation/index.html").decode()
        for v in VARIABLES[model]:
            assert f"<code>{v.name}</code>" in page, (model, v.name)
        assert "FMI 2.0" in page if family == "fmi2" else "FMI 3.0" in page
        assert member(fmu, "documentation/licenses/license.txt") == (ROOT / "LICENSE").read_bytes()


@pytest.mark.slow  # starts chromium twice; the fast subset's run of tests/run.sh does not install it
def test_documentation_renders_in_headless_chromium_with_every_image(host_built, tmp_path):
    """Chromium prints the page's DOM after load: every <img> has its natural size (an image
    that is missing or broken has naturalWidth 0), and the screenshot is not blank."""
    fmu = host_built["fmi3"]["TAPMP_Plant"]
    with zipfile.ZipFile(fmu) as z:
        z.extractall(tmp_path / "fmu")
    page = tmp_path / "fmu" / "documentation" / "index.html"
    check = tmp_path / "fmu" / "documentation" / "check.html"
    check.write_text(page.read_text().replace(
        "</body>", "<script>window.addEventListener('load', () => { document.title = 'images:' + "
        "Array.from(document.images).map(i => i.naturalWidth).join(','); });</script></body>"))
    flags = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
             "--disable-component-update", "--disable-sync", "--user-data-dir=" + str(tmp_path / "profile")]
    dom = subprocess.run(["chromium", *flags, "--virtual-time-budget=5000", "--dump-dom", check.as_uri()],
                         capture_output=True, text=True, timeout=120)
    title = dom.stdout.split("<title>")[1].split("</title>")[0]
    widths = [int(w) for w in title.removeprefix("images:").split(",")]
    assert title.startswith("images:") and widths and all(w > 0 for w in widths), title
    shot = tmp_path / "shot.png"
    subprocess.run(["chromium", *flags, f"--screenshot={shot}", "--window-size=1000,1400", page.as_uri()],
                   capture_output=True, timeout=120, check=True)
    import matplotlib.image
    pixels = matplotlib.image.imread(str(shot))
    assert pixels.shape[:2] == (1400, 1000) and pixels[..., :3].std() > 0.05  # text and the diagram


# --- the clocked controller (TAPMP_ControllerClocked.fmu) carries the same --------------------------

CLOCKED = "TAPMP_ControllerClocked"


@pytest.mark.needs_shared("schemas/fmi-ls-ref/fmi3LayeredStandardReferenceManifest.xsd",
                          "schemas/fmi3/fmi3TerminalsAndIcons.xsd")
def test_the_clocked_controllers_manifest_and_terminals_are_valid_and_name_its_files(host_built):
    from xml.etree import ElementTree as ET
    fmu = host_built["fmi3"][CLOCKED]
    data = member(fmu, f"{LS_REF}/fmi-ls-manifest.xml")
    assert_valid(schema(shared("schemas/fmi-ls-ref/fmi3LayeredStandardReferenceManifest.xsd")), data)
    with zipfile.ZipFile(fmu) as z:
        names = set(z.namelist())
    roles = {}
    for r in ET.fromstring(data).iter("Related"):
        assert str(Path(LS_REF) / r.get("source")).replace(f"{LS_REF}/../../", "") in names, r.get("source")
        roles.setdefault(r.get("role"), []).append(r.get("source"))
    assert roles["experiment/validation"] == [f"{SCENARIO}_in.csv", f"{SCENARIO}_ticks.csv", f"{SCENARIO}_ref.opt"]
    assert roles["result"] == [f"{SCENARIO}_ref.csv"] and roles["parameter"] == [f"{SCENARIO}.ssv"]
    terminals = member(fmu, "terminalsAndIcons/terminalsAndIcons.xml")
    assert_valid(schema(shared("schemas/fmi3/fmi3TerminalsAndIcons.xsd")), terminals)
    assert terminals == member(host_built["fmi3"]["TAPMP_Controller"], "terminalsAndIcons/terminalsAndIcons.xml")
    assert member(fmu, "terminalsAndIcons/icon.png")[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_clocked_controllers_reference_results_are_the_event_mode_controllers(host_built):
    """Ticked at every communication point, the clocked controller's expected outputs are the same doubles as
    those of TAPMP_Controller.fmu stepped by FMPy's simulate_fmu on the same stimulus; its tick schedule is
    every stimulus time but the last."""
    clocked, plain = host_built["fmi3"][CLOCKED], host_built["fmi3"]["TAPMP_Controller"]
    for name in (f"{SCENARIO}_ref.csv", f"{SCENARIO}_in.csv", f"{SCENARIO}.ssv", f"{SCENARIO}_ref.opt"):
        assert member(clocked, f"{LS_REF}/{name}") == member(plain, f"{LS_REF}/{name}"), name
    _, stimulus = fmu_extras.read_csv(member(clocked, f"{LS_REF}/{SCENARIO}_in.csv"))
    header, ticks = fmu_extras.read_csv(member(clocked, f"{LS_REF}/{SCENARIO}_ticks.csv"))
    assert header == ["time", "sample_clock"]
    assert [t for t, _ in ticks] == [r[0] for r in stimulus[:-1]] and {a for _, a in ticks} == {1.0}


def test_the_clocked_controllers_documented_fmpy_replay_gives_its_reference_results(host_built, tmp_path):
    """The FMPy code on the FMU's documentation page, run as it stands there in the FMU's folder, ticks the
    clock by the schedule and prints that its result equals the expected outputs."""
    import html
    import shutil
    import sys
    page = member(host_built["fmi3"][CLOCKED], "documentation/index.html").decode()
    code = html.unescape(page.split("<pre>")[1].split("</pre>")[0])
    assert code == fmu_extras.REPLAY_PY
    shutil.copy(host_built["fmi3"][CLOCKED], tmp_path / f"{CLOCKED}.fmu")
    (tmp_path / "replay.py").write_text(code)
    done = subprocess.run([sys.executable, "replay.py"], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout == "equal to the reference results: True\n"


def test_the_clocked_controllers_documentation_says_how_to_tick_it(host_built):
    fmu = host_built["fmi3"][CLOCKED]
    page = member(fmu, "documentation/index.html").decode()
    assert f"<h1>{CLOCKED}</h1>" in page and "<h2>The input clock</h2>" in page
    for v in VARIABLES["TAPMP_Controller"]:
        assert f"<code>{v.name}</code>" in page, v.name
    for call in ("fmi3SetClock", "fmi3UpdateDiscreteStates", "eventModeUsed", "examples/clocked_fmpy_host.py"):
        assert call in page, call
    assert member(fmu, "documentation/licenses/license.txt") == (ROOT / "LICENSE").read_bytes()
