"""A force step on a mover and seeded measurement noise: the plant's force law by hand, the
steady errors each law leaves against hand-derived stiffness values, the noise's statistics,
and the same numbers from every FMU family."""

import math

import numpy as np
import pytest

from tests.support.shared import ROOT
from orchestrator.tool.results import run_scenario
from orchestrator.tool.scenario import ScenarioError, load
from tapmp.errors import ModelInputError
from tapmp.params import PAPER_MODEL
from tapmp.plant import IDEAL, PlantConfig, PlantModel, noise_sample

POSE = (0.0, -0.01, 0.0)


def _plant(**cfg):
    return PlantModel(PAPER_MODEL, IDEAL._replace(**cfg), POSE)


def test_a_force_step_acts_like_a_motor_force_from_its_time_on_beyond_the_force_limit():
    forced, disturbed = _plant(force_limit=600.0), _plant(force_limit=600.0, disturbance_force1=50.0,
                                                         disturbance_force3=-20.0, disturbance_time=1e-4)
    # before its time: no effect
    forced.step(0.0, 1e-4, 1000.0, 0.0, 0.0)
    disturbed.step(0.0, 1e-4, 1000.0, 0.0, 0.0)
    assert disturbed.state == forced.state
    # from its time on: the saturated command (600 N) plus the disturbance, not limited
    reference = _plant(force_limit=0.0)
    reference.state = list(forced.state)
    reference.step(1e-4, 1e-4, 650.0, 0.0, -20.0)
    disturbed.step(1e-4, 1e-4, 1000.0, 0.0, 0.0)
    assert disturbed.state == reference.state


def test_noise_has_the_stated_rms_zero_mean_and_depends_only_on_seed_sample_and_motor():
    x = np.array([noise_sample(7, float(k), i) for k in range(20000) for i in range(3)])
    assert abs(x.mean()) < 0.03 and abs(x.std() - 1.0) < 0.02
    assert noise_sample(7, 123.0, 1) == noise_sample(7, 123.0, 1)
    assert len({noise_sample(s, 5.0, 0) for s in range(50)}) == 50
    # a plant's measured positions: true + rms * noise of the sample, before quantization
    plant = _plant(noise_rms=2e-6, noise_seed=3)
    for k in range(3):
        q = plant.joint_positions()
        assert plant.measured_positions() == tuple(x + 2e-6 * noise_sample(3, float(k), i) for i, x in enumerate(q))
        plant.step(k * 1e-4, 1e-4, 0.0, 0.0, 0.0)
    assert plant.sample == 3.0


def test_bad_noise_and_disturbance_values_are_refused_with_their_names(tmp_path):
    with pytest.raises(ModelInputError, match=r"noise_rms = -1e-06 is invalid: allowed is a number in \[0, 0.001\]"):
        PlantConfig(noise_rms=-1e-6).validated()
    with pytest.raises(ModelInputError, match="disturbance_force2 = inf is invalid"):
        PlantConfig(disturbance_force2=math.inf).validated()
    with pytest.raises(ModelInputError, match=r"noise_seed = -3 is invalid: allowed is an integer in \[0, 2147483647\]"):
        PlantConfig(noise_seed=-3).validated()
    force_step = ROOT / "scenarios" / "force_step.toml"
    with pytest.raises(ScenarioError, match=r"plant.disturbance_time = 4.0 is invalid: allowed is a time in "
                                            r"\[start_time, stop_time\) = \[0, 3\) s"):
        load(force_step, ["plant.disturbance_time=4.0"])
    with pytest.raises(ScenarioError, match="plant.noise_rms = -1e-06 is invalid"):
        load(force_step, ["plant.noise_rms=-1e-6"])


HOLD = ["stop_time=1.5", "gains=\"default\"", "gain_overrides={}", "plant.encoder_resolution=0.0",
        "mismatch={}", "plant.disturbance_time=0.5"]


@pytest.mark.parametrize("law", ["sc-dc", "apd-dc"])
def test_the_steady_error_under_a_force_step_is_the_force_over_the_law_stiffness(native_built, tmp_path, law):
    """Default gains (equal on the motors), 5 N on mover 1, holding the pose.

    At rest the command balances the force: K_P e / K_T = -d plus the integral. SC-DC integrates
    only the differential modes (K_I = Lambda_v D b L, 1^T L = 0), so the common mode keeps
    sum(e) = -sum(d) K_T / (Lambda_v D) = -5 x 4.1e-5 / 324 m: a mean error of -0.2109 um on every
    motor and no differential error. APD-DC has no integral and no coupling:
    e1 = -5 x 4.1e-5 / 300 m = -0.6833 um, e2 = e3 = 0.
    """
    sc = load(ROOT / "scenarios" / "force_step.toml", [*HOLD, f'law="{law}"'])
    m = run_scenario(sc, native_built["fmi2"]["ssp"], tmp_path / law, overwrite=True)["force_step"]
    change = m["error_change_um"]
    if law == "sc-dc":
        expected = -5.0 * 4.1e-5 / (0.36 * 900.0) / 3.0 * 1e6
        assert math.isclose(m["common_mode_change_um"], expected, rel_tol=0.05), m
        assert max(abs(c - expected) for c in change) < 0.05 * abs(expected), m  # synchronized: no differential error
    else:
        assert math.isclose(change[0], -5.0 * 4.1e-5 / 300.0 * 1e6, rel_tol=0.05), m
        assert abs(change[1]) < 0.02 and abs(change[2]) < 0.02, m
    assert m["disturbance_time_s"] == 0.5 and m["peak_error_change_um"][0] >= abs(change[0])


def test_every_family_measures_the_same_noise(built, native_built, tmp_path):
    sc = load(ROOT / "scenarios" / "paper_simulation.toml",
              ["stop_time=0.02", "plant.noise_rms=1e-6", "plant.noise_seed=11", "plant.encoder_resolution=0.0"])
    tables = {}
    for family, ssp in (("python", built["ssp"]), ("fmi2", native_built["fmi2"]["ssp"]),
                        ("fmi3", native_built["fmi3"]["ssp"])):
        run_scenario(sc, ssp, tmp_path / family, overwrite=True)
        with open(tmp_path / family / "results.csv") as f:
            header = f.readline().strip().split(",")
        data = np.loadtxt(tmp_path / family / "results.csv", delimiter=",", skiprows=1)
        tables[family] = {name: data[:, header.index(name)] for name in header}
    py = tables["python"]
    for i in (1, 2, 3):
        noise = py[f"plant.q{i}"] - py[f"plant.q{i}_true"]
        assert 0.5e-6 < np.sqrt(np.mean(noise ** 2)) < 1.5e-6  # 201 samples of 1 um rms
        for family in ("fmi2", "fmi3"):
            assert np.array_equal(tables[family][f"plant.q{i}"], py[f"plant.q{i}"]), (family, i)
