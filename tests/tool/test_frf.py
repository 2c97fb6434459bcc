"""`tapmp frf`: margins measured from the co-simulation of the native FMUs (orchestrator.tool.frf)
against the analytic ones of the linearized loop, the seeded excitation, and its bad input."""

import math
import zipfile
from xml.etree import ElementTree as ET

import numpy as np
import pytest

from orchestrator.cli import main
from orchestrator.tool import frf
from orchestrator.tool.baselines import compare_runs
from orchestrator.tool.scenario import load

from tests.support.shared import ROOT

PAPER = str(ROOT / "scenarios" / "paper_simulation.toml")
# The loop the linearization describes: the reference held at the start pose (the plant starts there at
# rest), no encoder quantization, no Coulomb friction (at rest its smoothed sign is a stiff damper the
# linearization leaves out). Then the measured points are the analytic ones and only the grid differs.
HOLD = ["trajectory.f_xz=0.0", "trajectory.f_B=0.0", "plant.encoder_resolution=0.0", "plant.F_c1=0.0",
        "plant.F_c2=0.0", "plant.F_c3=0.0"]
# What the grid (40 points per direction, 5 Hz apart at the bottom, about 6 % apart near the crossovers)
# can cost: Ms and the disk margin read at the points nearest the peak (below the peak between two points:
# the largest gap measured is 1.3 % for Ms, 3.3 % for the disk margin), a crossover interpolated between
# two points (the gain margin 0.5 %, the phase margin 0.2 deg, the delay margin 0.5 % measured).
GRID = {"Ms": 0.02, "disk_margin": 0.05, "gm": 0.01, "delay_margin_s": 0.01}
PM_DEG = 0.3


@pytest.fixture(scope="module")
def ssp(tmp_path_factory):
    from orchestrator.builder.build_native import build_native
    return build_native(tmp_path_factory.mktemp("native_frf"), families=("fmi2",), log=lambda *_: None,
                        windows=False)["fmi2"]["ssp"]


@pytest.mark.slow
def test_the_measured_margins_of_scdc_on_the_rigid_plant_are_the_analytic_ones_within_the_grid(ssp):
    scenario = load(PAPER, HOLD)
    result = frf.measure({"sc-dc": scenario}, ssp)
    run = result["runs"]["sc-dc"]
    assert run["linear"] and run["analytic"].startswith("the linearized TAPMP loop")
    assert set(run["loops"]) == {"motor 1", "motor 2", "motor 3", "common", "diff. Z", "diff. B"}
    for name, x in run["loops"].items():
        m, a = x["measured"], x["analytic"]
        assert x["S_error"] < 1e-3, name  # every measured point is the linearized loop's
        assert abs(m["Ms"] - x["Ms_analytic_on_points"]) < 1e-3, name
        for key, tol in GRID.items():
            assert abs(m[key] / a[key] - 1.0) < tol, (name, key, m[key], a[key])
        assert abs(m["pm_deg"] - a["pm_deg"]) < PM_DEG, (name, m["pm_deg"], a["pm_deg"])
        assert m["Ms"] <= a["Ms"] * (1.0 + 1e-3), name  # a grid can miss the peak, not exceed it


@pytest.mark.slow
def test_on_the_paper_trajectory_the_measured_ms_and_phase_margin_stay_within_the_nonlinear_terms(ssp):
    """The scenario as given: the reference moves along the paper's circle (the pose changes the
    differential modes' dynamics), a 100 nm encoder and Coulomb friction act; measured (docs/analysis.md):
    Ms at most 5.5 % and the phase margin at most 1.1 deg off the analytic values at the start pose."""
    run = frf.measure({"sc-dc": load(PAPER)}, ssp)["runs"]["sc-dc"]
    for name, x in run["loops"].items():
        m, a = x["measured"], x["analytic"]
        assert abs(m["Ms"] / a["Ms"] - 1.0) < 0.06, (name, m["Ms"], a["Ms"])
        assert abs(m["pm_deg"] - a["pm_deg"]) < 1.5, (name, m["pm_deg"], a["pm_deg"])


@pytest.mark.slow
def test_the_same_seed_gives_the_same_numbers_bit_for_bit_and_another_seed_other_ones(ssp):
    runs = {"pid-dc-full": compare_runs(load(PAPER))["pid-dc-full"]}
    short = dict(points=6, transient=1, periods=2, analytic=False)
    one, two = (frf.measure(runs, ssp, seed=7, **short)["runs"]["pid-dc-full"] for _ in range(2))
    other = frf.measure(runs, ssp, seed=8, **short)["runs"]["pid-dc-full"]
    for name, x in one["loops"].items():
        assert np.array_equal(x["S"], two["loops"][name]["S"]) and x["measured"] == two["loops"][name]["measured"]
        assert not np.array_equal(x["S"], other["loops"][name]["S"])


def test_the_excitation_is_periodic_with_the_rms_asked_and_one_direction_per_bin():
    exc = frf.excitation(1e-4, 0.2, 5.0, None, 40, 3, 10.0, seed=3)
    s = exc.signals(3 * exc.period_steps)
    assert np.array_equal(s[:, :exc.period_steps], s[:, exc.period_steps:2 * exc.period_steps])
    assert np.allclose(np.sqrt(np.mean(s[:, :exc.period_steps] ** 2, axis=1)), 10.0, rtol=1e-12)
    bins = np.concatenate(exc.bins)
    assert len(set(bins.tolist())) == 120 and bins.min() >= 1 and bins.max() < exc.period_steps // 2
    spectrum = np.abs(np.fft.rfft(s[:, :exc.period_steps], axis=1))
    for m, own in enumerate(exc.bins):  # each direction is excited at its own bins and nowhere else
        others = np.setdiff1d(np.arange(spectrum.shape[1]), own)
        assert spectrum[m, own].min() > 1e3 * spectrum[m, others].max()


def test_margins_from_points_read_a_known_loop():
    """L(s) = k / (s (s + 1)) e^(-s tau) sampled densely: the margins of the formulas."""
    f = np.geomspace(1e-3, 10.0, 4000)
    s = 2j * math.pi * f
    k, tau = 2.0, 0.3
    r = frf.margins_from_points(f, k / (s * (s + 1.0)) * np.exp(-s * tau))
    wc = math.sqrt((-1.0 + math.sqrt(1.0 + 4.0 * k * k)) / 2.0)  # |L| = 1 without the delay
    pm = 180.0 - 90.0 - math.degrees(math.atan(wc)) - math.degrees(wc * tau)
    assert r["pm_deg"] == pytest.approx(pm, abs=1e-3)
    assert r["delay_margin_s"] == pytest.approx(math.radians(pm) / wc, rel=1e-4)
    assert r["f_gc_hz"] == pytest.approx(wc / (2.0 * math.pi), rel=1e-5)
    S = 1.0 / (1.0 + k / (s * (s + 1.0)) * np.exp(-s * tau))
    assert r["Ms"] == pytest.approx(np.abs(S).max()) and r["disk_margin"] == pytest.approx(1.0 / np.abs(S - 0.5).max())


@pytest.mark.parametrize("option, words", [
    (["--amplitude", "0"], "--amplitude = 0.0 is invalid: allowed is an RMS force > 0"),
    (["--amplitude", "-3"], "--amplitude = -3.0 is invalid: allowed is an RMS force > 0"),
    (["--f-max", "6000"], "--f-max = 6000.0 is invalid: allowed is a frequency in [5, 5000) Hz"),
    (["--f-min", "5000"], "--f-min = 5000.0 is invalid: allowed is a frequency in [5, 5000) Hz"),
    (["--seed", "-1"], "--seed = -1 is invalid: allowed is an integer from 0 to 9223372036854775807"),
    (["--period", "nan"], "--period = nan is invalid: allowed is a whole number (>= 4) of steps of 0.0001 s"),
    (["--set", "event_mode=true"], "event_mode = true is invalid for a frequency response measurement (run sc-dc): "
                                   "allowed is false"),
], ids=["zero amplitude", "negative amplitude", "f-max above Nyquist", "f-min at Nyquist", "negative seed", "period not a number",
    "event mode"])
def test_bad_options_are_one_line_naming_them_and_exit_2(option, words, capsys, tmp_path):
    assert main(["frf", PAPER, "--ssp", str(tmp_path / "none.ssp"), "--out", str(tmp_path / "frf"), *option]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"error: {err[0][7:]}"] and words in err[0]
    assert not (tmp_path / "frf").exists()


@pytest.mark.slow
def test_a_plant_input_not_in_the_ssp_is_one_line_naming_it_and_exit_2(ssp, capsys, tmp_path):
    code = main(["frf", PAPER, "--ssp", str(ssp), "--inputs", "plant.F1,plant.Fx,plant.F3",
                 "--out", str(tmp_path / "frf")])
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("error")]
    assert code == 2 and len(err) == 1
    assert err[0].startswith("error: --inputs: 'plant.Fx' is not an input of the system") and "plant.F1" in err[0]


def test_a_former_measurement_stops_the_command_unless_overwrite_and_stays_as_it_was(capsys, tmp_path):
    (tmp_path / "frf").mkdir()
    mine = tmp_path / "frf" / "frf.json"
    mine.write_text("mine")
    assert main(["frf", PAPER, "--ssp", str(tmp_path / "none.ssp"), "--out", str(tmp_path / "frf")]) == 2
    assert capsys.readouterr().err.strip() == f"error: {mine} exists: allowed is --overwrite to replace it (or another --out)"
    assert mine.read_text() == "mine"


PASS = '''
from pythonfmu import Fmi2Causality, Fmi2Slave, Real


class Pass3(Fmi2Slave):
    """Three signals passed straight through: y_i = u_i (a user's FMU the analysis knows nothing of)."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        for i in (1, 2, 3):
            setattr(self, f"u{i}", 0.0)
            setattr(self, f"y{i}", 0.0)
            self.register_variable(Real(f"u{i}", causality=Fmi2Causality.input))
            self.register_variable(Real(f"y{i}", causality=Fmi2Causality.output))

    def exit_initialization_mode(self):
        self.do_step(0.0, 0.0)

    def do_step(self, current_time, step_size):
        for i in (1, 2, 3):
            setattr(self, f"y{i}", getattr(self, f"u{i}"))
        return True
'''


def with_a_foreign_fmu(ssp, tmp_path):
    """A copy of ``ssp`` with a pythonfmu FMU "amp" (Pass3) between the controller's forces and the plant."""
    from pythonfmu import FmuBuilder
    (tmp_path / "Pass3.py").write_text(PASS)
    fmu = FmuBuilder.build_FMU(tmp_path / "Pass3.py", dest=tmp_path)
    ns = {"ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
          "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon"}
    for prefix, uri in ns.items():
        ET.register_namespace(prefix, uri)
    with zipfile.ZipFile(ssp) as z:
        members = {i.filename: z.read(i) for i in z.infolist()}
    root = ET.fromstring(members["SystemStructure.ssd"])
    system = root.find("ssd:System", ns)
    comp = ET.SubElement(system.find("ssd:Elements", ns), f"{{{ns['ssd']}}}Component", name="amp",
                         type="application/x-fmu-sharedlibrary", source="resources/Pass3.fmu")
    connectors = ET.SubElement(comp, f"{{{ns['ssd']}}}Connectors")
    for name, kind in [(f"u{i}", "input") for i in (1, 2, 3)] + [(f"y{i}", "output") for i in (1, 2, 3)]:
        ET.SubElement(ET.SubElement(connectors, f"{{{ns['ssd']}}}Connector", name=name, kind=kind),
                      f"{{{ns['ssc']}}}Real")
    connections = system.find("ssd:Connections", ns)
    for c in list(connections):  # controller.F_i -> amp.u_i, amp.y_i -> plant.F_i
        if c.get("endElement") == "plant" and c.get("endConnector") in ("F1", "F2", "F3"):
            i = c.get("endConnector")[1]
            c.set("endElement", "amp")
            c.set("endConnector", f"u{i}")
            ET.SubElement(connections, f"{{{ns['ssd']}}}Connection", startElement="amp", startConnector=f"y{i}",
                          endElement="plant", endConnector=f"F{i}")
    members["SystemStructure.ssd"] = ET.tostring(root, encoding="UTF-8", xml_declaration=True)
    members["resources/Pass3.fmu"] = open(fmu, "rb").read()
    out = tmp_path / "foreign.ssp"
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as z:
        for name, data in members.items():
            z.writestr(name, data)
    return out


@pytest.mark.slow
def test_a_system_with_a_foreign_fmu_is_measured_through_the_generic_master_with_no_analytic_claim(ssp, tmp_path):
    """A pass-through FMU of the user's between controller and plant: the loop is the TAPMP loop, so the
    measured points are the TAPMP system's to the bit, but the SSP is no longer the linearization's."""
    scenario = load(PAPER, HOLD)
    short = dict(points=6, transient=1, periods=2)
    foreign = frf.measure({"sc-dc": scenario}, with_a_foreign_fmu(ssp, tmp_path), **short)["runs"]["sc-dc"]
    plain = frf.measure({"sc-dc": scenario}, ssp, analytic=False, **short)["runs"]["sc-dc"]
    assert foreign["analytic"] == "none: the linearized loop does not model Pass3 of the SSP"
    for name, x in foreign["loops"].items():
        assert "analytic" not in x and np.array_equal(x["S"], plain["loops"][name]["S"]), name
