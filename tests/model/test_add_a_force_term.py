"""Adding a force term with a setting to the plant is the struct field, the equation and one
row of the settings table, and every family follows it.

In a copy of the repository an extra force on mover 1, the new setting extra_force (default
7 N), is added exactly as docs/architecture.md says (step 1: the field in tapmp_plant_config;
step 2: one line in tapmp_plant_rhs of tapmp/c/tapmp_model.c and the same line in
PlantModel.joint_forces, the documented reference; step 3: the table row, its default in
PlantConfig, its unit, description and range in tapmp/interface.py; step 4: build).
Then the plant alone, from rest under zero commands, is stepped in the FMI-free Python model
(tapmp.plant.PlantModel, what tapmp.closed_loop runs), in the pythonfmu FMU and in the native
FMI 2.0 and 3.0 FMUs built in the copy: all four must give the same doubles, and differ from
the unchanged repository's plant.
"""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow  # builds every family in a copy of the repository

ROOT = Path(__file__).resolve().parents[2]
EXTRA_FORCE = 7.0  # [N] on mover 1
STEPS, H = 20, 1e-4

# Step 1: the struct field.
EDITS = [("tapmp/c/tapmp_model.h", "    double noise_rms;           /* measurement noise rms per measured position [m] */\n",
          "    double extra_force;         /* extra force on mover 1 [N] */\n"),
         # Step 2: the term in the C model's right-hand side, after the friction of mover 3, and the
         # same term in the composed Python reference (checked against the C by the tests).
         ("tapmp/c/tapmp_model.c", "    F3 -= c->c_v[2] * dq3 + c->F_c[2] * tanh(dq3 / vs);\n",
          "    F1 += c->extra_force;                               /* extra force on mover 1 */\n"),
         ("tapmp/plant.py", "        F3 -= c.c_v3 * dq[2] + c.F_c3 * math.tanh(dq[2] / vs)\n",
          "        F1 += c.extra_force  # extra force on mover 1\n"),
         # Step 3: the row of the settings table: default, unit and description, range.
         ("tapmp/plant.py", "    noise_rms: float = 0.0            # measurement noise, rms per measured position [m], 0 = off\n",
          f"    extra_force: float = {EXTRA_FORCE!r}  # extra force on mover 1 [N]\n"),
         ("tapmp/interface.py", '    "disturbance_time": ("s", "time at which the external force step starts"),\n',
          '    "extra_force": ("N", "extra force on mover 1"),\n'),
         ("tapmp/interface.py", '    "disturbance_time": (0.0, 1e9), "noise_rms": (0.0, 1e-3), "noise_seed": (0, 2147483647),\n',
          '    "extra_force": (-1e6, 1e6),\n')]

# Runs in a repository (its path first on sys.path): the X trajectories of the four plants.
RUN = r"""
import json, sys, tempfile
from pathlib import Path
from fmpy import simulate_fmu
import tapmp
from tapmp.params import PAPER_MODEL
from tapmp.plant import PlantConfig, PlantModel
from orchestrator.builder.build import build_fmu
from orchestrator.builder.build_native import build_native_fmu

steps, h = int(sys.argv[1]), float(sys.argv[2])
out = {"tapmp": tapmp.__file__}
plant = PlantModel(PAPER_MODEL, PlantConfig())
rows = [plant.state[0]]
for k in range(steps):  # the communication points of fmpy's loop: t_k = k h, step t_(k+1) - t_k
    plant.step(k * h, (k + 1) * h - k * h, 0.0, 0.0, 0.0)
    rows.append(plant.state[0])
out["python"] = rows
ds = plant.derivatives([0.0] * 6, 0.0, 0.0, 0.0)
out["reference_ddX"] = ds[3]
with tempfile.TemporaryDirectory() as tmp:
    for family in ("py", "fmi2", "fmi3"):
        (Path(tmp) / family).mkdir()
    fmus = {"pythonfmu": build_fmu("TAPMP_Plant", Path(tmp) / "py"),
            "fmi2": build_native_fmu("TAPMP_Plant", "fmi2", Path(tmp) / "fmi2", windows=False),
            "fmi3": build_native_fmu("TAPMP_Plant", "fmi3", Path(tmp) / "fmi3", windows=False)}
    for family, fmu in fmus.items():
        # from rest and with no force, as the Python plant above (the FMUs' defaults start on the paper's
        # trajectory, their force inputs at the paper run's first command)
        rest = {name: 0.0 for name in ("X0", "Z0", "B0", "dX0", "dZ0", "dB0", "F1", "F2", "F3")}
        res = simulate_fmu(str(fmu), stop_time=steps * h, step_size=h, output_interval=h, output=["X"],
                           start_values=rest)
        out[family] = [float(x) for x in res["X"]]
print(json.dumps(out))
"""


def run_plants(repo: Path, cache: Path) -> dict:
    env = {**os.environ, "PYTHONPATH": str(repo), "TAPMP_CACHE": str(cache)}
    proc = subprocess.run([sys.executable, "-c", RUN, str(STEPS), repr(H)], cwd=repo, env=env,
                          capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert Path(out["tapmp"]).resolve().is_relative_to(repo.resolve()), out["tapmp"]  # the copy's package ran
    return out


def copy_repository(dest: Path) -> Path:
    files = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    for name in files.decode().split("\0"):
        if name and (ROOT / name).is_file():
            (dest / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, dest / name)
    return dest


def add_term(path: Path, anchor: str, term: str) -> None:
    text = path.read_text()
    assert text.count(anchor) == 1, f"{path}: the anchor line is not there once"
    path.write_text(text.replace(anchor, anchor + term))


def test_a_force_term_with_a_setting_changes_every_family_identically(tmp_path):
    repo = copy_repository(tmp_path / "repo")
    for path, anchor, line in EDITS:                                      # steps 1 to 3
        add_term(repo / path, anchor, line)
    changed = run_plants(repo, tmp_path / "cache")                        # step 4: build and run
    original = run_plants(ROOT, tmp_path / "cache")
    families = ("python", "pythonfmu", "fmi2", "fmi3")
    for result in (original, changed):
        for family in families:
            assert len(result[family]) == STEPS + 1, (family, result[family])
            assert result[family] == result["python"], (family, result[family], result["python"])
    # the plant moves differently, in the direction of the force, in the C and in the reference
    assert changed["python"][-1] > original["python"][-1] + 1e-8
    assert changed["reference_ddX"] > original["reference_ddX"]
