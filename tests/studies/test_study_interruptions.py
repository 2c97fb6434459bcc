"""Studies that were cut or stopped, through the real `tapmp study` in child
processes on a real Dask LocalCluster: a cut last row of study.csv is dropped (the whole rows stay
byte for byte) and its case runs again on --resume; SIGINT and SIGHUP to the whole process group
(a Ctrl-C or a hangup in a terminal) and SIGTERM to the client end it with one line, exit
128 + N, the running case recorded as interrupted and no temporary folder left."""

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from orchestrator.studies.study import StudyError, StudyTable

pytestmark = pytest.mark.slow  # tapmp study in child processes on a Dask LocalCluster

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "scenarios" / "paper_simulation.toml"


def start(*args, tmpdir: Path) -> subprocess.Popen:
    """`tapmp ARGS` in a child process, in a session of its own (a process group, as a shell
    makes for a command), with its temp folder in ``tmpdir``."""
    tmpdir.mkdir(parents=True, exist_ok=True)
    return subprocess.Popen([sys.executable, "-m", "orchestrator", *map(str, args)], start_new_session=True,
                            env=dict(os.environ, TMPDIR=str(tmpdir)), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def finish(proc, timeout=240):
    out, err = proc.communicate(timeout=timeout)
    return proc.returncode, out, err


def read_rows(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        reader = csv.reader(f)
        header = next(reader)
        rows = list(reader)
    assert all(len(r) == len(header) for r in rows), "a partial row"
    return [dict(zip(header, r)) for r in rows]


GRID_STUDY = """[study]
base = "{base}"
[set]
stop_time = 0.01
[grid]
"gain_overrides.Lambda_v" = [0.36, 5.76]
"gain_overrides.D" = [450.0, 900.0]
"""


def test_resume_after_a_cut_last_row_keeps_the_whole_rows_and_reruns_the_cut_case(built, tmp_path):
    study, out, tmpdir = tmp_path / "grid.toml", tmp_path / "out", tmp_path / "tmp"
    study.write_text(GRID_STUDY.format(base=PAPER))
    args = ("study", study, "--ssp", built["ssp"], "--out", out, "--workers", "1", "--no-progress")
    code, _, err = finish(start(*args, tmpdir=tmpdir))
    assert code == 0, err
    lines = (out / "study.csv").read_bytes().splitlines(keepends=True)
    assert len(lines) == 1 + 4
    whole = b"".join(lines[:3])                       # header and the rows of c0000, c0001
    cut_case = lines[3].split(b",")[0].decode()       # c0002: cut after 25 bytes, c0003 never written
    (out / "study.csv").write_bytes(whole + lines[3][:25])

    code, stdout, err = finish(start(*args, "--resume", tmpdir=tmpdir))
    assert code == 0, err
    notes = [line for line in err.splitlines() if not line.startswith("grid: ")]  # the phase lines
    assert notes == [f"note: the last row of {out / 'study.csv'} was cut (25 characters without a "
                     "line end, e.g. the study was killed while writing it): dropped, its case runs again"]
    assert "2 run now" in stdout and "4 completed" in stdout
    data = (out / "study.csv").read_bytes()
    assert data.startswith(whole) and data.endswith(b"\n")
    rows = read_rows(out / "study.csv")
    assert sorted(r["case"] for r in rows) == ["c0000", "c0001", "c0002", "c0003"]
    assert [r["case"] for r in rows].count(cut_case) == 1
    assert all(r["status"] == "completed" for r in rows)
    # the flags: Lambda_v = 5.76 is beyond the stability limit at 0.1 ms (spectral radius > 1)
    for r in rows:
        unstable = float(r["gain_overrides.Lambda_v"]) == 5.76
        assert (float(r["spectral_radius"]) > 1.0) == unstable
        assert ("unstable" in r["flag"].split("+")) == unstable
        assert ("saturated" in r["flag"].split("+")) == (float(r["saturation_fraction_max"]) > 0.01)
    assert (out / "sweep.png").stat().st_size > 10_000   # the plot step ran on the mended table
    assert not list(tmpdir.iterdir())


def test_a_last_row_without_its_line_end_is_dropped_even_with_every_field(tmp_path):
    path = tmp_path / "study.csv"
    table = StudyTable(path, ["x"])
    table.close()
    header = path.read_bytes()
    row = b"c0000,1.0,completed" + b"," * (len(table.columns) - 3)
    path.write_bytes(header + row)                     # all fields, no line end
    table = StudyTable(path, ["x"])
    table.close()
    assert table.dropped == row.decode() and table.rows == {}
    assert path.read_bytes() == header


def test_a_cut_header_starts_the_table_again(tmp_path):
    path = tmp_path / "study.csv"
    path.write_bytes(b"case,x,sta")
    table = StudyTable(path, ["x"])
    table.close()
    assert table.dropped == "case,x,sta"
    assert path.read_text().splitlines() == [",".join(table.columns)]


def test_a_damaged_row_in_the_middle_is_refused_naming_the_line(tmp_path):
    path = tmp_path / "study.csv"
    table = StudyTable(path, ["x"])
    table.close()
    with open(path, "a") as f:
        f.write("c0000,1.0,completed\n")
    with pytest.raises(StudyError, match=r"study.csv: line 2 does not have the \d+ fields of the header: the "
                                         "file is damaged; use --overwrite to start again"):
        StudyTable(path, ["x"])


SLOW_STUDY = """[study]
base = "{base}"
keep_results = true
[set]
stop_time = 10.0
[grid]
"gain_overrides.D" = [450.0, 900.0, 1800.0]
"""


@pytest.mark.parametrize("signum, to_group", [(signal.SIGINT, True), (signal.SIGHUP, True),
                                              (signal.SIGTERM, False)])
def test_a_stopped_study_prints_one_line_and_leaves_no_temporary_folder(built, tmp_path, signum, to_group):
    study, out, tmpdir = tmp_path / "slow.toml", tmp_path / "out", tmp_path / "tmp"
    study.write_text(SLOW_STUDY.format(base=PAPER))
    proc = start("study", study, "--ssp", built["ssp"], "--out", out, "--workers", "1", "--no-progress",
                 tmpdir=tmpdir)
    deadline = time.monotonic() + 180
    while time.monotonic() < deadline and not list((out / "cases").glob("*/results.csv")):
        time.sleep(0.05)  # a case is running on the worker
    assert any(p.name.startswith("tapmp_cosim_") for p in tmpdir.iterdir()), "no case started"
    if to_group:
        os.killpg(proc.pid, signum)   # the client, its worker and every helper process
    else:
        proc.send_signal(signum)
    code, _, err = finish(proc)
    name = signal.Signals(signum).name
    assert code == 128 + signum, err
    # the phase lines of the study, then the one line of the interruption
    assert err.splitlines()[-1] == f"interrupted by {name}: the results so far are in the output folder"
    assert not any("Traceback" in line for line in err.splitlines())
    assert list(tmpdir.iterdir()) == []   # no tapmp_cosim_*, no Dask scratch space
    rows = read_rows(out / "study.csv")
    assert len(rows) < 3 and all(r["status"] == "completed" for r in rows)
    runs = {p.parent.name: json.loads(p.read_text()) for p in (out / "cases").glob("*/run.json")}
    stopped = [r for r in runs.values() if r["status"] == "interrupted"]
    assert stopped and all(r["signal"] == name and "the study was stopped" in r["error"] for r in stopped)
    assert {r["status"] for r in runs.values()} <= {"completed", "interrupted"}
