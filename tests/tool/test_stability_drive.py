"""The linearized loop with the drive in it (orchestrator.tool.stability.DriveModel): a pass-through drive
changes nothing, and with the default drive the check's verdict is what the co-simulation of the native
FMUs (TAPMP_Drive.ssp) does: SC-DC with its default gains grows, APD-DC stays."""

import csv
import json
from pathlib import Path

import numpy as np
import pytest

import ctoolchain as toolchain
from orchestrator.cli import main
from orchestrator.tool.scenario import load
from orchestrator.tool.stability import check

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "scenarios" / "paper_simulation.toml"
PASS_THROUGH = {"delay_samples": 0, "current_bandwidth": 0.0, "force_limit": 0.0}


def test_a_pass_through_drive_leaves_the_loop_s_eigenvalues_unchanged():
    plain = check(load(PAPER, []))
    through = check(load(PAPER, [f"drive.{k}={v}" for k, v in PASS_THROUGH.items()]))
    assert np.allclose(sorted(map(abs, through.eigenvalues)), sorted(map(abs, plain.eigenvalues)), atol=1e-9)


def test_with_jacobi_a_pass_through_drive_adds_its_own_step_of_delay():
    # Jacobi holds every element's output one step: the controller's and the drive's, two steps in all
    jacobi = check(load(PAPER, ['ordering="jacobi"', *(f"drive.{k}={v}" for k, v in PASS_THROUGH.items())]))
    two = check(load(PAPER, ["drive.delay_samples=2", "drive.current_bandwidth=0.0"]))
    assert jacobi.spectral_radius == pytest.approx(two.spectral_radius, abs=1e-9)


def test_one_sample_of_drive_delay_is_one_step_of_delay_like_jacobi():
    # Jacobi delays the command by one communication step; so does delay_samples = 1 with an ideal loop
    jacobi = check(load(PAPER, ['ordering="jacobi"']))
    delayed = check(load(PAPER, ["drive.delay_samples=1", "drive.current_bandwidth=0.0"]))
    assert delayed.spectral_radius == pytest.approx(jacobi.spectral_radius, abs=1e-9)


@pytest.fixture(scope="module")
def fmus_dir(tmp_path_factory):
    """The native FMUs for this host, as `tapmp build` lays them out."""
    from orchestrator.builder.build_native import build_native
    folder = tmp_path_factory.mktemp("fmus")
    build_native(folder / "native", log=lambda *_: None, platforms=(toolchain.HOST,))
    return folder


def tracking_error(out: Path) -> np.ndarray:
    """|q_d - q| [m] over the motors at every communication point of a run's results.csv."""
    with open(out / "results.csv") as f:
        rows = list(csv.reader(f))
    col = {name: i for i, name in enumerate(rows[0])}
    data = np.array([[float(v) for v in r] for r in rows[1:]])
    return np.abs(np.stack([data[:, col[f"controller.e{i}"]] for i in (1, 2, 3)], axis=1)).max(axis=1)


@pytest.mark.slow  # builds the native FMUs and runs 0.6 s of the loop twice
@pytest.mark.parametrize("law, stable", [("sc-dc", False), ("apd-dc", True)])
def test_the_check_with_the_drive_predicts_what_the_co_simulation_does(law, stable, fmus_dir, tmp_path):
    scenario = load(PAPER, ["drive=true", f'law="{law}"'])
    assert check(scenario).stable is stable
    out = tmp_path / law
    main(["run", str(PAPER), "--set", "drive=true", "--set", f'law="{law}"', "--set", "stop_time=0.6",
          "--fmus-dir", str(fmus_dir), "--out", str(out), "--no-progress"])
    run = json.loads((out / "run.json").read_text())
    e = tracking_error(out)
    early, late = e[(e.size // 6):(e.size // 3)].max(), e[-(e.size // 6):].max()
    if stable:  # the error of the whole run stays that of its first part
        assert run["status"] == "completed" and late < 2.0 * early
    else:  # the error grows by orders of magnitude, or the plant leaves its workspace
        assert run["status"] != "completed" or late > 100.0 * early
