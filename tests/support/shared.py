"""The repository root and the third-party files in ``../shared`` (relative to it) that some tests
need: a missing one skips the test, or fails it in CI (see tests/conftest.py's ``needs_shared``)."""

import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SHARED = ROOT.parent / "shared"
REQUIRE_SHARED = ("CI", "TAPMP_REQUIRE_SHARED")  # environment variables that make a missing file a failure


def shared_required() -> bool:
    """True where a missing ../shared file fails a test instead of skipping it (CI)."""
    return any(os.environ.get(name) for name in REQUIRE_SHARED)


def shared(relative: str) -> Path:
    """``../shared/<relative>`` (relative to the repository root) if it exists; else the test is
    skipped with a reason naming it, or fails where :func:`shared_required`."""
    path = SHARED / relative
    if not path.exists():
        reason = f"needs ../shared/{relative}"
        if shared_required():
            pytest.fail(f"{reason} (relative to the repository root {ROOT}), which is missing; "
                        f"{' or '.join(REQUIRE_SHARED)} is set, so it is required", pytrace=False)
        pytest.skip(reason)
    return path
