"""Bad settings through the real `tapmp` command: one line `error: ...` naming the setting that is
wrong (not another one it upsets) and what is allowed, exit 2, and nothing written."""

import os
import subprocess
import sys

import pytest

from tests.support.runs import PAPER
from tests.support.shared import ROOT

pytestmark = pytest.mark.slow  # every case runs the CLI in a child process


def tapmp(*args, env=None):
    return subprocess.run([sys.executable, "-m", "orchestrator", *map(str, args)], capture_output=True, text=True,
                          cwd=ROOT, timeout=300, env={**os.environ, **(env or {})})


def refused(tmp_path, *settings, ssp=None):
    """`tapmp run` of the paper scenario with ``settings`` (--set values); (exit code, stderr lines)."""
    sets = [a for s in settings for a in ("--set", s)]
    res = tapmp("run", PAPER, *sets, "--ssp", ssp or tmp_path / "none.ssp", "--out", tmp_path / "out",
                "--no-progress")
    assert not (tmp_path / "out").exists()  # refused before anything is written
    return res.returncode, res.stderr.splitlines()


@pytest.mark.parametrize("settings, message", [
    (["start_time=nan"], "start_time = nan is invalid: allowed is a finite number [s]"),
    (["stop_time=inf"], "stop_time = inf is invalid: allowed is a finite number [s]"),
    (["record_every=99999999999999999999"],
     "record_every = 99999999999999999999 is invalid: allowed is an integer from 1 to 2147483647"),
    (["record_every=0"], "record_every = 0 is invalid: allowed is an integer from 1 to 2147483647"),
    (["plant.substeps=99999999999999999999"],
     "plant.substeps = 99999999999999999999 is invalid: allowed is an FMI Integer, from -2147483648 to 2147483647"),
    (["start_time=1e10", "stop_time=10000000000.00015"],
     "stop_time = 10000000000.00015 is invalid: stop_time - start_time = 0.0001506805419921875 s is not a whole "
     "number of steps of 0.0001 s, and no stop time near it is: at |t| = 1e+10 s a double resolves 1.91e-06 s, too "
     "coarse for steps of 0.0001 s to be counted within 1e-09: allowed are times nearer to 0 or a larger step"),
    (["start_time=1000", "stop_time=1000.00015"],
     "stop_time = 1000.00015 is invalid: stop_time - start_time = 0.00014999999996234692 s is not a whole number of "
     "steps of 0.0001 s: allowed are e.g. 1000.0001 or 1000.0002"),
], ids=["start nan", "stop inf", "record_every overflow", "record_every 0", "Integer overflow", "off-grid at 1e10", "off-grid at 1000"])
def test_a_bad_time_or_integer_setting_is_named_in_one_line(tmp_path, settings, message):
    assert refused(tmp_path, *settings) == (2, [f"error: {message}"])


@pytest.mark.parametrize("stepper", ["python", "compiled"])
@pytest.mark.parametrize("settings, message", [
    (["start_time=9.3e9", "stop_time=9300000010", "step=1"],
     "start_time = 9300000000.0 s is invalid for clock = 'nanoseconds': allowed are times within +-9223372037 s (an "
     "int64 count of nanoseconds), or another clock"),
    (["start_time=9.2e9", "stop_time=9223372040", "step=1"],
     "stop_time = 9223372040.0 s is invalid for clock = 'nanoseconds' (start_time 9200000000.0 s + 23372040 steps "
     "of 1.0 s): allowed are times within +-9223372037 s (an int64 count of nanoseconds), or another clock"),
])
def test_the_nanosecond_clock_refuses_times_its_int64_cannot_hold_in_both_loops(tmp_path, built, stepper, settings,
                                                                                message):
    sets = [a for s in ('clock="nanoseconds"', *settings) for a in ("--set", s)]
    res = tapmp("run", PAPER, *sets, "--ssp", built["ssp"], "--out", tmp_path / "out", "--no-progress",
                env={"TAPMP_STEPPER": stepper})
    assert (res.returncode, res.stderr.splitlines()) == (2, [f"error: {message}"])
    assert not (tmp_path / "out").exists()


def test_an_ssp_that_is_a_folder_is_named_as_a_folder(tmp_path, built):
    assert refused(tmp_path, ssp=tmp_path) == (
        2, [f"error: --ssp = '{tmp_path}' is a folder: allowed is an SSP file (a zip archive holding "
            "SystemStructure.ssd and the FMUs); a folder of built FMUs goes to --fmus-dir"])
    ssp = built["ssp"]
    assert refused(tmp_path, ssp=ssp.parent) == (
        2, [f"error: --ssp = '{ssp.parent}' is a folder: allowed is an SSP file (a zip archive holding "
            f"SystemStructure.ssd and the FMUs), e.g. {ssp}"])


def test_a_number_of_workers_beyond_any_machine_is_one_line(tmp_path):
    res = tapmp("reproduce", "--workers", "99999999999999999999", "--out", tmp_path / "page.md", "--results",
                tmp_path / "results")
    assert (res.returncode, res.stderr.splitlines()) == (
        2, ["error: --workers = 99999999999999999999 is invalid: allowed is an integer from 1 to 4096"])
    assert not list(tmp_path.iterdir())
