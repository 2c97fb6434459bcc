"""What a native FMU carries besides its model, for a user who has only the FMU: the paper's
simulation as a reference experiment (FMI-LS-REF), its documentation with a diagram, the license,
and for FMI 3.0 its terminals and icon.

Inside every native FMU (``build_native.build_native_fmu`` adds :func:`extra_members`):

* ``extra/org.fmi-standard.fmi-ls-ref/fmi-ls-manifest.xml``: the FMI-LS-REF manifest listing
  the files below with their roles;
* beside it ``paper_simulation.ssv`` (the paper scenario's parameter set: every parameter of the
  FMU at its start value, since the defaults are that scenario), ``paper_simulation_in.csv`` (the
  input stimulus, for the FMUs with inputs), ``paper_simulation_ref.csv`` (the expected outputs at
  every communication point) and ``paper_simulation_ref.opt`` (start, stop, step, tolerance);
  the experiment is the first REFERENCE_STOP = 10 ms of the paper's closed loop at the 0.1 ms
  servo step, the stimulus what the FMU received in it (Gauss-Seidel ordering);
* ``documentation/index.html`` with ``documentation/diagram.svg`` and
  ``documentation/licenses/license.txt`` (the repository's MIT license);
* FMI 3.0: ``terminalsAndIcons/terminalsAndIcons.xml`` (one terminal per motor, one for the
  pose), ``terminalsAndIcons/icon.svg`` and ``icon.png``.

The stimulus comes from the Python binding of the one C model (the same doubles as every FMU);
the expected outputs from the built FMU itself, run alone on that stimulus by FMPy, so they are
what any importer replaying the experiment must get.
"""

import html
import io
from pathlib import Path
from xml.etree import ElementTree as ET

from tapmp.interface import (CONTROLLER, DEFAULT_EXPERIMENT, ELEMENT, INITIAL_STATE, PLANT, TRAJECTORY, UNITS, VARIABLES,
                             allowed_text)
from tapmp.models import CLOCKED, DRIVE, record, system_models
from tapmp.records import CLOCK_NAME
from tapmp.params import SERVO_STEP
from tapmp import laws

from .model_description import to_bytes
from .ssp import qname

TEMPLATES = Path(__file__).resolve().with_name("templates")  # the HTML and SVG templates (package data)

LS_REF = "extra/org.fmi-standard.fmi-ls-ref"
LS_NS = "http://fmi-standard.org/fmi-ls-manifest"
SSV = "http://ssp-standard.org/SSP1/SystemStructureParameterValues"
SSC = "http://ssp-standard.org/SSP1/SystemStructureCommon"
SCENARIO = "paper_simulation"
REFERENCE_STOP = 0.01  # s: 100 servo steps, so the FMU stays small (the CSVs are a few tens of kB)
REFERENCE_STEPS = 100
RELATIVE_TOLERANCE = 1e-10  # of the reference experiment (.opt): for a Model Exchange solver; CS ignores it
LICENSE_FILE = "documentation/licenses/license.txt"


def value_text(kind: str, value) -> str:
    """A value as SSV/CSV text that reads back to the same number (repr: shortest round trip)."""
    if kind == "Integer":
        return str(int(value))
    if kind == "Boolean":
        return "true" if value else "false"
    return repr(float(value))


def parameter_set(name: str, values: dict, declared: dict, units: dict, element: str) -> bytes:
    """One SSV document: ParameterSet ``name`` with ``values`` ({variable: value}) typed and
    with units as ``declared`` ({variable: (SSV type, unit)}) by the element's FMU; ValueError
    names a variable the FMU does not declare."""
    root = ET.Element(qname(SSV, "ParameterSet"), version="1.0", name=name)
    params = ET.SubElement(root, qname(SSV, "Parameters"))
    used = []
    for var, value in values.items():
        if var not in declared:
            raise ValueError(f"{element}.{var} = {value!r} cannot be exported: the {element} FMU has no "
                             f"parameter {var}; allowed are {', '.join(sorted(declared))}")
        kind, unit = declared[var]
        p = ET.SubElement(params, qname(SSV, "Parameter"), name=var)
        attrs = {"value": value_text(kind, value)}
        if kind == "Real" and unit in units:
            attrs["unit"] = unit
            used.append(unit)
        ET.SubElement(p, qname(SSV, kind), attrs)
    if used:
        table = ET.SubElement(root, qname(SSV, "Units"))
        for unit in sorted(set(used)):
            u = ET.SubElement(table, qname(SSC, "Unit"), name=unit)
            ET.SubElement(u, qname(SSC, "BaseUnit"), {k: str(e) for k, e in units[unit].items()})
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def default_parameter_set(model: str) -> bytes:
    """The paper scenario's parameter set of ``model``: every parameter at its start value."""
    table = [v for v in VARIABLES[model] if v.causality == "parameter"]
    declared = {v.name: ("Integer" if v.type == "Integer" else "Real", v.unit) for v in table}
    return parameter_set(SCENARIO, {v.name: v.start for v in table}, declared, UNITS, ELEMENT[model])


def inputs(model: str) -> list[str]:
    """The input names of ``model`` in the order of its variables."""
    return [v.name for v in VARIABLES[model] if v.causality == "input"]


def outputs(model: str) -> list[str]:
    """The output names of ``model`` in the order of its variables."""
    return [v.name for v in VARIABLES[model] if v.causality == "output"]


def closed_loop_stimulus(steps: int = REFERENCE_STEPS, h: float = SERVO_STEP) -> dict[str, list[tuple]]:
    """{model: rows (t, input values...)}: what each FMU receives at the communication points
    t_k = k h [s], k = 0 ... steps, in the paper's closed loop from the FMUs' defaults in the
    Gauss-Seidel ordering (controller, plant, trajectory; tapmp.closed_loop): the controller
    the reference and the measurement at t_k, the plant the command of the step from t_k. The
    plant's last row repeats its command (no step follows it); the drive's inputs are the plant's of this loop
    (the controller's commands)."""
    from tapmp.control import ControllerModel, Gains, ModalGains
    from tapmp.params import GAIN_PRESETS, ModelParams
    from tapmp.plant import PlantConfig, PlantModel
    from tapmp.trajectory import TrajectoryParams, reference

    start = {m: {v.name: v.start for v in VARIABLES[m]} for m in VARIABLES}
    plant_start, ctrl = start[PLANT], start[CONTROLLER]
    plant = PlantModel(ModelParams(**{n: plant_start[n] for n in ModelParams._fields}),
                       PlantConfig(**{n: plant_start[n] for n in PlantConfig._fields}),
                       INITIAL_STATE[:3], INITIAL_STATE[3:])
    gains = Gains.from_preset({n: tuple(ctrl[f"{n}{i}"] for i in (1, 2, 3)) for n in Gains._fields})
    controller = ControllerModel(ModelParams(**{n: ctrl[n] for n in ModelParams._fields}), gains,
                                 int(ctrl["law"]), int(ctrl["velocity_source"]), ctrl["force_limit"],
                                 ModalGains(**{n: ctrl[n] for n in ModalGains._fields}), ctrl["T_s"], 0.0,
                                 int(ctrl["anti_windup"]), ctrl["anti_windup_time"])
    assert gains == Gains.from_preset(GAIN_PRESETS["default"])
    traj = TrajectoryParams(**{n: start[TRAJECTORY][n] for n in TrajectoryParams._fields})
    ref = reference(0.0, traj)
    q, dq = plant.measured_positions(), plant.joint_velocities()
    F = controller.sample(0.0, h, ref, q, dq, advance=False)[0]
    rows = {CONTROLLER: [], PLANT: []}
    for k in range(steps):
        t = k * h
        rows[CONTROLLER].append((t, *ref, *q, *dq))
        sampled = controller.communication_point(t, h, ref, q, dq)[0]
        if sampled is not None:
            F = sampled[0]
        rows[PLANT].append((t, *F))
        plant.step(t, h, *F)
        ref = reference(t + h, traj)  # t + h as tapmp.closed_loop (not (k + 1) h: another rounding)
        q, dq = plant.measured_positions(), plant.joint_velocities()
    rows[CONTROLLER].append((steps * h, *ref, *q, *dq))
    rows[PLANT].append((steps * h, *F))
    rows[DRIVE] = list(rows[PLANT])  # the drive's inputs are the controller's commands
    return rows


def csv_text(names, rows) -> bytes:
    """A CSV of ``rows`` under the header time,NAMES... (shortest round-trip numbers)."""
    lines = [",".join(["time", *names])]
    lines += [",".join(repr(float(x)) for x in row) for row in rows]
    return ("\n".join(lines) + "\n").encode()


def read_csv(data: bytes) -> tuple[list[str], list[list[float]]]:
    """(header names, rows of floats) of a CSV written by :func:`csv_text`."""
    lines = data.decode().strip().splitlines()
    return ([n.strip().strip('"') for n in lines[0].split(",")],
            [[float(x) for x in line.split(",")] for line in lines[1:]])


def options_text(stop: float = REFERENCE_STOP, step: float = SERVO_STEP) -> bytes:
    """The experiment's options in the FMI Cross-Check's ``_ref.opt`` form."""
    return (f"StartTime, {DEFAULT_EXPERIMENT['startTime']!r}\nStopTime, {stop!r}\nStepSize, {step!r}\n"
            f"RelTol, {RELATIVE_TOLERANCE!r}\n").encode()


def expected_outputs(fmu: Path, model: str, stimulus_rows, steps: int = REFERENCE_STEPS,
                     h: float = SERVO_STEP) -> list[tuple]:
    """The outputs of ``fmu`` run alone by FMPy on ``stimulus_rows`` (None: no inputs) from
    0 to steps h [s] at the step h: rows (t, outputs...) at every communication point."""
    import numpy as np
    from fmpy import simulate_fmu

    signals = None
    if stimulus_rows is not None:
        names = inputs(model)
        signals = np.array([tuple(r) for r in stimulus_rows], dtype=[("time", float)] + [(n, float) for n in names])
    res = simulate_fmu(str(fmu), start_time=0.0, stop_time=steps * h, step_size=h, output_interval=h,
                       input=signals, output=outputs(model), validate=False)
    if len(res) != steps + 1:
        raise RuntimeError(f"{fmu}: FMPy returned {len(res)} rows for the reference experiment, not {steps + 1}")
    return [(k * h, *(float(res[n][k]) for n in outputs(model))) for k in range(steps + 1)]


def manifest(model: str) -> bytes:
    """extra/org.fmi-standard.fmi-ls-ref/fmi-ls-manifest.xml of ``model`` (FMI-LS-REF 1.0.0-alpha.1)."""
    ET.register_namespace("fmi-ls", LS_NS)
    root = ET.Element("fmiReferences", {
        qname(LS_NS, "fmi-ls-name"): "org.fmi-standard.fmi-ls-ref",
        qname(LS_NS, "fmi-ls-version"): "1.0.0-alpha.1",
        qname(LS_NS, "fmi-ls-description"): "Layered Standard providing information on related files included in an FMU."})
    label = ("scenario:paper_simulation", "the paper's simulation (Section 5.2), scenarios/paper_simulation.toml")

    def related(kind, source, role, description):
        r = ET.SubElement(root, "Related", type=kind, source=source, role=role, description=description)
        if role != "document":
            ET.SubElement(r, "Label", name=label[0], description=label[1])

    related("text/html", "../../documentation/index.html", "document",
            "What the model is, its equations with the paper's numbers, every variable, how to run it")
    related("application/x-ssp-parameter-set", f"{SCENARIO}.ssv", "parameter",
            "The paper scenario's parameter set: every parameter at its start value (the defaults are that scenario)")
    if inputs(model):
        related("text/csv", f"{SCENARIO}_in.csv", "experiment/validation",
                f"Input stimulus: what the FMU receives in the first {REFERENCE_STOP * 1e3:g} ms of the paper's closed "
                "loop (Gauss-Seidel ordering), at every 0.1 ms communication point")
    related("text/plain", f"{SCENARIO}_ref.opt", "experiment/validation",
            "Experiment: start time, stop time, communication step [s], relative tolerance")
    related("text/csv", f"{SCENARIO}_ref.csv", "result",
            "Expected outputs at every communication point of the experiment")
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


# --- FMI 3.0 terminals and icon ------------------------------------------------------------

def terminals(model: str) -> bytes:
    """terminalsAndIcons/terminalsAndIcons.xml (FMI 3.0): the icon's extent and one terminal
    per motor (its force, positions and velocity, or the controller's per-motor signals) and
    one for the pose (the platform's X, Z, B with rates, or the reference)."""
    root = ET.Element("fmiTerminalsAndIcons", fmiVersion="3.0")
    graphics = ET.SubElement(root, "GraphicalRepresentation")
    ET.SubElement(graphics, "CoordinateSystem", x1="-100", y1="-100", x2="100", y2="100",
                  suggestedScalingFactorTo_mm="0.1")
    ET.SubElement(graphics, "Icon", x1="-100", y1="-100", x2="100", y2="100")
    signals = [v.name for v in VARIABLES[model] if v.causality in ("input", "output")]
    motor = {n: "".join(ch for ch in n if ch.isdigit()) for n in signals}  # q1_true -> "1", X_d -> ""
    groups = [(f"motor{i}", f"motor {i}: its force command, positions, velocity and errors",
               [n for n in signals if motor[n] == str(i)]) for i in (1, 2, 3)]
    groups.append(("pose", "platform pose X, Z [m], B [rad] and its rates (desired: the _d signals)",
                   [n for n in signals if not motor[n]]))
    groups = [g for g in groups if g[2]]
    terms = ET.SubElement(root, "Terminals")
    for name, description, members in groups:
        t = ET.SubElement(terms, "Terminal", name=name, matchingRule="bus", description=description)
        for n in members:
            ET.SubElement(t, "TerminalMemberVariable", variableName=n, memberName=n,
                          variableKind="signal")
    ET.indent(root)
    return to_bytes(root)


def icon_svg(model: str) -> bytes:
    """The FMU's icon as SVG: the platform (three movers, links, the tilted platform) and a label."""
    return template("icon.svg").format(label=record(model).icon_label).encode()


def icon_png(model: str) -> bytes:
    """The icon as a 200 x 200 PNG (FMI 3.0 asks for a PNG beside an SVG), drawn with matplotlib
    with no metadata, so the same build gives the same bytes."""
    import matplotlib
    matplotlib.use("Agg")
    from matplotlib import pyplot as plt
    from matplotlib.patches import FancyBboxPatch, Rectangle

    fig = plt.figure(figsize=(2, 2), dpi=100)
    ax = fig.add_axes((0, 0, 1, 1))
    ax.set_xlim(0, 200)
    ax.set_ylim(200, 0)
    ax.axis("off")
    ax.add_patch(FancyBboxPatch((6, 6), 188, 188, boxstyle="round,pad=0,rounding_size=12", fc="#f4f6fa",
                                ec="#24476b", lw=4))
    ax.add_patch(Rectangle((30, 150), 140, 10, fc="#24476b"))
    for x, top in ((38, 70), (86, 100), (134, 130)):
        ax.add_patch(Rectangle((x, 130), 28, 20, fc="#5b8dc9"))
        ax.plot([x + 14, top], [130, 70], color="#24476b", lw=3)
    ax.add_patch(Rectangle((55, 55), 90, 16, fc="#e07b39", angle=-6, rotation_point="center"))
    ax.text(100, 36, record(model).icon_label, ha="center", va="center", fontsize=16, color="#24476b")
    buf = io.BytesIO()
    fig.savefig(buf, format="png", metadata={"Software": None})
    plt.close(fig)
    return buf.getvalue()


# --- documentation/ ----------------------------------------------------------------------



def template(name: str) -> str:
    """The text of the template ``name`` (orchestrator/builder/templates/, package data)."""
    return (TEMPLATES / name).read_text()


BOX_PITCH = 255  # px from one model's box to the next in the diagram (box 170 px wide, arrow 85 px)


def diagram_svg(model: str) -> bytes:
    """documentation/diagram.svg: one box per model of the registry (tapmp.models), left to right in
    signal-flow order, ``model`` highlighted, with forward arrows between neighbours; the feedback arrow
    and the signal labels of the TAPMP loop are the template's own."""
    models = system_models(model if record(model).optional else "")  # the drive's page shows its own loop
    boxes, arrows, labels = [], [], []
    for i, r in enumerate(models):
        x = 20 + BOX_PITCH * i
        fill = "#ffe2c8" if r.name == model else "#eef2f8"
        boxes.append(f'    <rect x="{x}" y="70" width="170" height="90" rx="8" fill="{fill}"/>')
        if i:  # alternate heights so that the labels above two arrows keep apart
            y = (115, 105)[(i - 1) % 2]
            arrows.append(f'    <line x1="{x - 85}" y1="{y}" x2="{x - 2}" y2="{y}" marker-end="url(#a)"/>')
        labels.append(f'    <text x="{x + 85}" y="110">{r.name}</text><text x="{x + 85}" y="132" '
                      f'font-size="12">{r.diagram_note}</text>')
    width = BOX_PITCH * len(models) - 45
    return template("diagram.svg").format(
        width=width, middle=width // 2, title=", ".join(r.element for r in models),
        boxes="\n".join(boxes + arrows), names="\n".join(labels)).encode()


def _n(model: str, name: str) -> str:
    """The start value of ``model``'s parameter ``name`` as the page writes it."""
    return f"{next(v.start for v in VARIABLES[model] if v.name == name):g}"


_PLATFORMS = {"fmi2": "linux64, aarch64-linux, win64, win32, darwin64 (universal x86_64 + arm64)",
              "fmi3": "x86_64-linux, aarch64-linux, x86_64-windows, x86-windows, x86_64-darwin, aarch64-darwin"}


def _range(v) -> str:
    if v.causality != "parameter":
        return ""
    return html.escape(allowed_text(v))


def documentation_html(model: str, family: str, platforms=None) -> bytes:
    """documentation/index.html of ``model`` in ``family`` ("fmi2" or "fmi3"): what the model
    is, its equations with the paper's numbers, every variable with unit, range and start value,
    the family and platforms, how to run it in FMPy, fmusim and OMSimulator, the reference
    experiment, the license."""
    version = "2.0" if family == "fmi2" else "3.0"
    plats = ", ".join(platforms) if platforms else _PLATFORMS[family]
    e = html.escape
    rows = []
    for v in VARIABLES[model]:
        start = "" if v.causality == "output" else e(value_text("Integer" if v.type == "Integer" else "Real", v.start))
        rows.append(f"<tr><td><code>{e(v.name)}</code></td><td>{e(v.causality)}</td><td>{e(v.unit)}</td>"
                    f"<td>{start}</td><td>{_range(v)}</td><td>{e(v.description)}</td></tr>")
    eqs = "".join(f"<tr><th>{e(name)}</th><td><code>{e(text)}</code></td></tr>" for name, text in record(model).text("equations"))
    stim = ("" if not inputs(model) else
            f" <code>fmusim ... --input-file {LS_REF}/{SCENARIO}_in.csv</code> feeds the stimulus.")
    fmpy_input = "" if not inputs(model) else (
        f"\n    input=read_csv('{SCENARIO}_in.csv'),")
    me = bool(record(model).me_states) and family == "fmi2"  # Model Exchange in FMI 2.0 (ModelRecord.me_states)
    interfaces = "Co-Simulation and Model Exchange" if me else "Co-Simulation"
    me_section = "" if not me else template("model_exchange.html").format(stop=repr(REFERENCE_STOP), model=model)
    page = template("documentation.html").format(
        model=model, version=version, what=record(model).text("what"), eqs=eqs, rows="".join(rows),
        interfaces=interfaces, platforms=e(plats), stop_time=f"{DEFAULT_EXPERIMENT['stopTime']:g}",
        step_ms=f"{SERVO_STEP * 1e3:g}", LS_REF=LS_REF, SCENARIO=SCENARIO,
        stimulus_file=f"the input stimulus <code>{SCENARIO}_in.csv</code>, " if inputs(model) else "",
        reference_ms=f"{REFERENCE_STOP * 1e3:g}", reference_stop=repr(REFERENCE_STOP), fmpy_input=fmpy_input,
        stim=stim, me_section=me_section)
    return page.encode()


def license_text() -> bytes:
    """The repository's MIT license (LICENSE at the root; in an installed wheel its dist-info copy)."""
    root = Path(__file__).resolve().parents[2] / "LICENSE"
    if root.is_file():
        return root.read_bytes()
    from importlib import metadata
    dist = metadata.distribution("tapmp-cosim")
    for f in dist.files or ():
        if f.name in ("LICENSE", "LICENSE.txt"):
            return Path(dist.locate_file(f)).read_bytes()
    raise FileNotFoundError("the project's LICENSE is neither in the checkout nor in the installed package")


def extra_members(model: str, family: str, host_fmu: Path, platforms=None,
                  stimulus: dict | None = None) -> dict[str, bytes]:
    """{member name: bytes} of everything this module adds to the FMU. ``host_fmu``: the FMU as
    built so far with a binary this machine runs, for the expected outputs; ``stimulus``: the
    result of :func:`closed_loop_stimulus` (computed if None)."""
    stimulus = stimulus if stimulus is not None else closed_loop_stimulus()
    rows = stimulus.get(model)
    if rows is None and inputs(model):  # a model outside the TAPMP loop's stimulus: its inputs held at their starts
        start = {v.name: v.start for v in VARIABLES[model]}
        rows = [(k * SERVO_STEP, *(start[n] for n in inputs(model))) for k in range(REFERENCE_STEPS + 1)]
    members = {
        f"{LS_REF}/fmi-ls-manifest.xml": manifest(model),
        f"{LS_REF}/{SCENARIO}.ssv": default_parameter_set(model),
        f"{LS_REF}/{SCENARIO}_ref.opt": options_text(),
        f"{LS_REF}/{SCENARIO}_ref.csv": csv_text(outputs(model), expected_outputs(host_fmu, model, rows)),
        "documentation/index.html": documentation_html(model, family, platforms),
        "documentation/diagram.svg": diagram_svg(model),
        LICENSE_FILE: license_text(),
    }
    if rows is not None:
        members[f"{LS_REF}/{SCENARIO}_in.csv"] = csv_text(inputs(model), rows)
    if family == "fmi2":
        members["model.png"] = icon_png(model)  # FMI 2.0's icon of the model (section 2.3)
    if family == "fmi3":
        members["terminalsAndIcons/terminalsAndIcons.xml"] = terminals(model)
        members["terminalsAndIcons/icon.svg"] = icon_svg(model)
        members["terminalsAndIcons/icon.png"] = icon_png(model)
    return members


# --- the FMI Cross-Check layout -------------------------------------------------------------

CROSS_CHECK_PLATFORMS = {"linux64": "linux64", "win64": "win64", "darwin64": "darwin64"}  # binaries/ -> tree
EXPORTING_TOOL = "tapmp"


def cross_check_readme(model: str, platform: str, version: str) -> bytes:
    """ReadMe.txt of one model's Cross-Check folder: what it is, the experiment, how to run it."""
    inputs_note = (f"{model}_in.csv holds the input stimulus (what the FMU receives in the closed loop at every "
                   "0.1 ms communication point); hold each value until the next row.\n" if inputs(model) else
                   "The FMU has no inputs.\n")
    import re
    what = re.sub(r"<[^>]+>", "", record(model).text("what"))  # the documentation's HTML as plain text
    return (f"{model} {version}: {what}\n\n"
            f"Exported by tapmp {version} (three-axis parallel motion platform co-simulation), FMI 2.0 "
            f"Co-Simulation, platform {platform}. The FMU carries its documentation in documentation/index.html.\n\n"
            f"Experiment ({model}_ref.opt): the first {REFERENCE_STOP * 1e3:g} ms of the paper's simulation "
            f"(scenarios/paper_simulation.toml) at the {SERVO_STEP * 1e3:g} ms communication step, every "
            "parameter at its start value (the FMU's defaults are that scenario).\n" + inputs_note +
            f"{model}_ref.csv holds the expected outputs at every communication point, computed by this FMU alone "
            "in FMPy (fixed-step co-simulation; the FMU integrates internally with RK4, so the tolerance is not "
            "used). Any importer stepping the FMU at the same points gets the same values to the last printed "
            "digit.\n").encode()


def cross_check_tree(fmus: dict[str, Path], out_dir: Path, version: str | None = None) -> list[Path]:
    """Write the FMI Cross-Check layout of the native FMI 2.0 Co-Simulation FMUs ``fmus``
    ({model: path}) under ``out_dir``: fmus/2.0/cs/<platform>/tapmp/<version>/<model>/ with the
    FMU, <model>_ref.csv, <model>_in.csv (models with inputs), <model>_ref.opt and ReadMe.txt,
    for every Cross-Check platform the FMU has binaries for. The CSV and options files are the
    FMU's own reference experiment (FMI-LS-REF). Returns the model folders written."""
    import shutil
    import zipfile

    from tapmp import __version__
    version = version or __version__
    written = []
    for model, fmu in fmus.items():
        fmu = Path(fmu)
        with zipfile.ZipFile(fmu) as z:
            names = set(z.namelist())
            root = ET.fromstring(z.read("modelDescription.xml"))
            if root.get("fmiVersion") != "2.0" or root.find("CoSimulation") is None:
                raise ValueError(f"{fmu} is not an FMI 2.0 Co-Simulation FMU: the Cross-Check layout is for those")
            files = {f"{model}_ref.csv": z.read(f"{LS_REF}/{SCENARIO}_ref.csv"),
                     f"{model}_ref.opt": z.read(f"{LS_REF}/{SCENARIO}_ref.opt")}
            if f"{LS_REF}/{SCENARIO}_in.csv" in names:
                files[f"{model}_in.csv"] = z.read(f"{LS_REF}/{SCENARIO}_in.csv")
        platforms = [tree for folder, tree in CROSS_CHECK_PLATFORMS.items()
                     if any(n.startswith(f"binaries/{folder}/") for n in names)]
        if not platforms:
            raise ValueError(f"{fmu} has no binaries for a Cross-Check platform ({', '.join(CROSS_CHECK_PLATFORMS)})")
        for platform in platforms:
            folder = Path(out_dir) / "fmus" / "2.0" / "cs" / platform / EXPORTING_TOOL / version / model
            folder.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(fmu, folder / f"{model}.fmu")
            for name, data in files.items():
                (folder / name).write_bytes(data)
            (folder / "ReadMe.txt").write_bytes(cross_check_readme(model, platform, version))
            written.append(folder)
    return written


# --- the clocked controller (TAPMP_ControllerClocked.fmu, FMI 3.0) ---------------------------

CLOCK = CLOCK_NAME  # the clocked controller's input clock (tapmp.records)
TICKS_FILE = f"{SCENARIO}_ticks.csv"

# How an importer replays the clocked controller's reference experiment on FMPy's FMI 3.0 API, from the folder
# the FMU is in (its documentation shows this text; the tests run it as it stands there). Every communication
# point t_k: Event Mode, the inputs of t_k, the clock activated if t_k is in the tick schedule,
# updateDiscreteStates, Step Mode, doStep over [t_k, t_k + h]; the outputs after each step are the rows of
# the expected results after the first, which holds those after the tick at the start time.
REPLAY_PY = """import csv, zipfile
from fmpy import extract, read_model_description
from fmpy.fmi3 import FMU3Slave

fmu_path, ref = 'TAPMP_ControllerClocked.fmu', 'extra/org.fmi-standard.fmi-ls-ref/'
zipfile.ZipFile(fmu_path).extractall('reference')
read = lambda name: list(csv.reader(open('reference/' + ref + name)))
stimulus = read('paper_simulation_in.csv')
names, rows = stimulus[0][1:], [[float(x) for x in r] for r in stimulus[1:]]
ticks = {float(r[0]) for r in read('paper_simulation_ticks.csv')[1:]}
h = float(dict(read('paper_simulation_ref.opt'))['StepSize'])
md = read_model_description(fmu_path)
vr = {v.name: v.valueReference for v in md.modelVariables}
outputs = [v.name for v in md.modelVariables if v.causality == 'output']
fmu = FMU3Slave(guid=md.guid, unzipDirectory=extract(fmu_path),
                modelIdentifier=md.coSimulation.modelIdentifier, instanceName='controller')
fmu.instantiate(eventModeUsed=True)        # a clocked FMU needs Event Mode
fmu.enterInitializationMode(startTime=0.0)
fmu.exitInitializationMode()               # now in Event Mode at the start time
result = []
for k, (t, *u) in enumerate(rows[:-1]):
    if k > 0:
        fmu.enterEventMode()
    fmu.setFloat64([vr[n] for n in names], u)
    if t in ticks:
        fmu.setClock([vr['sample_clock']], [True])
    fmu.updateDiscreteStates()
    if k == 0:
        result.append([t, *fmu.getFloat64([vr[n] for n in outputs])])
    fmu.enterStepMode()
    fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)
    result.append([rows[k + 1][0], *fmu.getFloat64([vr[n] for n in outputs])])
fmu.terminate()
fmu.freeInstance()
expected = [[float(x) for x in r] for r in read('paper_simulation_ref.csv')[1:]]
print('equal to the reference results:', result == expected)
"""


def ticks_csv(rows) -> bytes:
    """The tick schedule: every time [s] at which the host activates the input clock, one per row, under
    the header time,sample_clock (1: active); the clock ticks at every t0 + k T_s, here every stimulus row."""
    return ("\n".join(["time," + CLOCK, *(f"{float(r[0])!r},1" for r in rows)]) + "\n").encode()


def clocked_expected_outputs(fmu: Path, stimulus_rows, h: float = SERVO_STEP) -> list[tuple]:
    """The outputs of the clocked controller ``fmu`` replayed as :data:`REPLAY_PY` does (FMPy's FMI 3.0 API, the
    clock ticking at every stimulus row t_k = k h [s]): rows (t, outputs...), the first after the tick at the
    start time, then one after each step."""
    import shutil
    import tempfile as tmp

    from fmpy import extract, read_model_description
    from fmpy.fmi3 import FMU3Slave

    md = read_model_description(str(fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    names, outs = inputs(CONTROLLER), outputs(CONTROLLER)
    folder = extract(str(fmu), unzipdir=tmp.mkdtemp(prefix="tapmp_clocked_"))
    instance = FMU3Slave(guid=md.guid, unzipDirectory=folder, modelIdentifier=CLOCKED, instanceName="controller")
    rows = []
    try:
        instance.instantiate(eventModeUsed=True)
        instance.enterInitializationMode(startTime=0.0)
        instance.exitInitializationMode()
        for k, (t, *u) in enumerate(stimulus_rows[:-1]):
            if k > 0:
                instance.enterEventMode()
            instance.setFloat64([vr[n] for n in names], u)
            instance.setClock([vr[CLOCK]], [True])
            instance.updateDiscreteStates()
            if k == 0:
                rows.append((t, *instance.getFloat64([vr[n] for n in outs])))
            instance.enterStepMode()
            instance.doStep(currentCommunicationPoint=t, communicationStepSize=h)
            rows.append((stimulus_rows[k + 1][0], *instance.getFloat64([vr[n] for n in outs])))
        instance.terminate()
    finally:
        instance.freeInstance()
        shutil.rmtree(folder, ignore_errors=True)
    return rows


def clocked_manifest() -> bytes:
    """The clocked controller's FMI-LS-REF manifest: the controller's, with the tick schedule."""
    root = ET.fromstring(manifest(CONTROLLER))
    at = [r.get("source") for r in root.iter("Related")].index(f"{SCENARIO}_ref.opt")
    ticks = ET.Element("Related", type="text/csv", source=TICKS_FILE, role="experiment/validation",
                       description=f"Tick schedule: every time at which the host activates the input clock {CLOCK} "
                                   "(Event Mode, fmi3SetClock, fmi3UpdateDiscreteStates), one per row")
    ET.SubElement(ticks, "Label", name="scenario:paper_simulation",
                  description="the paper's simulation (Section 5.2), scenarios/paper_simulation.toml")
    root.insert(at, ticks)
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def clocked_documentation_html(platforms=None) -> bytes:
    """documentation/index.html of the clocked controller: the controller's page under its own name, with
    the input clock, how to tick it (FMPy, the FMI Library, tapmp), which tools cannot, and the replay of
    its reference experiment (:data:`REPLAY_PY`)."""
    page = documentation_html(CONTROLLER, "fmi3", platforms).decode()
    page = page.replace(f"<title>{CONTROLLER} ", f"<title>{CLOCKED} ").replace(f"<h1>{CONTROLLER}</h1>",
                                                                              f"<h1>{CLOCKED}</h1>")
    page = page.replace(f"model identifier <code>{CONTROLLER}</code>", f"model identifier <code>{CLOCKED}</code>")
    head, rest = page.split("<h2>How to run it</h2>", 1)
    tail = rest[rest.index("<h2>License</h2>"):]
    head = head.replace(f"the options <code>{SCENARIO}_ref.opt</code>",
                        f"the tick schedule <code>{TICKS_FILE}</code>, the options <code>{SCENARIO}_ref.opt</code>")
    e = html.escape
    clock = template("clocked_clock.html").format(CLOCK=CLOCK, T_s=_n(CONTROLLER, "T_s"), replay=e(REPLAY_PY))
    return (head + clock + tail).encode()


def clocked_extra_members(host_fmu: Path, platforms=None, stimulus: dict | None = None) -> dict[str, bytes]:
    """{member name: bytes} of what the clocked controller carries besides its model, as the other native FMUs:
    its reference experiment (the controller's stimulus, with the tick schedule), documentation, license,
    terminals and icon. ``host_fmu``: the FMU as built so far with a binary this machine runs."""
    stimulus = stimulus if stimulus is not None else closed_loop_stimulus()
    rows = stimulus[CONTROLLER]
    return {
        f"{LS_REF}/fmi-ls-manifest.xml": clocked_manifest(),
        f"{LS_REF}/{SCENARIO}.ssv": default_parameter_set(CONTROLLER),
        f"{LS_REF}/{SCENARIO}_in.csv": csv_text(inputs(CONTROLLER), rows),
        f"{LS_REF}/{TICKS_FILE}": ticks_csv(rows[:-1]),
        f"{LS_REF}/{SCENARIO}_ref.opt": options_text(),
        f"{LS_REF}/{SCENARIO}_ref.csv": csv_text(outputs(CONTROLLER), clocked_expected_outputs(host_fmu, rows)),
        "documentation/index.html": clocked_documentation_html(platforms),
        "documentation/diagram.svg": diagram_svg(CONTROLLER),
        LICENSE_FILE: license_text(),
        "terminalsAndIcons/terminalsAndIcons.xml": terminals(CONTROLLER),
        "terminalsAndIcons/icon.svg": icon_svg(CONTROLLER),
        "terminalsAndIcons/icon.png": icon_png(CONTROLLER),
    }
