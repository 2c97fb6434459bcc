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
from tapmp.params import SERVO_STEP
from tapmp import laws

from .model_description import to_bytes
from .ssp import qname

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
    plant's last row repeats its command (no step follows it)."""
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
                                 ModalGains(**{n: ctrl[n] for n in ModalGains._fields}), ctrl["T_s"], 0.0)
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


ICON_SVG = """<?xml version="1.0" encoding="UTF-8"?>
<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 200 200" width="200" height="200">
  <rect x="4" y="4" width="192" height="192" rx="12" fill="#f4f6fa" stroke="#24476b" stroke-width="6"/>
  <rect x="30" y="150" width="140" height="10" fill="#24476b"/>
  <rect x="38" y="130" width="28" height="20" fill="#5b8dc9"/>
  <rect x="86" y="130" width="28" height="20" fill="#5b8dc9"/>
  <rect x="134" y="130" width="28" height="20" fill="#5b8dc9"/>
  <line x1="52" y1="130" x2="70" y2="70" stroke="#24476b" stroke-width="5"/>
  <line x1="100" y1="130" x2="100" y2="70" stroke="#24476b" stroke-width="5"/>
  <line x1="148" y1="130" x2="130" y2="70" stroke="#24476b" stroke-width="5"/>
  <rect x="55" y="55" width="90" height="16" rx="3" fill="#e07b39" transform="rotate(-6 100 63)"/>
  <text x="100" y="36" font-family="sans-serif" font-size="26" text-anchor="middle" fill="#24476b">{label}</text>
</svg>
"""
ICON_LABEL = {PLANT: "plant", CONTROLLER: "SC-DC", TRAJECTORY: "ref"}


def icon_svg(model: str) -> bytes:
    """The FMU's icon as SVG: the platform (three movers, links, the tilted platform) and a label."""
    return ICON_SVG.format(label=ICON_LABEL[model]).encode()


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
    ax.text(100, 36, ICON_LABEL[model], ha="center", va="center", fontsize=16, color="#24476b")
    buf = io.BytesIO()
    fig.savefig(buf, format="png", metadata={"Software": None})
    plt.close(fig)
    return buf.getvalue()


# --- documentation/ ----------------------------------------------------------------------

DIAGRAM_SVG = """<?xml version="1.0" encoding="UTF-8"?>
<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 720 250" width="720" height="250" font-family="sans-serif"
     font-size="14">
  <title>TAPMP closed loop: trajectory, controller, plant</title>
  <defs><marker id="a" markerWidth="10" markerHeight="8" refX="9" refY="4" orient="auto">
    <path d="M0,0 L10,4 L0,8 z" fill="#24476b"/></marker></defs>
  <g stroke="#24476b" stroke-width="2">
    <rect x="20" y="70" width="170" height="90" rx="8" fill="{fill_traj}"/>
    <rect x="275" y="70" width="170" height="90" rx="8" fill="{fill_ctrl}"/>
    <rect x="530" y="70" width="170" height="90" rx="8" fill="{fill_plant}"/>
    <line x1="190" y1="115" x2="273" y2="115" marker-end="url(#a)"/>
    <line x1="445" y1="105" x2="528" y2="105" marker-end="url(#a)"/>
    <polyline points="615,160 615,215 360,215 360,162" fill="none" marker-end="url(#a)"/>
  </g>
  <g text-anchor="middle" fill="#102030">
    <text x="105" y="110">TAPMP_Trajectory</text><text x="105" y="132" font-size="12">X_d Z_d B_d (Eq. 1)</text>
    <text x="360" y="110">TAPMP_Controller</text><text x="360" y="132" font-size="12">SC-DC (Eq. 15-26)</text>
    <text x="615" y="110">TAPMP_Plant</text><text x="615" y="132" font-size="12">dynamics (Eq. 5-14), RK4</text>
    <text x="232" y="100" font-size="12">pose_d, q_d</text>
    <text x="487" y="92" font-size="12">F1 F2 F3 [N]</text>
    <text x="487" y="235" font-size="12">q1..q3 [m], dq1..dq3 [m/s]</text>
  </g>
  <text x="360" y="40" text-anchor="middle" font-size="16" fill="#102030">This FMU is the highlighted block</text>
</svg>
"""


def diagram_svg(model: str) -> bytes:
    """documentation/diagram.svg: the closed loop of the three FMUs with ``model`` highlighted."""
    fill = {m: ("#ffe2c8" if m == model else "#eef2f8") for m in (TRAJECTORY, CONTROLLER, PLANT)}
    return DIAGRAM_SVG.format(fill_traj=fill[TRAJECTORY], fill_ctrl=fill[CONTROLLER], fill_plant=fill[PLANT]).encode()


def _n(model: str, name: str) -> str:
    """The start value of ``model``'s parameter ``name`` as the page writes it."""
    return f"{next(v.start for v in VARIABLES[model] if v.name == name):g}"


def _what(model: str) -> str:
    n = lambda name: _n(PLANT, name)  # noqa: E731
    return {
        PLANT: ("The plant of the three-axis parallel motion platform (TAPMP) of Zhou, Gao and Zhang, "
                f"<i>Actuators</i> 2024, 13, 166: a platform (m_p = {n('m_p')} kg, I_y = {n('I_y')} kg m2, "
                f"width L_1 = {n('L_1')} m) on three linear motors whose movers (m_1 = {n('m_1')} kg, "
                f"m_2 = {n('m_2')} kg, m_3 = {n('m_3')} kg) slide on one axis; the platform moves in X and Z and "
                "rotates about Y by B. The motor forces F1..F3 [N] drive it; it outputs the encoder positions, "
                "the true positions and velocities of the motors, and the pose. Inside, fixed-step RK4 "
                "integrates the dynamics over each communication step with the force of that step."),
        CONTROLLER: ("The SC-DC synchronization controller with dynamics compensation of the TAPMP (Zhou, Gao, "
                     "Zhang, <i>Actuators</i> 2024, 13, 166), with the APD-DC and modal PID-DC baselines: it "
                     f"samples the reference pose and the measured motor positions every T_s = "
                     f"{float(_n(CONTROLLER, 'T_s')) * 1e3:g} ms and holds the force commands F1..F3 [N] between "
                     "samples."),
        TRAJECTORY: ("The reference of the TAPMP paper's simulation (Section 5.2): a circle in the XZ plane and a "
                     "sinusoid in B; outputs the desired pose with its first two derivatives and the desired motor "
                     "positions q_d (Eq. 2)."),
    }[model]


def _equations(model: str) -> list[tuple[str, str]]:
    p, c, t = (lambda name, m=m: _n(m, name) for m in (PLANT, CONTROLLER, TRAJECTORY))
    kinematics = ("Inverse kinematics (Eq. 2)", "q1 = X + sqrt(3) Z + L_1 (1 - cos B + sqrt(3) sin B), q2 = X, "
                  "q3 = X - sqrt(3) Z - L_1 (1 - cos B - sqrt(3) sin B), L_1 = " + p("L_1") + " m")
    return {
        PLANT: [
            kinematics,
            ("Dynamics (Eq. 5-14)", "M(x) ddx + C(x, dx) dx + G(x) = J(x)^T (F - F_f - F_pull + F_dist), "
                                    "x = (X, Z, B), dq = J(x) dx (Eq. 3), g = " + p("g") + " m/s2"),
            ("Friction", f"F_f,i = c_v,i dq_i + F_c,i tanh(dq_i / v_s), c_v = {p('c_v1')} N s/m, "
                         f"F_c = {p('F_c1')} N, v_s = {p('v_s')} m/s"),
            ("Saturation", f"|F_i| <= force_limit = {p('force_limit')} N"),
            ("Mutual pulling", f"k_pull = {p('k_pull')} N/m on the change of the gaps q2 - q1 and q3 - q2"),
            ("Encoder", f"q_i (measured) = r round(q_i / r), r = encoder_resolution = {p('encoder_resolution')} m"),
            ("Integration", "RK4, `substeps` = " + p("substeps") + " step(s) per communication step"),
        ],
        CONTROLLER: [
            ("Errors (Eq. 15, 18, 21)", "e_i = q_d,i - q_i; e_s,i = e_i - e_(i+1); c = (e_s1 - e_s3, e_s2 - e_s1, "
                                        "e_s3 - e_s2)"),
            ("Coupled errors (Eq. 22-24)", "e_c = e + b int(c) dt, de_c = de + b c, n = de_c + D e_c, "
                                           f"b = {c('b1')} 1/s, D = {c('D1')} 1/s"),
            ("SC-DC command (Eq. 25)", f"u = K_T u_d + Lambda_v n + Lambda_p c, Lambda_p = {c('Lambda_p1')} 1/m, "
                                       f"Lambda_v = {c('Lambda_v1')} s/m, K_T = {c('K_T1')} 1/N; F = u / K_T"),
            ("Dynamics compensation (Eq. 26)", "u_d = J^-T(x) (M(x) ddx_d + C(x, dx) dx_d + G(x)), x = FK(q) (Eq. 1)"),
            *laws.equation_rows(),
            ("Sampling", f"at t0 + k T_s, T_s = {c('T_s')} s; velocity by backward difference of q"),
        ],
        TRAJECTORY: [
            ("Circle", f"X_d = X_c + R sin(2 pi f_xz t + phase_xz), Z_d = Z_c + R cos(2 pi f_xz t + phase_xz), "
                       f"X_c = {t('X_c')} m, Z_c = {t('Z_c')} m, R = {t('radius')} m, f_xz = {t('f_xz')} Hz"),
            ("Rotation", f"B_d = B_offset + A sin(2 pi f_B t + phase_B), A = {t('B_amplitude')} rad (5 deg), "
                         f"f_B = {t('f_B')} Hz"),
            kinematics,
            ("Other profiles", "profile = 1 step, 2 ramp, 3 jerk-limited S-curve from pose A to pose B"),
        ],
    }[model]


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
    eqs = "".join(f"<tr><th>{e(name)}</th><td><code>{e(text)}</code></td></tr>" for name, text in _equations(model))
    stim = ("" if not inputs(model) else
            f" <code>fmusim ... --input-file {LS_REF}/{SCENARIO}_in.csv</code> feeds the stimulus.")
    fmpy_input = "" if not inputs(model) else (
        f"\n    input=read_csv('{SCENARIO}_in.csv'),")
    me = model == PLANT and family == "fmi2"  # the plant offers Model Exchange in FMI 2.0 (build_native.ME_STATES)
    interfaces = "Co-Simulation and Model Exchange" if me else "Co-Simulation"
    me_section = "" if not me else f"""<h2>Model Exchange</h2>
<p>The same model identifier offers FMI 2.0 Model Exchange: the host integrates the continuous states
<code>X, Z, B, dX, dZ, dB</code> (the outputs of those names) from their derivatives <code>der(X)</code> ...
<code>der(dB)</code>, computed by the same C model as the Co-Simulation step. There are no event indicators:
the right-hand side is smooth in the state (the Coulomb friction is tanh-smoothed; the force saturation acts
on the inputs F1..F3, which the host sets). The one discontinuity, the external force step at
<code>disturbance_time</code>, is a time event. The encoder positions <code>q1..q3</code> are a
piecewise-constant function of the state (quantized to <code>encoder_resolution</code>); they feed no
derivative, so they need no event, and are declared continuous. The measurement noise is drawn once per
communication step, so <code>noise_rms</code> must be 0 in Model Exchange. OMSimulator picks Model Exchange
when an FMU offers both (<code>--mode=cs</code> selects the FMU's own RK4).</p>
<p>What the host sets is checked. A state set by <code>fmi2SetContinuousStates</code> (or an FMU state set) must
be finite with |X|, |Z| &lt;= 3 m (the initial pose's range [-1, 1] m widened by its 2 m stroke on each side),
|B| &lt; pi/2 and each rate within what the plant's forces can reach across that domain: 1e3 (the initial
rates' range) plus sqrt(2 (F/m) D) m/s, F the sum of the force bounds the settings allow, m the lightest body,
D = 6 m (the message names the bound). Otherwise, and for a derivative or output that is not finite, the call
is an error naming the state, its value and what is allowed. <code>fmi2SetTime</code> never goes before the
last accepted time (the end of initialization, an event or a completed integrator step). An FMU state keeps
Continuous-Time Mode or Event Mode.</p>
<pre>fmusim --interface-type me --solver cvode --tolerance 1e-10 --stop-time {REFERENCE_STOP!r} --output-interval 1e-4 --output-file out.csv {model}.fmu
simulate_fmu('{model}.fmu', fmi_type='ModelExchange', solver='CVode', relative_tolerance=1e-10, stop_time={REFERENCE_STOP!r})</pre>
"""
    page = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{model} (FMI {version})</title>
<style>body{{font-family:sans-serif;max-width:60em;margin:1em auto;padding:0 1em;color:#102030}}
table{{border-collapse:collapse}}td,th{{border:1px solid #bcc7d6;padding:2px 6px;text-align:left;vertical-align:top}}
code,pre{{background:#f4f6fa}}pre{{padding:6px;overflow-x:auto}}</style></head>
<body>
<h1>{model}</h1>
<p>{_what(model)}</p>
<figure><img src="diagram.svg" alt="The closed loop of the three TAPMP FMUs: trajectory, controller, plant"
 width="720" height="250"><figcaption>The closed loop this FMU belongs to; its defaults are the paper's
simulation, so the three FMUs wired as shown with no parameter set run it (the plant starts on the
reference, moving at 25.1 mm/s in X and 0.219 rad/s in B).</figcaption></figure>
<h2>Equations</h2>
<table>{eqs}</table>
<h2>Variables</h2>
<p>Ranges are enforced: a parameter outside its range is refused with an error status and a log message naming
the variable, the value and what is allowed.</p>
<table><tr><th>name</th><th>causality</th><th>unit</th><th>start</th><th>range</th><th>description</th></tr>
{''.join(rows)}
</table>
<h2>This FMU</h2>
<p>FMI {version} {interfaces}, native C (no Python at run time), model identifier <code>{model}</code>;
binaries for {e(plats)}; the C sources in <code>sources/</code> (compile <code>sources/all.c</code>).
DefaultExperiment: 0 to {DEFAULT_EXPERIMENT['stopTime']:g} s at the {SERVO_STEP * 1e3:g} ms servo step.</p>
<h2>Reference experiment</h2>
<p><code>{LS_REF}/fmi-ls-manifest.xml</code> (FMI-LS-REF) lists the paper scenario's parameter set
<code>{SCENARIO}.ssv</code>, {'the input stimulus <code>' + SCENARIO + '_in.csv</code>, ' if inputs(model) else ''}
the options <code>{SCENARIO}_ref.opt</code> and the expected outputs <code>{SCENARIO}_ref.csv</code>: the first
{REFERENCE_STOP * 1e3:g} ms at 0.1 ms steps.</p>
<h2>How to run it</h2>
<p>FMPy (Python):</p>
<pre>from fmpy import simulate_fmu
from fmpy.util import read_csv
result = simulate_fmu('{model}.fmu', stop_time={REFERENCE_STOP!r}, step_size=1e-4, output_interval=1e-4,{fmpy_input})</pre>
<p>fmusim (Modelica Reference-FMUs):</p>
<pre>fmusim --interface-type cs --stop-time {REFERENCE_STOP!r} --output-interval 1e-4 --output-file out.csv {model}.fmu</pre>
<p>{stim}</p>
<p>OMSimulator:</p>
<pre>OMSimulator --mode=cs --stopTime={REFERENCE_STOP!r} --stepSize=1e-4 --resultFile=out.csv {model}.fmu</pre>
<p>Wire it with the other two TAPMP FMUs as in the diagram (the SSP TAPMP.ssp does this) to run the closed loop.</p>
{me_section}<h2>License</h2>
<p>MIT, see <a href="licenses/license.txt">licenses/license.txt</a>.</p>
</body></html>
"""
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
    what = re.sub(r"<[^>]+>", "", _what(model))  # the documentation's HTML as plain text
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

CLOCKED = "TAPMP_ControllerClocked"  # build_native.CLOCKED (not imported: build_native imports this module)
CLOCK = "sample_clock"               # build_native.CLOCK_NAME
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
    clock = f"""<h2>The input clock</h2>
<p><code>{CLOCK}</code> is a periodic input clock (interval <code>T_s</code> = {_n(CONTROLLER, 'T_s')} s, first tick
at the start time, <code>intervalVariability="fixed"</code>). Every output is clocked by it: the controller samples
its inputs at a tick, computes the command and holds it until the next tick. Instantiate it with
<code>eventModeUsed = true</code> (without it the FMU refuses to instantiate); at every tick t0 + k T_s the host
enters Event Mode, sets the inputs, activates the clock (<code>fmi3SetClock</code>),
calls <code>fmi3UpdateDiscreteStates</code>, reads the outputs and enters Step Mode. After
<code>fmi3ExitInitializationMode</code> the FMU is in Event Mode at the start time: the first tick happens there.
A host that never activates the clock gets the command of initialization throughout and one warning.</p>
<h2>How to run it</h2>
<p>FMPy's FMI 3.0 API (<code>fmpy.fmi3.FMU3Slave</code>): this replays the reference experiment with its tick
schedule and prints whether the result equals the expected outputs (run it in the folder of the FMU):</p>
<pre>{e(REPLAY_PY)}</pre>
<p>The closed loop (the plant and trajectory FMUs with this one, <code>TAPMP_Clocked.ssp</code>) the same way, one
macro step per tick: the TAPMP repository's <code>examples/clocked_fmpy_host.py</code> gives
<code>tapmp run</code> on that SSP bit for bit. The FMI Library (C) and any C host: the same calls
(<code>fmi3EnterEventMode</code>, <code>fmi3SetClock</code>, <code>fmi3UpdateDiscreteStates</code>,
<code>fmi3EnterStepMode</code>, <code>fmi3DoStep</code>). tapmp: <code>tapmp run ... --ssp TAPMP_Clocked.ssp
--set event_mode=true</code>.</p>
<p>FMPy's <code>simulate_fmu</code>, fmusim and FMU Manipulation Toolbox's container do not activate input
clocks: they run it with the command of initialization held. Use <code>TAPMP_Controller.fmu</code> there, the same
controller with its samples as time events (Event Mode) or at every communication point.</p>
"""
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
