"""The ``needs_shared`` marker of tests/conftest.py, run for real: pytest on a copy of the
conftest and the tests' support package in a scratch repository whose ``../shared`` has or lacks
the file a test needs."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow  # pytest in child processes on a scratch repository

ROOT = Path(__file__).resolve().parents[2]
TEST = '''
import pytest
from tests.support.shared import shared


@pytest.mark.needs_shared("tools/OMSimulator/bin/OMSimulator")
def test_marked():
    pass


def test_by_function():
    assert shared("paper/paper.txt").read_text() == "text"
'''


def run_pytest(tmp_path: Path, present=(), **env) -> tuple[int, str]:
    """pytest -rsE on the scratch repository tmp_path/repo; ``present``: files created in tmp_path/shared."""
    tests = tmp_path / "repo" / "tests"
    tests.mkdir(parents=True)
    # the conftest without its compatibility plugin, which checks rows of the repository's docs
    text = (ROOT / "tests" / "conftest.py").read_text()
    plugin = 'pytest_plugins = ("tests.interop.compatibility", "tests.support.temp_folder")\n'
    assert text.count(plugin) == 1
    (tests / "conftest.py").write_text(text.replace(plugin, 'pytest_plugins = ("tests.support.temp_folder",)\n'))
    (tests / "__init__.py").write_text("")
    shutil.copytree(ROOT / "tests" / "support", tests / "support", ignore=shutil.ignore_patterns("__pycache__"))
    (tests / "test_scratch.py").write_text(TEST)
    for relative in present:
        (tmp_path / "shared" / relative).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / "shared" / relative).write_text("text")
    clean = {k: v for k, v in os.environ.items() if k not in ("CI", "TAPMP_REQUIRE_SHARED")}
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-rsE", "-p", "no:cacheprovider", str(tests)],
                          cwd=tmp_path / "repo", env={**clean, **env}, capture_output=True, text=True, timeout=300)
    return proc.returncode, proc.stdout + proc.stderr


def test_without_shared_the_tests_are_skipped_with_a_reason_naming_the_file(tmp_path):
    code, out = run_pytest(tmp_path)
    assert code == 0, out
    assert "2 skipped" in out and "passed" not in out, out
    assert "needs ../shared/tools/OMSimulator/bin/OMSimulator" in out, out
    assert "needs ../shared/paper/paper.txt" in out, out


@pytest.mark.parametrize("variable", ["CI", "TAPMP_REQUIRE_SHARED"])
def test_in_ci_a_missing_file_fails_the_test_naming_it(tmp_path, variable):
    code, out = run_pytest(tmp_path, **{variable: "1"})
    assert code == 1, out
    assert "1 failed" in out and "1 error" in out and "skipped" not in out, out  # marker: at setup
    assert "needs ../shared/tools/OMSimulator/bin/OMSimulator (relative to the repository root" in out, out
    assert "needs ../shared/paper/paper.txt" in out, out


def test_with_the_files_present_the_tests_run(tmp_path):
    code, out = run_pytest(tmp_path, present=("tools/OMSimulator/bin/OMSimulator", "paper/paper.txt"), CI="1")
    assert code == 0 and "2 passed" in out, out
