"""[mismatch]: the controller's nominal model parameters differ from the plant's, by factor.

The factor reaches the controller FMU (its m_p .. g parameters) and never the plant FMU; checked
by reading the parameters back from the instantiated FMUs of a real co-simulation, in every
family, and by the feedforward the controller computes with them."""

import pytest

from orchestrator.engine.master import CoSimulation, RunOptions
from orchestrator.tool.roles import ROLES
from orchestrator.tool.scenario import ScenarioError, load
from tapmp.params import PAPER_MODEL
from tests.support.runs import PAPER

MISMATCH = ["mismatch.m_p=1.25", "mismatch.I_y=0.8", "mismatch.m_2=1.1", "plant.m_p=2.0"]
NAMES = ("m_p", "m_1", "m_2", "m_3", "I_y", "L_1", "g")


def test_mismatch_sets_the_controller_to_plant_value_times_factor_and_leaves_the_plant():
    s = load(PAPER, MISMATCH)
    par = s.parameters()
    # plant m_p = 2.0 kg (a payload); the controller believes 1.25 x 2.0 = 2.5 kg
    assert par["controller"]["m_p"] == 2.5 and par["plant"]["m_p"] == 2.0
    assert par["controller"]["I_y"] == pytest.approx(0.8 * PAPER_MODEL.I_y, rel=1e-15)
    assert par["controller"]["m_2"] == pytest.approx(1.1 * PAPER_MODEL.m_2, rel=1e-15)
    assert "I_y" not in par["plant"] and "m_2" not in par["plant"]
    plant, ctrl, _ = s.plain_models()
    assert (plant.p.m_p, plant.p.I_y) == (2.0, PAPER_MODEL.I_y)
    assert (ctrl.p.m_p, ctrl.p.I_y, ctrl.p.m_1) == (2.5, 0.8 * PAPER_MODEL.I_y, PAPER_MODEL.m_1)


@pytest.mark.parametrize("override,match", [
    ("mismatch.mass=1.1", r"mismatch.mass is unknown: allowed are m_p, m_1, m_2, m_3, I_y, L_1, g"),
    ("mismatch.m_p=0.0", r"mismatch.m_p = 0.0 is invalid: allowed is a factor in \[0.01, 100\]"),
    ("mismatch.m_p=inf", r"mismatch.m_p = inf is invalid"),
    ("mismatch.m_p=\"big\"", r"mismatch.m_p = 'big' has the wrong type: allowed is float"),
])
def test_bad_mismatch_is_refused_naming_the_key(override, match):
    with pytest.raises(ScenarioError, match=match):
        load(PAPER, [override])


def test_mismatch_and_an_explicit_controller_value_conflict():
    with pytest.raises(ScenarioError, match=r"mismatch.m_p = 1.1 conflicts with controller.m_p = 2.0"):
        load(PAPER, ["mismatch.m_p=1.1", "controller.m_p=2.0"])


def _read(unit, name):
    vr = [unit.vars[name].valueReference]
    return (unit.slave.getFloat64(vr) if unit.fmi3 else unit.slave.getReal(vr))[0]


@pytest.mark.parametrize("family", ["python", "fmi2", "fmi3"])
def test_mismatch_reaches_the_controller_fmu_and_not_the_plant_fmu(built, native_built, family):
    ssp = built["ssp"] if family == "python" else native_built[family]["ssp"]
    s = load(PAPER, ["stop_time=0.001", *MISMATCH])
    nominal = load(PAPER, ["stop_time=0.001", "plant.m_p=2.0"])
    F = {}
    for key, scen in (("mismatch", s), ("nominal", nominal)):
        with CoSimulation(ssp, scen.parameters(), RunOptions(start_time=scen.start_time, step_size=scen.step,
                                                             ordering=scen.ordering, roles=ROLES)) as sim:
            ctrl, plant = sim.units["controller"], sim.units["plant"]
            got_c = {n: _read(ctrl, n) for n in NAMES}
            got_p = {n: _read(plant, n) for n in NAMES}
            sim.step()
            F[key] = [sim.row()[sim.columns.index(f"controller.F{i}")] for i in (1, 2, 3)]
        assert got_p == {**PAPER_MODEL._asdict(), "m_p": 2.0}  # the plant keeps the true values
        if key == "mismatch":
            assert got_c == {**PAPER_MODEL._asdict(), "m_p": 2.5, "I_y": 0.8 * PAPER_MODEL.I_y,
                             "m_2": 1.1 * PAPER_MODEL.m_2}
        else:
            assert got_c == PAPER_MODEL._asdict()  # the nominal controller model, not the plant's payload
    # the feedback terms are the same in both runs (same plant, same first sample); the commands
    # differ by the feedforward u_d (Eq. 26) of the mismatched model minus that of the nominal one
    plant, ctrl_mis, traj = s.plain_models()
    ctrl_nom = nominal.plain_models()[1]
    from tests.support.control_reference import feedforward
    from tapmp.trajectory import reference
    ref = reference(s.start_time, traj)
    q, dq = plant.measured_positions(), plant.joint_velocities()
    want = [a - b for a, b in zip(feedforward(q, dq, ref[3:6], ref[6:9], ctrl_mis.p),
                                  feedforward(q, dq, ref[3:6], ref[6:9], ctrl_nom.p))]
    got = [a - b for a, b in zip(F["mismatch"], F["nominal"])]
    assert got == pytest.approx(want, rel=1e-9, abs=1e-9)
    # gravity dominates: the mismatched controller believes m_p = 2.5 kg, the nominal one 1.835 kg;
    # S3 (F1 - F3) is the Z force (Eq. 14): about 0.665 kg * 9.8 m/s^2 = 6.5 N (plus 0.665 kg * ddZ_d)
    assert 3 ** -0.5 * (got[0] - got[2]) == pytest.approx((2.5 - PAPER_MODEL.m_p) * 9.8, rel=0.02)
