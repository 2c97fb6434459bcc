"""The output folders are safe to share, through the real `tapmp` in child processes: one writer per
folder, whole rows only, nothing stale left behind by signals or a full disk."""

import csv
import json
import os
import re
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow  # concurrent tapmp processes, signals, a full disk

ROOT = Path(__file__).resolve().parents[2]
PAPER = str(ROOT / "scenarios" / "paper_simulation.toml")


def start(*args, tmpdir: Path) -> subprocess.Popen:
    """`tapmp ARGS` in a child process with its own temp folder ``tmpdir``."""
    tmpdir.mkdir(parents=True, exist_ok=True)
    return subprocess.Popen([sys.executable, "-m", "orchestrator", *map(str, args)],
                            env=dict(os.environ, TMPDIR=str(tmpdir)), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def run_args(ssp, out, stop_time, *extra):
    return ("run", PAPER, "--ssp", ssp, "--out", out, "--set", f"stop_time={stop_time}", "--no-progress", *extra)


def finish(proc: subprocess.Popen, timeout=180) -> tuple[int, str]:
    """Exit code and stderr of a child started by start()."""
    _, err = proc.communicate(timeout=timeout)
    return proc.returncode, err


def whole_rows(path: Path) -> list[list[float]]:
    """The rows of a results.csv; asserts every row has the header's fields, all floats."""
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    assert rows and rows[0][0] == "time"
    assert all(len(r) == len(rows[0]) for r in rows), "a partial row"
    return [[float(x) for x in r] for r in rows[1:]]


def wait_for_rows(path: Path, n_bytes=50_000, timeout=120) -> None:
    """Wait until a growing results.csv holds some rows."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and (not path.exists() or path.stat().st_size < n_bytes):
        time.sleep(0.02)
    assert path.exists() and path.stat().st_size >= n_bytes, "the run wrote no rows"


def in_use(out: Path, pid: int) -> str:
    return (f"error: output folder {out} is in use by tapmp (pid {pid}): allowed is one writer per output "
            "folder; wait for it to end or choose another --out")


def test_two_runs_started_at_once_on_one_folder_one_runs_and_the_other_is_refused(built, tmp_path):
    for attempt in range(3):
        out = tmp_path / f"out{attempt}"
        procs = [start(*run_args(built["ssp"], out, 0.3), tmpdir=tmp_path / "tmp") for _ in range(2)]
        done = [finish(p) for p in procs]
        assert sorted(code for code, _ in done) == [0, 2], done
        winner, loser = (0, 1) if done[0][0] == 0 else (1, 0)
        if "already holds results" not in done[loser][1]:
            break  # they overlapped (else the second started after the first had ended: try again)
    assert done[loser][1].strip() == in_use(out, procs[winner].pid)
    rows = whole_rows(out / "results.csv")
    assert len(rows) == 3001 and rows[-1][0] == pytest.approx(0.3)  # one run's rows, whole
    run = json.loads((out / "run.json").read_text())
    assert run["status"] == "completed"
    assert sorted(p.name for p in out.iterdir()) == [".tapmp.lock", "metrics.json", "results.csv", "run.json"]


def paused_while_writing(proc: subprocess.Popen, done: Path) -> bool:
    """Stop ``proc`` (SIGSTOP) and say whether it is stopped inside its output lock: alive and
    ``done`` (written inside the lock as its last act) not there yet. Else it is let go."""
    proc.send_signal(signal.SIGSTOP)
    if proc.poll() is None and not done.exists():
        return True
    proc.send_signal(signal.SIGCONT)
    return False


def run_finished(out: Path) -> Path:
    """A file that exists once the run into ``out`` has recorded its end (inside its lock)."""
    return out / "metrics.json"


def test_overwrite_does_not_take_a_folder_another_run_is_writing(built, tmp_path):
    for attempt in range(5):  # the first run is paused inside its lock, so the second meets it
        out = tmp_path / f"out{attempt}"
        first = start(*run_args(built["ssp"], out, 3), tmpdir=tmp_path / "tmp")
        wait_for_rows(out / "results.csv")
        if paused_while_writing(first, run_finished(out)):
            break
        finish(first)  # it had ended before it could be paused: try again
    else:
        pytest.fail("the first run always ended before it could be paused")
    second = start(*run_args(built["ssp"], out, 0.3, "--overwrite"), tmpdir=tmp_path / "tmp")
    result = finish(second)
    first.send_signal(signal.SIGCONT)
    assert result == (2, in_use(out, first.pid) + "\n")
    assert finish(first)[0] == 0
    assert len(whole_rows(out / "results.csv")) == 30001
    assert json.loads((out / "run.json").read_text())["status"] == "completed"


HOLD = ("import sys; from orchestrator.tool.folders import output_lock\n"
        "with output_lock(sys.argv[1]):\n    print('held', flush=True); sys.stdin.read()\n")


@pytest.fixture
def held(tmp_path):
    """An output folder locked by another process: (folder, pid of the holder)."""
    out = tmp_path / "held"
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(out)], stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, text=True)
    assert holder.stdout.readline() == "held\n"
    yield out, holder.pid
    holder.communicate("", timeout=30)


def test_compare_and_study_lock_their_output_folders(built, tmp_path, held):
    out, pid = held
    study = tmp_path / "s.toml"
    study.write_text(f'[study]\nbase = "{PAPER}"\n[set]\nstop_time = 0.01\n[grid]\nlaw = ["sc-dc"]\n')
    commands = {"compare": ("compare", PAPER, "--ssp", built["ssp"], "--out", out, "--set", "stop_time=0.01",
                            "--no-progress"),
                "study": ("study", study, "--ssp", built["ssp"], "--out", out, "--workers", "1", "--no-progress")}
    for name, args in commands.items():
        code, err = finish(start(*args, tmpdir=tmp_path / "tmp"))
        assert (code, err) == (2, in_use(out, pid) + "\n"), name
    assert sorted(p.name for p in out.iterdir()) == [".tapmp.lock"]  # nothing was written


def test_a_run_into_the_folder_or_a_subfolder_of_a_running_compare_is_refused(built, tmp_path):
    out = tmp_path / "cmp"
    compare = start("compare", PAPER, "--ssp", built["ssp"], "--out", out, "--set", "stop_time=3", "--no-progress",
                    tmpdir=tmp_path / "tmp")
    wait_for_rows(out / "sc-dc" / "results.csv")
    assert paused_while_writing(compare, out / "comparison.md"), "the compare ended before it could be paused"
    try:
        for folder in (out, out / "sc-dc"):
            code, err = finish(start(*run_args(built["ssp"], folder, 0.3, "--overwrite"), tmpdir=tmp_path / "tmp"))
            assert (code, err) == (2, in_use(folder, compare.pid) + "\n")
    finally:
        compare.terminate()
        compare.send_signal(signal.SIGCONT)
        finish(compare)


def test_json_files_are_written_under_unique_temporary_names(tmp_path):
    from orchestrator.tool.folders import write_json
    for i in range(3):
        write_json(tmp_path / "run.json", {"i": i})
    assert [p.name for p in tmp_path.iterdir()] == ["run.json"]
    assert json.loads((tmp_path / "run.json").read_text()) == {"i": 2}
    assert oct((tmp_path / "run.json").stat().st_mode & 0o777) == "0o644"


def cosim_folders(tmpdir: Path) -> list:
    return sorted(p.name for p in tmpdir.glob("tapmp_cosim_*"))


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP])
def test_sigterm_and_sighup_end_a_run_at_a_step_boundary(built, tmp_path, signum):
    out, tmpdir = tmp_path / "out", tmp_path / "tmp"
    proc = start(*run_args(built["ssp"], out, 60), tmpdir=tmpdir)
    wait_for_rows(out / "results.csv", n_bytes=500_000)
    assert len(cosim_folders(tmpdir)) == 1  # the run's extracted FMUs
    proc.send_signal(signum)
    code, err = finish(proc)
    name = signal.Signals(signum).name
    assert code == 128 + signum, err
    # after the one-line size estimate of a long run
    assert re.fullmatch(rf"(paper_simulation: about \S+ MB of results [^\n]*\n)?"
                        rf"interrupted by {name} at t = \S+ s: the results so far are in the output folder\n", err)
    rows = whole_rows(out / "results.csv")
    run = json.loads((out / "run.json").read_text())
    assert (run["status"], run["signal"], run["exit_code"]) == ("interrupted", name, 128 + signum)
    assert run["failed_at_s"] >= rows[-1][0] > 0.05 and not (out / "metrics.json").exists()
    assert cosim_folders(tmpdir) == []  # removed on the way out


def limit_file_size(n_bytes: int):
    """preexec_fn: files of the child may not grow beyond n_bytes (writes fail with EFBIG)."""
    def apply():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # else the kernel kills the writer
        resource.setrlimit(resource.RLIMIT_FSIZE, (n_bytes, n_bytes))
    return apply


@pytest.fixture
def small_disk(tmp_path):
    """A 2 MB file system for an output folder: (folder, preexec_fn for the child). A tmpfs if
    this process may mount one (root), else a 2 MB file size limit on the child: both make
    the real writes of results.csv fail, with ENOSPC or EFBIG."""
    disk = tmp_path / "disk"
    disk.mkdir()
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=2m", "tmpfs", str(disk)],
                             capture_output=True).returncode == 0
    yield disk, (None if mounted else limit_file_size(2 * 1024 * 1024))
    if mounted:
        subprocess.run(["umount", "-l", str(disk)], check=True)


def test_a_full_disk_ends_the_run_with_one_line_whole_rows_and_no_temporary_files(built, tmp_path, small_disk):
    disk, preexec = small_disk
    out, tmpdir = disk / "out", tmp_path / "tmp"
    tmpdir.mkdir()
    proc = subprocess.Popen([sys.executable, "-m", "orchestrator", *map(str, run_args(built["ssp"], out, 3))],
                            env=dict(os.environ, TMPDIR=str(tmpdir), TAPMP_NO_DISK_CHECK="1"),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=preexec)
    code, err = finish(proc)
    assert code == 2, err
    m = re.fullmatch(rf"error: cannot write {out / 'results.csv'}: (No space left on device \(errno 28\)|"
                     r"File too large \(errno 27\)): it keeps the rows up to t = (\S+) s, whole rows only\n", err)
    assert m, err
    rows = whole_rows(out / "results.csv")
    assert len(rows) >= 1000 and rows[-1][0] == pytest.approx(float(m.group(2)))
    assert [r[0] for r in rows] == pytest.approx([k * 1e-4 for k in range(len(rows))])  # none lost
    run = json.loads((out / "run.json").read_text())
    assert run["status"] == "failed" and run["exit_code"] == 2 and run["error"] == err[len("error: "):-1]
    assert sorted(p.name for p in out.iterdir()) == [".tapmp.lock", "results.csv", "run.json"]  # no *.tmp
    assert cosim_folders(tmpdir) == []


def test_stale_temporary_folders_of_dead_processes_are_removed_at_the_start_of_a_run(built, tmp_path):
    from orchestrator.engine.tempdirs import host as _host
    tmpdir = tmp_path / "tmp"
    dead = subprocess.Popen(["true"])
    dead.wait()
    folders = {"dead": f"tapmp_cosim_{dead.pid}_{_host()}_x1", "live": f"tapmp_cosim_{os.getpid()}_{_host()}_x2",
               "other host": f"tapmp_cosim_{dead.pid}_elsewhere_x3", "old name": "tapmp_cosim_x4"}
    for name in folders.values():
        (tmpdir / name / "fmu").mkdir(parents=True)
        (tmpdir / name / "fmu" / "plant.so").write_bytes(b"x")
    code, err = finish(start(*run_args(built["ssp"], tmp_path / "out", 0.01), tmpdir=tmpdir))
    assert code == 0, err
    assert cosim_folders(tmpdir) == sorted(folders[k] for k in ("live", "other host", "old name"))


def test_sigterm_to_a_study_stops_its_cases_and_leaves_no_temporary_folder(built, tmp_path):
    study, out, tmpdir = tmp_path / "s.toml", tmp_path / "out", tmp_path / "tmp"
    study.write_text(f'[study]\nbase = "{PAPER}"\nkeep_results = true\n[set]\nstop_time = 2.0\n'
                     '[grid]\n"gain_overrides.D" = [450.0, 900.0, 1800.0, 3600.0]\n')
    proc = start("study", study, "--ssp", built["ssp"], "--out", out, "--workers", "1", "--no-progress",
                 tmpdir=tmpdir)
    deadline = time.monotonic() + 180
    while time.monotonic() < deadline and not list((out / "cases").glob("*/results.csv")):
        time.sleep(0.05)  # a case is running on the worker
    assert cosim_folders(tmpdir), "no case started"
    proc.send_signal(signal.SIGTERM)
    code, err = finish(proc)
    assert code == 143, err
    assert err.strip().splitlines()[-1] == "interrupted by SIGTERM: the results so far are in the output folder"
    assert cosim_folders(tmpdir) == []
    with open(out / "study.csv", newline="") as f:
        table = list(csv.reader(f))
    assert all(len(r) == len(table[0]) for r in table) and len(table) < 1 + 4
    runs = [json.loads(p.read_text()) for p in (out / "cases").glob("*/run.json")]
    assert {r["status"] for r in runs} <= {"completed", "interrupted"}
    stopped = [r for r in runs if r["status"] == "interrupted"]
    assert stopped and all(r["signal"] == "SIGTERM" and "the study was stopped" in r["error"] for r in stopped)
    for case in (out / "cases").iterdir():
        whole_rows(case / "results.csv")
