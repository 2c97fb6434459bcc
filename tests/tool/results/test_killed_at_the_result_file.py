"""A run killed at the instant one of its files appears under its name (the result file as it is
opened, metrics.json and results.mat as the run ends) leaves a folder that the next run into it takes:
the marker (run.json) already lists the file, by its inode, so the file is tapmp's own, not a
stranger's that would be replaced. (A killed case of a study is run again
into its folder by --resume, with --overwrite, so any moment of a kill must leave such a folder.)"""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from orchestrator.cli import main

pytestmark = pytest.mark.slow  # runs through the FMUs in a child process

ROOT = Path(__file__).resolve().parents[3]
PAPER = str(ROOT / "scenarios" / "paper_simulation.toml")

# The child dies (as by SIGKILL: no cleanup) right after the rename that gives the result file its name.
KILL_AFTER_RENAME = """
import os, sys
from orchestrator.cli import main
real = os.replace
def replace(src, dst, *a, **k):
    real(src, dst, *a, **k)
    if os.path.basename(str(dst)) == sys.argv[1]:
        os._exit(9)
os.replace = replace
sys.exit(main(sys.argv[2:]))
"""


@pytest.mark.parametrize("fmt,name", [("csv", "results.csv"), ("mat", "results.part.npy"), ("csv", "metrics.json"),
                                      ("mat", "results.mat")])
def test_a_run_killed_as_one_of_its_files_appears_leaves_a_folder_the_next_run_takes(built, tmp_path, fmt, name):
    out = tmp_path / "out"
    args = ["run", PAPER, "--ssp", str(built["ssp"]), "--out", str(out), "--set", "stop_time=0.01", "--format", fmt,
            "--no-progress"]
    killed = subprocess.run([sys.executable, "-c", KILL_AFTER_RENAME, name, *args], capture_output=True, text=True,
                            timeout=300, cwd=ROOT)
    assert killed.returncode == 9, killed.stderr
    info = json.loads((out / "run.json").read_text())
    assert info["status"] == "running"
    assert info["tapmp_files"][name] == {"writing": True, "inode": os.lstat(out / name).st_ino}

    # --overwrite, as a study's case runs (metrics.json alone counts as results that may be good), and it
    # replaces only what the marker lists: before, the killed run's newest file was not listed and was refused
    assert main([*args, "--overwrite"]) == 0
    info = json.loads((out / "run.json").read_text())
    assert info["status"] == "completed"
    assert (out / ("results.csv" if fmt == "csv" else "results.mat")).stat().st_size > 0
