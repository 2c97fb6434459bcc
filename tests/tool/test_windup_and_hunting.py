"""The integrators under stress, measured in runs: windup on a step at the force limit
(scenarios/windup_step.toml) with and without the controller's anti-windup, and the limit cycles
of a hold against Coulomb friction (scenarios/hold_friction.toml). The runs are the FMI-free loop
stepped in C (tapmp.closed_loop.run: the C model every FMU runs, the same doubles as the FMUs,
tests/engine/test_reference_run.py); one run goes through `tapmp run` and the native FMUs.
The numbers docs/analysis.md gives come from `tapmp compare` on the same scenarios."""

import json

import numpy as np
import pytest

from orchestrator.cli import main
from orchestrator.tool import metrics
from orchestrator.tool.baselines import full_integral, scdc_modal
from orchestrator.tool.scenario import load
from tapmp.closed_loop import COLUMNS, run
from tapmp.control import AW_BACK, AW_CLAMP, AW_OFF
from tests.support.shared import ROOT

STEP = ROOT / "scenarios" / "windup_step.toml"
HOLD = ROOT / "scenarios" / "hold_friction.toml"
# the FMI-free loop's columns by the names of a result file (metrics.py reads those)
_NAMES = {"t": "time", **{a: f"trajectory.{a}" for a in ("X_d", "Z_d", "B_d")},
          **{f"q_d{i}": f"trajectory.q{i}_d" for i in (1, 2, 3)}, **{f"F{i}": f"controller.F{i}" for i in (1, 2, 3)},
          **{f"q{i}_true": f"plant.q{i}_true" for i in (1, 2, 3)}, **{a: f"plant.{a}" for a in ("X", "Z", "B")}}
NAMES = [_NAMES.get(c, c) for c in COLUMNS]


def with_law(scenario, law: str):
    """The scenario with SC-DC, APD-DC or `tapmp compare`'s pid-dc-full (SC-DC's modal P, D, I with the
    integral on every mode, ki_c = ki_d: orchestrator.tool.baselines)."""
    if law != "pid-dc-full":
        return scenario.with_changes(law=law)
    mg = full_integral(scdc_modal(scenario.gain_values())[0])
    return scenario.with_changes(law="pid-dc", controller={**scenario.controller, **mg._asdict()})


def rows_of(scenario) -> np.ndarray:
    """Every communication point of the scenario's run in the FMI-free loop (columns NAMES)."""
    plant, ctrl, traj = scenario.plain_models()
    blocks = []
    run(plant, ctrl, traj, scenario.start_time, scenario.n_steps, scenario.step, scenario.ordering, blocks.append)
    return np.vstack(blocks)


def measured(path, law: str, anti_windup: int) -> tuple[dict, np.ndarray]:
    """(metrics.json of the run, its rows) of the scenario at ``path`` with ``law`` and ``anti_windup``."""
    sc = with_law(load(path, [f"controller.anti_windup={anti_windup}"]), law)
    rows = rows_of(sc)
    par = sc.parameters()
    m = metrics.compute(NAMES, rows, metrics.saturation_limit(par), metrics.move_spec(par, sc.settling_bands))
    return m, rows


@pytest.fixture(scope="module")
def step_runs():
    return {(law, aw): measured(STEP, law, aw)[0] for law in ("sc-dc", "pid-dc-full", "apd-dc")
            for aw in (AW_OFF, AW_CLAMP, AW_BACK)}


def overshoot_um(m) -> float:
    return m["move"]["channels"]["X"]["overshoot"]


def settling_s(m, band="1e-06") -> float:
    return m["move"]["channels"]["X"]["settling_time_s"][band]


def test_the_step_holds_every_law_at_the_force_limit(step_runs):
    for (law, aw), m in step_runs.items():
        assert m["force_limit_n"] == 600.0
        assert min(m["saturation_fraction"]) > 0.01, (law, aw, m["saturation_fraction"])
    # pid-dc-full without anti-windup: at the limit on 9 % of its 3,000 samples (27 ms) on motor 1
    assert max(step_runs["pid-dc-full", AW_OFF]["saturation_fraction"]) > 0.08


def test_pid_dc_full_winds_up_on_the_step_and_either_anti_windup_takes_most_of_its_overshoot(step_runs):
    """Measured: X overshoots 678 um without anti-windup, 180 um with conditional integration and 90 um
    with back-calculation (APD-DC, no integral: 166 um); back-calculation also settles into +-1 um first."""
    off, clamp, back = (step_runs["pid-dc-full", aw] for aw in (AW_OFF, AW_CLAMP, AW_BACK))
    apd = step_runs["apd-dc", AW_OFF]
    assert overshoot_um(off) > 3.0 * overshoot_um(apd)  # the integral's windup, on top of the saturated PD's
    assert overshoot_um(clamp) < overshoot_um(off) / 3.0
    assert overshoot_um(back) < overshoot_um(clamp)
    assert settling_s(back) < settling_s(off) and settling_s(back) < settling_s(clamp)
    # the time at the limit: the wound-up integral holds the command there longer
    assert max(off["saturation_fraction"]) > 2.0 * max(back["saturation_fraction"])


def test_scdc_hardly_winds_up_on_a_common_mode_step(step_runs):
    """SC-DC integrates c (Eq. 21-22), which has no common mode: a step in X winds its integral only
    through the motors' unequal loads, so its overshoot stays that of APD-DC without integral (157 against
    166 um). Conditional integration halves its settling into +-1 um (27 to 14 ms)."""
    off, clamp = step_runs["sc-dc", AW_OFF], step_runs["sc-dc", AW_CLAMP]
    apd = step_runs["apd-dc", AW_OFF]
    assert overshoot_um(off) < 1.1 * overshoot_um(apd)
    assert overshoot_um(off) < overshoot_um(step_runs["pid-dc-full", AW_OFF]) / 3.0
    assert settling_s(clamp) < 0.75 * settling_s(off)


def test_apd_dc_has_no_integral_for_the_anti_windup_to_act_on(step_runs):
    assert step_runs["apd-dc", AW_CLAMP] == step_runs["apd-dc", AW_OFF] == step_runs["apd-dc", AW_BACK]


@pytest.mark.slow
def test_the_hold_hunts_in_force_but_not_in_position_and_the_anti_windup_changes_nothing():
    """hold_friction: over the last half of the 1.5 s hold, SC-DC's force command cycles by about 9 N
    (the encoder's 100 nm counts through the backward-difference velocity) every 2 ms while the true
    position moves less than two counts, with no cycle of its own; no sample reaches the force limit,
    so the anti-windup leaves every double as it was."""
    m, rows = measured(HOLD, "sc-dc", AW_OFF)
    assert m["saturation_fraction"] == [0.0, 0.0, 0.0]
    t_end = metrics.move_spec(load(HOLD).parameters()).t1
    stop = rows[-1, 0]
    cycles = metrics.hold_cycles(NAMES, rows, (t_end + stop) / 2.0)
    force, tracking = cycles["force_n"], cycles["tracking_um"]
    assert all(5.0 < a < 15.0 for a in force["amplitude"]), force
    assert all(p is not None and 1e-3 < p < 5e-3 for p in force["period_s"]), force
    assert all(a < 0.2 for a in tracking["amplitude"]), tracking
    assert all(n <= 1 for n in tracking["cycles"]), tracking
    for aw in (AW_CLAMP, AW_BACK):
        assert np.array_equal(measured(HOLD, "sc-dc", aw)[1], rows)


@pytest.mark.slow
def test_the_hold_with_pid_dc_full_cycles_ten_times_slower_in_force():
    m, rows = measured(HOLD, "pid-dc-full", AW_OFF)
    t_end = metrics.move_spec(load(HOLD).parameters()).t1
    cycles = metrics.hold_cycles(NAMES, rows, (t_end + rows[-1, 0]) / 2.0)
    assert all(p is not None and 1e-2 < p < 5e-2 for p in cycles["force_n"]["period_s"]), cycles
    assert all(a < 0.2 for a in cycles["tracking_um"]["amplitude"]), cycles


@pytest.mark.slow
def test_tapmp_run_of_the_step_through_the_native_fmus_measures_the_same_windup(native_built, tmp_path, step_runs):
    for aw in (AW_OFF, AW_BACK):
        out = tmp_path / f"aw{aw}"
        assert main(["run", str(STEP), "--ssp", str(native_built["fmi2"]["ssp"]), "--set", 'law="pid-dc"', "--set",
                     f"controller.ki_c={scdc_modal(load(STEP).gain_values())[0].ki_d!r}", "--set",
                     f"controller.anti_windup={aw}", "--out", str(out), "--no-progress"]) == 0
        m = json.loads((out / "metrics.json").read_text())
        assert overshoot_um(m) == overshoot_um(step_runs["pid-dc-full", aw])


@pytest.mark.parametrize("setting, message", [
    ("controller.anti_windup=3",
     "anti_windup = 3 is invalid: allowed is 0 (off), 1 (conditional integration) or 2 (back-calculation)"),
    ("controller.anti_windup_time=0.0", "anti_windup_time = 0.0 is invalid: allowed is a number in [1e-09, 1000]"),
])
def test_tapmp_refuses_an_anti_windup_setting_out_of_range_in_one_line(capsys, setting, message):
    assert main(["check", str(STEP), "--set", setting]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and len(err.strip().splitlines()) == 1, err


def test_tapmp_refuses_an_anti_windup_without_a_controller_force_limit_in_one_line(capsys):
    assert main(["check", str(STEP), "--set", "controller.anti_windup=1", "--set", "controller.force_limit=0.0"]) == 2
    err = capsys.readouterr().err
    assert "anti_windup = 1 is invalid: allowed is 0 (off) while force_limit = 0" in err, err
    assert len(err.strip().splitlines()) == 1, err
