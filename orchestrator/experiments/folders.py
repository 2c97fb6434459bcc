"""Result folders: what they hold, atomic JSON files in them, and one writer at a time.

A run folder holds run.json (kind "run"), metrics.json and the rows (FORMATS); a
comparison folder holds comparison.json (kind "comparison") and one run folder per
compared law. JSON files are written atomically (a uniquely named temporary file in the
same folder, then os.replace).

One writer per output folder: a run holds an exclusive lock (filelock's FileLock, an
fcntl.flock on OUT/.tapmp.lock, which records the holder's pid) from before it looks at
the folder until its last file is written; a second writer is refused (OutputInUseError),
also with overwrite. The lock is re-entrant within one thread (a command may lock a folder
and then run into it) and released by the kernel if the process dies, even by SIGKILL. A
folder whose run completed is never reused without overwrite; one whose run failed, was
interrupted or never finished is (its old files are removed first); a folder of the other
kind (run / comparison) is refused even with overwrite.
"""

import json
import os
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

from filelock import FileLock, Timeout

FORMATS = {"csv": "results.csv", "mat": "results.mat"}  # scenario key format / --format -> file
PART_FILE = "results.part.npy"  # a MAT run's rows while it runs (writers.MatBlocks)
RUN_FILES = (*FORMATS.values(), PART_FILE, "run.json", "metrics.json")
COMPARISON_JSON = "comparison.json"  # marks a comparison folder (kind "comparison")
LOCK_FILE = ".tapmp.lock"  # in every output folder while a tapmp writer holds it


class OutputExistsError(RuntimeError):
    """The output folder already holds results and overwriting was not asked for."""


class OutputInUseError(RuntimeError):
    """Another tapmp process (or thread) is writing into the output folder."""


class ResultsWriteError(RuntimeError):
    """A result file could not be written (e.g. the disk is full); the message names it."""


@contextmanager
def atomic_file(path: Path, mode: str = "w"):
    """A new file object (``mode`` "w" or "wb") that replaces ``path`` when the block ends
    without an error: a reader sees the old file or the whole new one. The temporary file
    has a unique name in the same folder and is removed on failure."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, mode) as f:
            os.fchmod(f.fileno(), 0o644)  # mkstemp makes 0600; results are for everyone to read
            yield f
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_json(path: Path, data) -> None:
    """Write JSON atomically (atomic_file)."""
    text = json.dumps(data, indent=2, default=str) + "\n"
    with atomic_file(path) as f:
        f.write(text)


def write_result(path: Path, data) -> None:
    """write_json, with an OSError (e.g. a full disk) as ResultsWriteError naming the file."""
    try:
        write_json(path, data)
    except OSError as err:
        raise ResultsWriteError(f"cannot write {path}: {err.strerror or err} (errno {err.errno})") from err


def read_json(path: Path):
    """The JSON content of ``path``, or None if it is missing or unreadable."""
    try:
        return json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None


def _record_pid(fd: int) -> None:
    """Put this process's pid on record in the lock file just locked (for a refused writer's message)."""
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
    except OSError:
        pass  # a full disk: the lock holds all the same, only the pid is not on record


def _lock_holder(path: Path) -> str:
    """The pid recorded in a lock file held by someone else ("unknown" if not yet written)."""
    for _ in range(20):  # the holder writes its pid right after taking the lock
        try:
            text = path.read_text(errors="replace").strip()
        except OSError:
            text = ""
        if text:
            return text
        time.sleep(0.05)
    return "unknown"


@contextmanager
def output_lock(folder):
    """Hold the exclusive lock of the output folder ``folder`` (created if missing) for the
    duration; OutputInUseError names the holder's pid if another writer holds it."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / LOCK_FILE
    # One lock object per file in this process, its count per thread: re-entrant in one thread, while
    # another thread's attempt contends like another process's. No soft-lock fallback: a lock file
    # left by a killed process must never block; the file stays (it is the lock, not a marker).
    lock = FileLock(path, is_singleton=True, blocking=False, fallback_to_soft=False, preserve_lock_file=True,
                    on_acquired=_record_pid)
    try:
        lock.acquire()
    except Timeout:
        holder = _lock_holder(path)
        if holder == str(os.getpid()):
            raise OutputInUseError(f"output folder {folder} is in use by another thread of this process "
                                   f"(pid {holder}): allowed is one writer per output folder") from None
        raise OutputInUseError(f"output folder {folder} is in use by tapmp (pid {holder}): "
                               "allowed is one writer per output folder; wait for it to end or choose "
                               "another --out") from None
    try:
        yield folder
    finally:
        if lock.lock_counter == 1:
            try:
                os.truncate(path, 0)  # no stale pid on record once released
            except OSError:
                pass
        lock.release()


def folder_kind(folder) -> str | None:
    """What a result folder holds: "comparison" (comparison.json, or a comparison written before
    comparison.json existed: no run files of its own and run folders below), "run" (any of
    RUN_FILES) or None (nothing of tapmp's)."""
    folder = Path(folder)
    if (folder / COMPARISON_JSON).is_file():
        return "comparison"
    if any((folder / f).exists() for f in RUN_FILES):
        return "run"
    if folder.is_dir() and any((p / "run.json").is_file() for p in folder.iterdir() if p.is_dir()):
        return "comparison"
    return None


def folder_completed(folder) -> bool:
    """Whether a result folder holds a completed run or comparison: status "completed"
    in run.json / comparison.json; a run's metrics.json (written only on completion) or an
    unreadable run.json count as completed too (never reuse what might be good results);
    a comparison without comparison.json is completed if one of its runs is."""
    folder = Path(folder)
    kind = folder_kind(folder)
    if kind == "run":
        info = read_json(folder / "run.json")
        if (folder / "metrics.json").exists() or ((folder / "run.json").exists() and info is None):
            return True
        return isinstance(info, dict) and info.get("status") == "completed"
    if kind == "comparison":
        info = read_json(folder / COMPARISON_JSON)
        if info is not None:
            return info.get("status") == "completed"
        return any(folder_completed(p) for p in folder.iterdir() if p.is_dir())
    return False


def prepare_output(out: Path, overwrite: bool, kind: str = "run") -> Path:
    """Create the output folder for a result of ``kind`` ("run" or "comparison"). Refused
    (OutputExistsError, one line naming --out, and --overwrite where it would help): a
    folder holding the other kind, and one holding a completed result unless overwrite.
    A folder of the same kind whose result failed, was interrupted or never finished is
    reused: its run files (and figures of a run) are removed. Call it holding the
    folder's output_lock."""
    out = Path(out)
    existing = folder_kind(out) if out.exists() else None
    if existing is not None and existing != kind:
        marker = COMPARISON_JSON if existing == "comparison" else "run.json"
        what = {"run": "a single run", "comparison": "a comparison"}
        raise OutputExistsError(f"output folder {out} holds {what[existing]} ({marker}), not {what[kind]}: "
                                f"choose another folder with --out")
    if existing is not None and folder_completed(out) and not overwrite:
        raise OutputExistsError(f"output folder {out} already holds results of a completed {kind}: "
                                "choose another with --out or pass --overwrite")
    if kind == "run":
        for f in RUN_FILES:
            (out / f).unlink(missing_ok=True)
        for fig in out.glob("run_fig*.png") if out.exists() else ():
            fig.unlink()
    out.mkdir(parents=True, exist_ok=True)
    return out


def write_comparison_status(out: Path, scenario_name: str, runs: dict, status: str, **extra) -> None:
    """comparison.json of a comparison folder: kind, scenario, the compared runs
    {folder name: law}, status ("running", "completed", "failed", "interrupted")."""
    write_result(Path(out) / COMPARISON_JSON, {"kind": "comparison", "scenario": scenario_name,
                                              "runs": dict(runs), "status": status, **extra})
