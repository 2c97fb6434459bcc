"""Adding a control law is its record, its constant and its branch in the C model: three files,
and the tool, the FMUs and their descriptions follow.

In a copy of the repository a P-only law (u = Lambda_p e: no feedforward, no damping, no
integral; scenario name "p-only", law = 3) is added exactly as docs/architecture.md, "Adding a
control law", says (step 1: its record in tapmp/laws.py; step 2: its constant in
tapmp/c/tapmp_model.h; step 3: its branch in tapmp_controller_sample of tapmp/c/tapmp_model.c;
step 4: build). The copy's native FMI 2.0 FMUs are built and `tapmp run` runs a scenario with
law = "p-only" through them: every recorded sample's command is the hand-derived
F_i = Lambda_p,i e_i / K_T,i of the law, and the controller FMU declares the new value of its law
setting. The unchanged repository refuses the scenario (exit 2, naming the allowed laws).
"""

import csv
import json
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from tests.model.test_add_a_force_term import add_term, copy_repository

pytestmark = pytest.mark.slow  # builds the native FMUs in a copy of the repository

ROOT = Path(__file__).resolve().parents[2]
LAMBDA_P, K_T = (300.0, 250.0, 320.0), 4.1e-5  # [1/m] per motor, [1/N]: the force gain Lambda_p / K_T [N/m]

EDITS = [  # (file, anchor line, the lines added after it)
    # Step 1: the law's record.
    ("tapmp/laws.py", '        tuple((n, n) for n in ("kp_c", "kp_d", "kv_c", "kv_d", "ki_c", "ki_d")), "e", _pid_integral),\n',
     '    Law("p-only", 3, "TAPMP_PONLY", "P only", "P on e, no feedforward", "a P-only law on e",\n'
     '        (("k_p", "Lambda_p"),), "", equation=("P only (law = 3)", "u = Lambda_p e")),\n'),
    # Step 2: its constant, the record's c_name = c_id.
    ("tapmp/c/tapmp_model.h", "enum { TAPMP_SCDC = 0, TAPMP_APDDC = 1, TAPMP_PIDDC = 2 };\n",
     "enum { TAPMP_PONLY = 3 };\n"),
    # Step 3: its branch in the C model's law switch.
    ("tapmp/c/tapmp_model.c", "        tapmp_pid_command(e, de, integral, u_d, g, u);\n",
     "    } else if (law == TAPMP_PONLY) {\n"
     "        for (int i = 0; i < 3; i++) u[i] = g->Lambda_p[i] * e[i];\n"),
]

SCENARIO = f"""name = "p_only"
law = "p-only"
stop_time = 0.005
start_on_trajectory = true

[gain_overrides]
Lambda_p = {list(LAMBDA_P)}
K_T = {[K_T] * 3}
"""

BUILD = r"""
import sys
from pathlib import Path
from orchestrator.builder.build_native import build_native
print(build_native(Path(sys.argv[1]), families=("fmi2",), windows=False, log=lambda line: None)["fmi2"]["ssp"])
"""


# Runs in the copy: what the tool's other readers of the records make of the new law.
READERS = r"""
import json, sys
from orchestrator.studies.study_file import _TUNABLE
from orchestrator.tool.baselines import run_gains_text
from orchestrator.tool.plots import label
from orchestrator.tool.scenario import ScenarioError, load
sc = load(sys.argv[1])
try:
    load(sys.argv[1], ["law=p-onl"])
except ScenarioError as e:
    refusal = str(e)
print(json.dumps({"label": label("run", "p-only"), "tunable": _TUNABLE["p-only"], "gains": run_gains_text(sc),
                  "refusal": refusal}))
"""


def tapmp(repo: Path, cache: Path, *args) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(repo), "TAPMP_CACHE": str(cache)}
    return subprocess.run([sys.executable, *args], cwd=repo, env=env, capture_output=True, text=True, timeout=1200)


def test_a_p_only_law_added_by_the_recipe_runs_through_the_tool_and_the_fmus(tmp_path):
    scenario = tmp_path / "p_only.toml"
    scenario.write_text(SCENARIO)
    refused = tapmp(ROOT, tmp_path / "cache0", "-m", "orchestrator", "check", str(scenario))
    assert refused.returncode == 2, refused.stderr
    assert "law = 'p-only' is invalid" in refused.stderr and "sc-dc" in refused.stderr

    repo = copy_repository(tmp_path / "repo")
    for path, anchor, lines in EDITS:                                         # steps 1 to 3
        add_term(repo / path, anchor, lines)
    built = tapmp(repo, tmp_path / "cache", "-c", BUILD, str(tmp_path / "native"))   # step 4
    assert built.returncode == 0, built.stderr[-3000:]
    ssp = Path(built.stdout.strip().splitlines()[-1])

    run = tapmp(repo, tmp_path / "cache", "-m", "orchestrator", "run", str(scenario), "--ssp", str(ssp),
                "--out", str(tmp_path / "run"), "--no-progress")
    assert run.returncode == 0, run.stderr[-3000:]
    with open(tmp_path / "run" / "results.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 51
    moved = 0
    for row in rows:
        for i in (1, 2, 3):
            e, F = float(row[f"controller.e{i}"]), float(row[f"controller.F{i}"])
            assert F == pytest.approx(LAMBDA_P[i - 1] * e / K_T, rel=1e-12, abs=1e-9), (row["time"], i)
            moved += F != 0.0
    assert moved > 0  # the errors (and so the commands) are not all zero: the law acts

    with zipfile.ZipFile(ssp.parent / "TAPMP_Controller.fmu") as z:
        md = z.read("modelDescription.xml").decode()
        doc = z.read("documentation/index.html").decode()
    assert "the modal PID-DC baseline (law 2) and a P-only law on e (law 3) for the TAPMP" in md
    assert "3 = P-ONLY (P on e, no feedforward)" in md and 'name="law"' in md
    assert 'max="3"' in md.split('name="law"')[1].split("/>")[0]
    assert "u = Lambda_p e" in doc

    readers = tapmp(repo, tmp_path / "cache", "-c", READERS, str(scenario))
    assert readers.returncode == 0, readers.stderr[-3000:]
    got = json.loads(readers.stdout.strip().splitlines()[-1])
    assert got["label"] == "P only" and got["tunable"] == ["Lambda_p"]
    assert got["gains"] == "k_p = 300/250/320"
    assert "law = 'p-onl' is invalid" in got["refusal"] and "p-only" in got["refusal"]

    check = tapmp(repo, tmp_path / "cache", "-m", "orchestrator", "check", str(scenario))
    assert check.returncode in (0, 1), check.stderr[-3000:]  # the pre-check's verdict on the law's loop
    assert "gauss-seidel, p-only;" in check.stdout
    assert check.stdout.startswith("p_only: stable:") == (check.returncode == 0), check.stdout
