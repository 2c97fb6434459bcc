"""tests/project/test_temp_folder.py counts only what the suite itself leaves: a mini suite (that
test's file, the session-folder plugin tests/support/temp_folder.py, and one test) runs for real
in a child pytest whose system temporary folder is a folder of this test's own."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
BIG = 200 * 2**20  # [bytes] over the limit of 100 MiB; written as sparse files (no disk used)

# Another job on the machine: its own process writes a 200 MiB folder into the system's temporary
# folder while the mini suite runs.
FOREIGN = f'''
import os, subprocess, sys

def test_another_process_fills_the_system_temporary_folder(request):
    code = ("import os, tempfile; d = tempfile.mkdtemp(prefix='foreign-'); "
            "open(os.path.join(d, 'big'), 'wb').truncate({BIG})")
    env = {{**os.environ, "TMPDIR": request.config.system_temp}}
    subprocess.run([sys.executable, "-c", code], env=env, check=True)
'''
# The suite's own leftover: a module writes 200 MiB into the temporary folder when it is imported.
OWN = f'''
import os, tempfile

LEFT = tempfile.mkdtemp(prefix="left-")
open(os.path.join(LEFT, "big"), "wb").truncate({BIG})

def test_nothing():
    pass
'''


def mini_suite(tmp_path: Path, test: str) -> tuple[subprocess.CompletedProcess, Path]:
    """Run the temp-folder test after ``test`` in a child pytest; returns its result and its system
    temporary folder."""
    suite, system = tmp_path / "suite", tmp_path / "system"
    suite.mkdir()
    system.mkdir()
    (suite / "pytest.ini").write_text("[pytest]\ntmp_path_retention_policy = failed\n")
    (suite / "test_a.py").write_text(test)
    (suite / "test_temp_folder.py").write_text((ROOT / "tests" / "project" / "test_temp_folder.py").read_text())
    env = {k: v for k, v in os.environ.items() if k not in ("PYTEST_DEBUG_TEMPROOT", "PYTEST_ADDOPTS")}
    env.update(TMPDIR=str(system), PYTHONPATH=str(ROOT))
    res = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "tests.support.temp_folder",
                          "--basetemp", str(tmp_path / "base"), "test_a.py", "test_temp_folder.py"],
                         cwd=suite, env=env, capture_output=True, text=True, timeout=120)
    return res, system


def test_another_process_files_in_the_temporary_folder_do_not_count(tmp_path):
    res, system = mini_suite(tmp_path, FOREIGN)
    assert res.returncode == 0, res.stdout[-3000:]
    assert "2 passed" in res.stdout
    # the foreign folder is there (200 MiB), the session's own folder was removed with the passing session
    assert [p.name[:8] for p in system.iterdir()] == ["foreign-"]


@pytest.mark.slow  # seconds: runs tapmp or pytest in a fresh Python process
def test_what_the_suite_leaves_in_its_temporary_folder_counts(tmp_path):
    res, system = mini_suite(tmp_path, OWN)
    assert res.returncode == 1, res.stdout[-3000:]
    assert "the tests leave 200 MiB in " in res.stdout and "1 failed, 1 passed" in res.stdout
    # kept after the failure, for the post-mortem
    (kept,) = system.iterdir()
    assert kept.name.startswith("tapmp-tests-") and [p.name[:5] for p in kept.iterdir()] == ["left-"]
