"""The master on any SSP of co-simulation FMUs: renamed elements, an extra FMU in the loop,
algebraic loops, explicit and graph-derived step orders (orchestrator.engine.schedule)."""

import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np
import pytest

from orchestrator.cli import main
from orchestrator.engine.master import CoSimulation, CoSimulationError, RunOptions
from orchestrator.engine.schedule import (Connection, ScheduleError, check_algebraic_loops, gauss_seidel_order,
                                          initialization_order)
from orchestrator.tool.roles import ROLES
from orchestrator.tool.scenario import load

ROOT = Path(__file__).resolve().parents[3]
PAPER = ROOT / "scenarios" / "paper_simulation.toml"
SSD_NS = "http://ssp-standard.org/SSP1/SystemStructureDescription"
SSC_NS = "http://ssp-standard.org/SSP1/SystemStructureCommon"
ET.register_namespace("ssd", SSD_NS)
ET.register_namespace("ssc", SSC_NS)
RENAME = {"controller": "ctl", "plant": "axis", "trajectory": "ref"}

DELAY = '''
from pythonfmu import Fmi2Causality, Fmi2Slave, Real


class Delay(Fmi2Slave):
    """One-sample delay of three signals: after doStep(t, h), y_i is u_i as it was at t."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        for i in (1, 2, 3):
            setattr(self, f"u{i}", 0.0)
            setattr(self, f"y{i}", 0.0)
            self.register_variable(Real(f"u{i}", causality=Fmi2Causality.input))
            self.register_variable(Real(f"y{i}", causality=Fmi2Causality.output))

    def exit_initialization_mode(self):
        for i in (1, 2, 3):
            setattr(self, f"y{i}", getattr(self, f"u{i}"))

    def do_step(self, current_time, step_size):
        for i in (1, 2, 3):
            setattr(self, f"y{i}", getattr(self, f"u{i}"))
        return True
'''

GAIN = '''
from pythonfmu import Fmi2Causality, Fmi2Slave, Real


class Gain(Fmi2Slave):
    """y = k u, passed straight through (pythonfmu declares every output dependent on every input)."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.u = 0.0
        self.y = 0.0
        self.k = 1.0
        self.register_variable(Real("u", causality=Fmi2Causality.input))
        self.register_variable(Real("y", causality=Fmi2Causality.output))
        self.register_variable(Real("k", causality=Fmi2Causality.parameter, variability="tunable"))

    def do_step(self, current_time, step_size):
        self.y = self.k * self.u
        return True
'''


def _build(tmp: Path, source: str, name: str, no_feedthrough: bool = False) -> Path:
    """A pythonfmu FMU of ``source`` (class ``name``) built for real; with ``no_feedthrough`` its
    modelDescription declares that no output depends directly on an input (dependencies="")."""
    from pythonfmu import FmuBuilder
    script = tmp / f"{name}.py"
    script.write_text(source)
    fmu = Path(FmuBuilder.build_FMU(script, dest=tmp))
    if no_feedthrough:
        with zipfile.ZipFile(fmu) as z:
            members = {i.filename: z.read(i) for i in z.infolist()}
        root = ET.fromstring(members["modelDescription.xml"])
        for unknown in root.find("ModelStructure").find("Outputs"):
            unknown.set("dependencies", "")
        members["modelDescription.xml"] = ET.tostring(root, encoding="UTF-8", xml_declaration=True)
        with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as z:
            for member, data in members.items():
                z.writestr(member, data)
    return fmu


@pytest.fixture(scope="module")
def test_fmus(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("extra_fmus")
    return {"Delay": _build(tmp, DELAY, "Delay", no_feedthrough=True), "Gain": _build(tmp, GAIN, "Gain")}


def _q(tag, ns=SSD_NS):
    return f"{{{ns}}}{tag}"


def rewrite_ssp(ssp: Path, out: Path, rename=None, add=(), rewire=None) -> Path:
    """A copy of ``ssp`` with elements renamed ({old: new}), components added ((name, FMU path,
    [(connector, kind)])) and connections replaced by ``rewire(connections)`` (a list of
    (start element, connector, end element, connector) in the new names)."""
    rename = rename or {}
    with zipfile.ZipFile(ssp) as z:
        members = {i.filename: z.read(i) for i in z.infolist()}
    root = ET.fromstring(members["SystemStructure.ssd"])
    system = root.find(_q("System"))
    elements, connections = system.find(_q("Elements")), system.find(_q("Connections"))
    for comp in elements:
        comp.set("name", rename.get(comp.get("name"), comp.get("name")))
    for name, fmu, connectors in add:
        comp = ET.SubElement(elements, _q("Component"), name=name, type="application/x-fmu-sharedlibrary",
                             source=f"resources/{fmu.name}")
        conns = ET.SubElement(comp, _q("Connectors"))
        for cname, kind in connectors:
            ET.SubElement(ET.SubElement(conns, _q("Connector"), name=cname, kind=kind), _q("Real", SSC_NS))
        members[f"resources/{fmu.name}"] = fmu.read_bytes()
    wires = [(rename.get(c.get("startElement"), c.get("startElement")), c.get("startConnector"),
              rename.get(c.get("endElement"), c.get("endElement")), c.get("endConnector")) for c in connections]
    for c in list(connections):
        connections.remove(c)
    for a, ac, b, bc in (rewire(wires) if rewire else wires):
        ET.SubElement(connections, _q("Connection"), startElement=a, startConnector=ac, endElement=b,
                      endConnector=bc)
    members["SystemStructure.ssd"] = ET.tostring(root, encoding="UTF-8", xml_declaration=True)
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as z:
        for member, data in members.items():
            z.writestr(member, data)
    return out


def record(ssp, parameters, n, ordering="gauss-seidel", order=None):
    """(columns, rows as an array, step order, initialization order) of n steps."""
    with CoSimulation(ssp, parameters, RunOptions(start_time=0.0, step_size=1e-4, ordering=ordering, order=order,
                                                  roles=ROLES)) as sim:
        rows = [sim.row()]
        for _ in range(n):
            sim.step()
            rows.append(sim.row())
        return sim.columns, np.array(rows), sim.step_order, sim.init_order


@pytest.mark.parametrize("ordering", ["gauss-seidel", "jacobi"])
def test_renamed_elements_give_bit_identical_results(built, tmp_path, ordering):
    renamed = rewrite_ssp(built["ssp"], tmp_path / "renamed.ssp", rename=RENAME)
    scenario = load(PAPER, [f'ordering="{ordering}"', "stop_time=0.05"])
    cols0, rows0, order0, init0 = record(built["ssp"], scenario.parameters(), scenario.n_steps, ordering)
    cols1, rows1, order1, init1 = record(renamed, scenario.parameters(), scenario.n_steps, ordering)
    assert cols1 == cols0  # the TAPMP FMUs are recorded by role, whatever the SSP calls them
    assert np.array_equal(rows1, rows0)
    assert order1 == [RENAME[e] for e in order0] and init1 == [RENAME[e] for e in init0]
    assert np.abs(rows0[-1, 1:]).max() > 0.0  # the loop moved: the comparison compares something


def test_without_roles_the_master_names_columns_and_tables_by_element(built, tmp_path):
    renamed = rewrite_ssp(built["ssp"], tmp_path / "renamed.ssp", rename=RENAME)
    with CoSimulation(renamed, {"axis": {"k_pull": 0.0}}) as sim:  # no roles: the engine knows no TAPMP
        assert {c.split(".")[0] for c in sim.columns} == {"time", "ref", "ctl", "axis"}
        assert {"axis.q1", "ctl.F1"} <= set(sim.columns)
    with pytest.raises(CoSimulationError, match=r"parameters given for unknown element\(s\) plant: allowed are "
                                                r"ref, ctl, axis$"):
        with CoSimulation(renamed, {"plant": {"k_pull": 0.0}}):
            pass


@pytest.mark.slow
def test_parameters_address_elements_by_ssp_name_or_role(built, tmp_path):
    renamed = rewrite_ssp(built["ssp"], tmp_path / "renamed.ssp", rename=RENAME)
    base = load(PAPER, ["stop_time=0.01"])
    by_role = base.parameters()
    by_role["plant"].update(k_pull=0.0, encoder_resolution=1e-6)
    by_name = base.parameters()
    by_name["axis"] = {k: by_name["plant"].pop(k) for k in ("k_pull", "encoder_resolution", "force_limit")}
    by_name["axis"].update(k_pull=0.0, encoder_resolution=1e-6)
    _, rows_role, _, _ = record(renamed, by_role, base.n_steps)
    _, rows_name, _, _ = record(renamed, by_name, base.n_steps)
    _, rows_base, _, _ = record(renamed, base.parameters(), base.n_steps)
    assert np.array_equal(rows_role, rows_name)
    assert not np.array_equal(rows_role, rows_base)  # the values reached the plant
    both = {**base.parameters(), "axis": {"k_pull": 0.0}}  # the scenario's [plant] sets k_pull too
    with pytest.raises(CoSimulationError, match=r"axis\.k_pull is set twice"):
        record(renamed, both, 1)
    with pytest.raises(CoSimulationError, match=r"parameters given for unknown element\(s\) axle: allowed are "
                                                r"ref, ctl, axis"):
        record(renamed, {"axle": {"k_pull": 0.0}}, 1)
    # a scenario's table named after the element reaches it like the role's table
    scenario = load(PAPER, ["stop_time=0.01", "axis.c_v1=7.0"])
    assert scenario.parameters()["axis"] == {"c_v1": 7.0}
    _, rows_table, _, _ = record(renamed, scenario.parameters(), scenario.n_steps)
    expected = base.parameters()
    expected["plant"]["c_v1"] = 7.0
    _, rows_expected, _, _ = record(renamed, expected, base.n_steps)
    assert np.array_equal(rows_table, rows_expected) and not np.array_equal(rows_table, rows_base)


def test_a_delay_fmu_in_the_loop_delays_the_measurement_by_one_sample(built, test_fmus, tmp_path):
    def through_delay(wires):
        out = [w for w in wires if not (w[0] == "plant" and w[1] in ("q1", "q2", "q3"))]
        out += [("plant", f"q{i}", "delay", f"u{i}") for i in (1, 2, 3)]
        out += [("delay", f"y{i}", "controller", f"q{i}") for i in (1, 2, 3)]
        return out
    ports = [(f"u{i}", "input") for i in (1, 2, 3)] + [(f"y{i}", "output") for i in (1, 2, 3)]
    delayed = rewrite_ssp(built["ssp"], tmp_path / "delayed.ssp", add=[("delay", test_fmus["Delay"], ports)],
                          rewire=through_delay)
    scenario = load(PAPER, ["stop_time=0.02"])
    cols, rows, order, init = record(delayed, scenario.parameters(), scenario.n_steps)
    assert order[0] == "controller" and order.index("delay") < order.index("plant")
    c = {name: rows[:, i] for i, name in enumerate(cols)}
    for i in (1, 2, 3):
        q, y = c[f"plant.q{i}"], c[f"delay.y{i}"]
        assert np.array_equal(y[1:], q[:-1])  # what the delay FMU says: y(t + h) = u(t)
        assert y[0] == q[0]
        # The controller's tracking error e = q_d - q (Eq. 15) after its step from t_k was computed
        # from the measurement it read: the plant's q of t_(k-1), one sample late.
        e, q_d = c[f"controller.e{i}"], c[f"trajectory.q{i}_d"]
        assert np.array_equal(e[2:], q_d[1:-1] - q[:-2])
        assert not np.array_equal(e[2:], q_d[1:-1] - q[1:-1])
    _, plain, _, _ = record(built["ssp"], scenario.parameters(), scenario.n_steps)
    e_plain, q_plain, qd_plain = (plain[:, cols.index(n)] for n in ("controller.e1", "plant.q1", "trajectory.q1_d"))
    assert np.array_equal(e_plain[1:], qd_plain[:-1] - q_plain[:-1])  # without it: the measurement of t_k


@pytest.mark.slow
def test_an_algebraic_loop_is_refused_naming_its_elements(built, test_fmus, tmp_path, capsys):
    ports = [("u", "input"), ("y", "output")]
    looped = rewrite_ssp(built["ssp"], tmp_path / "loop.ssp",
                         add=[("g1", test_fmus["Gain"], ports), ("g2", test_fmus["Gain"], ports)],
                         rewire=lambda w: w + [("g1", "y", "g2", "u"), ("g2", "y", "g1", "u")])
    with pytest.raises(CoSimulationError, match=r"algebraic loop through direct feedthrough between the "
                                                r"elements g1, g2: "):
        record(looped, {}, 1)
    scenario = tmp_path / "s.toml"
    scenario.write_text(f'name = "s"\nstop_time = 0.001\noutput = "{tmp_path / "out"}"\n')
    assert main(["run", str(scenario), "--ssp", str(looped)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "g1, g2" in err[0] and err[0].startswith("error:")
    # the same gains in a loop through the plant (no feedthrough) are no algebraic loop
    chain = rewrite_ssp(built["ssp"], tmp_path / "chain.ssp",
                        add=[("g1", test_fmus["Gain"], ports), ("g2", test_fmus["Gain"], ports)],
                        rewire=lambda w: w + [("plant", "q1_true", "g1", "u"), ("g1", "y", "g2", "u")])
    _, rows, order, _ = record(chain, {}, 2)
    assert order.index("g1") < order.index("g2")  # g2 takes g1's output computed from the same sample


@pytest.mark.parametrize("order", [["trajectory", "controller", "plant"], ["plant", "trajectory", "controller"]])
def test_an_explicit_order_is_honoured(built, order):
    scenario = load(PAPER, ["stop_time=0.005"])
    cols, rows, step_order, _ = record(built["ssp"], scenario.parameters(), scenario.n_steps, order=order)
    assert step_order == order
    c = {name: rows[:, i] for i, name in enumerate(cols)}
    e, q_d, q = c["controller.e1"], c["trajectory.q1_d"], c["plant.q1"]
    # e after the controller's step from t_k = q_d - q as the controller read them: from t_(k+1)
    # for an element stepped before it, from t_k for one stepped after it.
    k_ref = 1 if order.index("trajectory") < order.index("controller") else 0
    k_meas = 1 if order.index("plant") < order.index("controller") else 0
    n = len(e) - 1
    assert np.array_equal(e[1:], q_d[k_ref:k_ref + n] - q[k_meas:k_meas + n])


@pytest.mark.parametrize("order, message", [
    (["controller", "plant"], r"\(missing trajectory\)"),
    (["controller", "plant", "trajectory", "motor"], r"\(unknown motor\)"),
    (["controller", "plant", "plant", "trajectory"], r"\(repeated plant\)"),
])
def test_a_bad_order_is_refused_naming_the_elements(built, order, message):
    with pytest.raises(CoSimulationError, match=message + r": allowed is every element of the system exactly "
                                                          r"once: trajectory, controller, plant"):
        record(built["ssp"], {}, 1, order=order)


def test_a_bad_order_through_the_cli_is_one_line_and_exit_2(built, tmp_path, capsys):
    scenario = tmp_path / "s.toml"
    scenario.write_text(f'name = "s"\nstop_time = 0.001\norder = ["controller", "plant"]\n'
                        f'output = "{tmp_path / "out"}"\n')
    assert main(["run", str(scenario), "--ssp", str(built["ssp"])]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "missing trajectory" in err[0]
    scenario.write_text('name = "s"\nordering = "jacobi"\norder = ["controller", "plant", "trajectory"]\n')
    assert main(["run", str(scenario), "--ssp", str(built["ssp"])]) == 2
    assert "allowed is an order only with ordering = \"gauss-seidel\"" in capsys.readouterr().err


def _orders(ssp):
    with CoSimulation(ssp, {}, RunOptions(roles=ROLES)) as sim:
        return sim.step_order, sim.init_order


@pytest.mark.parametrize("family", ["python", "fmi2", "fmi3"])
def test_the_graph_derived_order_is_todays_for_tapmp(built, native_built, family):
    ssp = built["ssp"] if family == "python" else native_built[family]["ssp"]
    assert _orders(ssp) == (["controller", "plant", "trajectory"], ["trajectory", "controller", "plant"])


# --- the rule on graphs alone (no FMUs) ------------------------------------------------------
def _ft(table):
    """feedthrough(element, output) from {element: inputs every output depends on}."""
    return lambda element, output: frozenset(table.get(element, ()))


TAPMP = [Connection("trajectory", "X_d", "controller", "X_d"), Connection("plant", "q1", "controller", "q1"),
         Connection("controller", "F1", "plant", "F1")]
ELEMENTS = ["trajectory", "controller", "plant"]


def test_the_rule_on_the_tapmp_graph_does_not_depend_on_names_or_ssd_order():
    for elements in (ELEMENTS, ELEMENTS[::-1], ["plant", "trajectory", "controller"]):
        assert gauss_seidel_order(elements, TAPMP, _ft({})) == ["controller", "plant", "trajectory"]
        assert initialization_order(elements, TAPMP, _ft({})) == ["trajectory", "controller", "plant"]
    names = {"trajectory": "b", "controller": "c", "plant": "a"}
    renamed = [Connection(names[c.source], c.output, names[c.target], c.input) for c in TAPMP]
    assert gauss_seidel_order(["a", "b", "c"], renamed, _ft({})) == ["c", "a", "b"]


def test_a_feedthrough_sensor_in_the_feedback_path_keeps_the_zero_delay_loop():
    conns = [Connection("trajectory", "X_d", "controller", "X_d"), Connection("plant", "q1", "sensor", "u"),
             Connection("sensor", "y", "controller", "q1"), Connection("controller", "F1", "plant", "F1")]
    order = gauss_seidel_order([*ELEMENTS, "sensor"], conns, _ft({"sensor": {"u"}}))
    # the sensor reads q(t), the controller its output, the plant the command computed from it
    assert order == ["sensor", "controller", "plant", "trajectory"]


def test_feedthrough_on_another_port_is_no_algebraic_loop():
    conns = [Connection("a", "y", "b", "u"), Connection("b", "y", "a", "v")]
    check_algebraic_loops(["a", "b"], conns, lambda e, o: frozenset({"u"}))  # a.y depends on a.u only
    with pytest.raises(ScheduleError, match="between the elements a, b"):
        check_algebraic_loops(["a", "b"], conns, lambda e, o: frozenset({"u", "v"}))
