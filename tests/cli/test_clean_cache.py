"""`tapmp build --clean-cache` removes the cache's libraries and lock files older than the package's
C sources (earlier versions, other checkouts and environments) and keeps everything else; a cache
another user could write is refused before anything is removed or built."""

import os
import subprocess
import sys

import pytest

pytestmark = pytest.mark.slow  # the real command builds the FMUs in a child process

OLD = 1_000_000_000  # 2001: older than any checkout's sources


def _tapmp(*args, cache, cwd):
    env = {**os.environ, "TAPMP_CACHE": str(cache)}
    return subprocess.run([sys.executable, "-m", "orchestrator", *args], capture_output=True, text=True, cwd=cwd,
                          env=env, timeout=1800)


def test_clean_cache_removes_stale_libraries_and_locks_and_keeps_the_rest(tmp_path):
    cache = tmp_path / "cache"
    cache.mkdir(mode=0o700)
    stale = [cache / "tapmp_model_0123456789abcdef.so", cache / ".tapmp_model_0123456789abcdef.lock",
             cache / "tapmp_stepper_0123456789abcdef.so", cache / ".tapmp_model_0123456789abcdef.x1y2.so"]
    fresh = [cache / "tapmp_model_fedcba9876543210.so", cache / ".tapmp_model_fedcba9876543210.lock"]
    other = [cache / "notes.txt", cache / "ssp" / "tapmp_model_0000000000000000.so"]
    other[1].parent.mkdir()
    for f in stale + fresh + other:
        f.write_bytes(b"x")
    for f in stale + other:
        os.utime(f, (OLD, OLD))
    res = _tapmp("build", "--clean-cache", "--platform", "x86_64-linux", "--out", str(tmp_path / "fmus"),
                 cache=cache, cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert res.stdout.splitlines()[0] == f"removed 4 stale file(s) from the compiled-code cache {cache}"
    assert not any(f.exists() for f in stale)
    assert all(f.exists() for f in fresh + other)
    assert list(cache.glob("tapmp_model_*.so")) != [fresh[0]]  # the build compiled the current model again


def test_clean_cache_refuses_a_cache_others_can_write_and_removes_nothing(tmp_path):
    cache = tmp_path / "cache"
    cache.mkdir()
    cache.chmod(0o777)
    stale = cache / "tapmp_model_0123456789abcdef.so"
    stale.write_bytes(b"x")
    os.utime(stale, (OLD, OLD))
    res = _tapmp("build", "--clean-cache", "--out", str(tmp_path / "fmus"), cache=cache, cwd=tmp_path)
    assert res.returncode == 2 and len(res.stderr.splitlines()) == 1, res.stderr
    assert res.stderr.startswith(f"error: the compiled-code cache: {cache} is writable by its group and others")
    assert stale.exists() and not (tmp_path / "fmus").exists()
