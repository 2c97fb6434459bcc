"""The suite cleans up after itself: run last (tests/conftest.py orders it so), this measures what the
tests before it left in the temporary folders and asserts it is at most LIMIT. A passing test's
tmp_path and its own temp folder are removed when it ends (pyproject's tmp_path_retention_policy =
"failed", conftest's own_temp_folder); what remains here are the session's and modules' shared
fixtures (the built FMUs) and the folders of failed tests, which pytest removes with its base folder
when every test passed. Outside pytest's base folder, no test may leave anything in the system's
temporary folder. Measured in a session that runs alone (as CI's does): a concurrent session's
files in the system temporary folder would count too."""

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
    base = tmp_path_factory.getbasetemp()
    left_in_base = size_of(base)
    system = Path(config.system_temp)
    new = [p for p in system.iterdir() if p.name not in config.system_temp_before
           and p != base.parent and not p.name.startswith("pytest-of-")]
    left_outside = {p.name: size_of(p) for p in new}
    print(f"pytest's base folder {base}: {left_in_base / 2**20:.1f} MiB; new in {system}: "
          f"{sum(left_outside.values()) / 2**20:.1f} MiB {sorted(left_outside)}")
    largest = sorted(((size_of(p), p.name) for p in base.iterdir()), reverse=True)[:5]
    assert left_in_base + sum(left_outside.values()) <= LIMIT, (
        f"the tests left {left_in_base / 2**20:.0f} MiB in {base} (largest: "
        f"{[(name, round(s / 2**20)) for s, name in largest]}) and "
        f"{sum(left_outside.values()) / 2**20:.0f} MiB in {system}: {left_outside}")
