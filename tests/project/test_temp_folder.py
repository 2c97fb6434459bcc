"""The suite cleans up after itself: run last (tests/conftest.py orders it so), this measures what the
tests before it leave in the session's own temporary folder and asserts it is at most LIMIT.

The session has a temporary folder of its own (tests/support/temp_folder.py: ``TMPDIR`` and Python's
tempfile point at it from the start), so only the suite's files are measured: another process's
files in the system's /tmp, on a shared machine or CI runner, are not counted. A passing test's
tmp_path and its own temp folder are removed when it ends (pyproject's tmp_path_retention_policy =
"failed", conftest's own_temp_folder). What is still in pytest's base folder now (the session's and
modules' shared fixtures: the built FMUs) pytest removes when the session ends with every test
passed (the same policy); after a failure it keeps the base folder, with the failed tests' folders,
for their post-mortem. So what a passing suite leaves is whatever its tests put in the session's
folder outside pytest's base folder (written at import or collection, by child processes that
outlive a test), which is what this counts. Files a test writes to a hard-coded /tmp path are not
seen (tests/studies/test_study_remote.py's workers' venv is one; its fixture removes it).

On pytest-xdist's workers (tests/run.sh) each worker has its own session folder, inside the
controller's: this test runs after every test of the worker it lands on (its file is the last one
handed out) and measures that worker's folder."""

import os
from pathlib import Path

LIMIT = 100 * 2**20  # [bytes]


def size_of(path: Path) -> int:
    """Bytes of the files under ``path`` (symbolic links not followed; files that vanish skipped)."""
    if path.is_symlink() or path.is_file():
        return path.lstat().st_size
    total = 0
    for dirpath, _, filenames in os.walk(path, onerror=lambda err: None):
        for name in filenames:
            try:
                total += (Path(dirpath) / name).lstat().st_size
            except OSError:
                pass
    return total


def test_the_suite_leaves_at_most_100_mb_in_the_temporary_folders(request, tmp_path_factory):
    config = request.config
    assert config.getini("tmp_path_retention_policy") == "failed"  # pytest removes a passing session's base
    base = tmp_path_factory.getbasetemp()
    in_base = size_of(base)
    suite = Path(config.suite_temp)
    left = {p.name: size_of(p) for p in suite.iterdir()}
    print(f"pytest's base folder {base}: {in_base / 2**20:.1f} MiB (removed at the end unless a test failed: "
          f"{request.session.testsfailed} failed); the session's temporary folder {suite}: "
          f"{sum(left.values()) / 2**20:.1f} MiB {sorted(left)}")
    largest = sorted(((size_of(p), p.name) for p in base.iterdir()), reverse=True)[:5]
    # the base folder goes with a passing session; after a failure it is kept on purpose
    assert sum(left.values()) <= LIMIT, (
        f"the tests leave {sum(left.values()) / 2**20:.0f} MiB in {suite}: {left} (and, until the "
        f"session ends, {in_base / 2**20:.0f} MiB in {base}, largest: "
        f"{[(name, round(s / 2**20)) for s, name in largest]})")
