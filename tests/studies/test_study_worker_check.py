"""What a study worker is checked for before it gets a case (orchestrator.studies.remote.worker_problem),
each in a fresh process as a worker starts: a compiler it cannot run with an empty cache, a cache
another user could write; the SSP cache under the compiled-code cache's ownership rule; the
case files a worker sends back capped when they are unpacked.

CI runs as root: "another user" is nobody (chown)."""

import os
import subprocess
import sys
import zlib
from pathlib import Path

import pytest

from orchestrator.studies.remote import cached_ssp, unpack_folder
from orchestrator.studies.study_file import StudyError

NOBODY = 65534
CHECK = ("from orchestrator.studies.remote import identity, worker_problem\n"
         "print(worker_problem('tcp://w:1', identity()))")


def check_in_a_new_process(cache: Path, **env) -> str:
    """worker_problem of a new process with the cache folder ``cache`` and ``env``: its one line."""
    res = subprocess.run([sys.executable, "-c", CHECK], env={**os.environ, "TAPMP_CACHE": str(cache), **env},
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    return res.stdout.strip()


@pytest.mark.slow  # seconds: runs tapmp or pytest in a fresh Python process
def test_a_worker_with_an_empty_cache_and_no_compiler_fails_the_check_naming_it(tmp_path):
    line = check_in_a_new_process(tmp_path / "cache", CC=str(tmp_path / "no-such-cc"))
    assert line.startswith(f"Dask worker tcp://w:1 ({os.uname().nodename}) cannot run the cases: "), line
    assert "no-such-cc" in line and "\n" not in line


def test_a_worker_whose_cache_others_may_write_fails_the_check_naming_it(tmp_path):
    cache = tmp_path / "cache"
    cache.mkdir()
    cache.chmod(0o777)
    line = check_in_a_new_process(cache)
    assert line.startswith(f"Dask worker tcp://w:1 ({os.uname().nodename}) cannot run the cases: the compiled-code "
                           f"cache: {cache} is writable by its group and others (mode 0777)"), line


@pytest.mark.slow  # seconds: runs tapmp or pytest in a fresh Python process
def test_a_worker_with_its_own_cache_passes_the_check(tmp_path):
    assert check_in_a_new_process(tmp_path / "cache") == "None"


def test_a_planted_ssp_in_the_cache_is_refused_naming_its_owner(tmp_path, monkeypatch):
    """An SSP file of another user in the worker's SSP cache, even with the study's bytes, is never
    used: its FMUs' binaries would run."""
    import hashlib
    monkeypatch.setenv("TAPMP_CACHE", str(tmp_path / "cache"))
    data = b"the study's SSP"
    sha = hashlib.sha256(data).hexdigest()
    planted = tmp_path / "cache" / "ssp" / sha / "TAPMP.ssp"
    planted.parent.mkdir(parents=True)
    planted.parent.chmod(0o700)
    planted.write_bytes(data)
    os.chown(planted, NOBODY, NOBODY)
    with pytest.raises(StudyError) as err:
        cached_ssp(sha, "TAPMP.ssp", data, "tcp://w:1")
    assert str(err.value) == (f"Dask worker tcp://w:1 does not trust its SSP cache: the compiled-code cache: {planted} "
                              f"belongs to uid {NOBODY} (nobody), not to this user (uid 0 (root)), so it may be a "
                              "library another user planted; tapmp does not load it: delete it, or set TAPMP_CACHE to "
                              "a folder of your own that only you can write (chmod 700)")
    assert planted.read_bytes() == data


def test_the_ssp_cache_is_written_private(tmp_path, monkeypatch):
    import hashlib
    monkeypatch.setenv("TAPMP_CACHE", str(tmp_path / "cache"))
    data = b"the study's SSP"
    path = cached_ssp(hashlib.sha256(data).hexdigest(), "TAPMP.ssp", data)
    assert path.read_bytes() == data and path.parent.stat().st_mode & 0o777 == 0o700


@pytest.mark.slow  # seconds: runs tapmp or pytest in a fresh Python process
def test_case_files_above_the_cap_are_refused_without_inflating_them_or_writing_anything(tmp_path):
    """1 GB of zeros travels as 1 MB: refused at the cap (inflating no more than the cap), nothing written."""
    squeeze = zlib.compressobj()
    blob = b"".join(squeeze.compress(bytes(2**20)) for _ in range(1024)) + squeeze.flush()
    assert len(blob) < 2**21
    files = {"run.json": zlib.compress(b'{"status": "completed"}'), "results.csv": blob}
    with pytest.raises(StudyError) as err:
        unpack_folder(files, tmp_path / "case", "TAPMP.ssp", 10**6)
    assert str(err.value) == ("the case's files from the worker hold more than 1000000 bytes uncompressed (at "
                              "results.csv), more than the run can write: refused, nothing written")
    assert not (tmp_path / "case").exists()
    assert unpack_folder({"metrics.json": zlib.compress(b"{}")}, tmp_path / "case", "TAPMP.ssp", 10**6) > 0
    assert (tmp_path / "case" / "metrics.json").read_bytes() == b"{}"
