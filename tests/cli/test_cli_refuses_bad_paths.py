"""A stop time that is no whole number of steps, and output or
scenario paths the file system refuses, are one line and exit 2 from the real CLI."""

import os
import subprocess
import sys

import pytest

from tests.support.runs import PAPER
from tests.support.shared import ROOT

pytestmark = pytest.mark.slow  # every case runs the CLI in a child process


def tapmp(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "orchestrator", *args], capture_output=True, text=True,
                          cwd=cwd or ROOT, timeout=300)


@pytest.mark.parametrize("stop_time,nearest", [("0.00035", "0.0003 or 0.0004"), ("1e-9", "0.0001")])
def test_a_stop_time_that_is_no_whole_number_of_steps_is_refused_with_the_nearest_valid(stop_time, nearest, tmp_path):
    proc = tapmp("run", str(PAPER), "--set", f"stop_time={stop_time}", "--ssp", str(tmp_path / "none.ssp"),
                 "--out", str(tmp_path / "out"))
    err = proc.stderr.strip()
    assert proc.returncode == 2 and "\n" not in err, err
    assert f"is not a whole number of steps of 0.0001 s: allowed are e.g. {nearest}" in err, err
    assert not (tmp_path / "out" / "results.csv").exists()


def _one_line_exit_2(proc, *words):
    err = proc.stderr.strip()
    assert proc.returncode == 2, (proc.returncode, err)
    assert err.startswith("error: ") and "\n" not in err and "Traceback" not in err, err
    assert all(w in err for w in words), err


def run_into(built, out):
    return tapmp("run", str(PAPER), "--set", "stop_time=0.001", "--ssp", str(built["ssp"]), "--out", str(out))


def test_an_output_folder_that_is_a_file_is_one_line(built, tmp_path):
    target = tmp_path / "out"
    target.write_text("a user's file\n")
    _one_line_exit_2(run_into(built, target), str(target))
    assert target.read_text() == "a user's file\n"


def test_an_output_folder_under_a_file_is_one_line(built, tmp_path):
    (tmp_path / "file").write_text("x")
    _one_line_exit_2(run_into(built, tmp_path / "file" / "out"), "file")


def test_an_output_folder_on_a_read_only_file_system_is_one_line(built, tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m,ro", "tmpfs", str(ro)],
                             capture_output=True).returncode == 0
    try:
        if not mounted:  # no mount rights: a folder without write permission for a non-root child
            os.chmod(ro, 0o555)
        proc = run_into(built, ro / "out")
        if not mounted and os.geteuid() == 0:
            pytest.fail("cannot make a read-only folder: mount failed and root ignores permissions")
        _one_line_exit_2(proc, str(ro / "out"))
    finally:
        if mounted:
            subprocess.run(["umount", str(ro)], check=True)


def test_a_scenario_path_that_is_a_directory_is_one_line(built, tmp_path):
    _one_line_exit_2(tapmp("run", str(tmp_path), "--ssp", str(built["ssp"]), "--out", str(tmp_path / "out")),
                     str(tmp_path))
