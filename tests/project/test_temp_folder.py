"""The suite cleans up after itself: run last (tests/conftest.py orders it so), this measures what the
tests before it leave in the temporary folders and asserts it is at most LIMIT.

A passing test's tmp_path and its own temp folder are removed when it ends (pyproject's
tmp_path_retention_policy = "failed", conftest's own_temp_folder). What is still in pytest's base
folder now (the session's and modules' shared fixtures: the built FMUs) pytest removes when the session
ends with every test passed (the same policy); after a failure it keeps the base folder, with the
failed tests' folders, for their post-mortem. So what a passing suite leaves is whatever the tests put
in the system's temporary folder outside pytest's base folder.
Measured in a session that runs alone (as CI's does): a concurrent session's files in the system
temporary folder would count too."""

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
    system = Path(config.system_temp)
    new = [p for p in system.iterdir() if p.name not in config.system_temp_before
           and p != base.parent and not p.name.startswith("pytest-of-")]
    outside = {p.name: size_of(p) for p in new}
    print(f"pytest's base folder {base}: {in_base / 2**20:.1f} MiB (removed at the end unless a test failed: "
          f"{request.session.testsfailed} failed); new in {system}: {sum(outside.values()) / 2**20:.1f} MiB "
          f"{sorted(outside)}")
    largest = sorted(((size_of(p), p.name) for p in base.iterdir()), reverse=True)[:5]
    # the base folder goes with a passing session; after a failure it is kept on purpose
    assert sum(outside.values()) <= LIMIT, (
        f"the tests leave {sum(outside.values()) / 2**20:.0f} MiB in {system}: {outside} (and, until the "
        f"session ends, {in_base / 2**20:.0f} MiB in {base}, largest: "
        f"{[(name, round(s / 2**20)) for s, name in largest]})")
