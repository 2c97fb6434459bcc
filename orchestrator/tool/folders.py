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
interrupted or never finished is (its old result files are removed first); a folder of the other
kind (run / comparison) is refused even with overwrite.

Never delete what tapmp did not write: a folder is tapmp's only if tapmp marked it (run.json or
comparison.json of its kind, written first); reusing or overwriting it removes only the files of
fixed names tapmp writes there (tapmp_names), so a user's notes stay. A folder tapmp did not mark
is written into only if it is empty, or with overwrite if no file there has a name tapmp writes;
otherwise it is refused before anything, even the lock file, is made there.
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
    """What a result folder holds, for reading it: "comparison" (comparison.json, or a comparison
    written before comparison.json existed: no run files of its own and run folders below), "run"
    (any of RUN_FILES) or None (nothing of tapmp's)."""
    folder = Path(folder)
    if (folder / COMPARISON_JSON).is_file():
        return "comparison"
    if any((folder / f).exists() for f in RUN_FILES):
        return "run"
    if folder.is_dir() and any((p / "run.json").is_file() for p in folder.iterdir() if p.is_dir()):
        return "comparison"
    return None


# The figures `tapmp plot` and `tapmp compare` write (plots.py): run_<stem> in a run folder, <stem>
# in a comparison folder, signals (--signals) in either; PNG, and SVG with --svg.
FIGURE_STEMS = ("fig4_trajectory", "fig5_tracking_errors", "fig6_sync_errors", "fig7_axis_errors",
                "fig8_force_commands")
_FIGURE_EXTS = ("png", "svg")
MARKERS = {"run": "run.json", "comparison": COMPARISON_JSON}  # the file whose content makes a folder tapmp's
WHAT = {"run": "a single run", "comparison": "a comparison"}


def tapmp_names(kind: str) -> frozenset:
    """The fixed names of the files tapmp writes into a result folder of ``kind`` ("run" or
    "comparison"); besides them tapmp writes only its lock file, temporary files named
    ``.<name>.*.tmp`` while it writes (renamed or removed at once) and, in a comparison, one run
    folder per compared run."""
    if kind == "run":
        figs = [f"run_{stem}.{ext}" for stem in FIGURE_STEMS for ext in _FIGURE_EXTS]
        return frozenset((*RUN_FILES, *figs, *(f"signals.{ext}" for ext in _FIGURE_EXTS)))
    figs = [f"{stem}.{ext}" for stem in (*FIGURE_STEMS, "signals") for ext in _FIGURE_EXTS]
    return frozenset((COMPARISON_JSON, "comparison.md", *figs))


def marked_kind(folder) -> str | None:
    """"run" or "comparison" if tapmp marked ``folder`` as its own (a run.json or comparison.json
    it wrote: a JSON object of that "kind"; or a comparison from before comparison.json existed:
    no run.json of its own and run folders tapmp marked below), else None. Only a marked folder
    is tapmp's to reuse or overwrite."""
    folder = Path(folder)
    for kind, marker in MARKERS.items():
        info = read_json(folder / marker)
        if isinstance(info, dict) and info.get("kind") == kind:
            return kind
    if not (folder / MARKERS["run"]).exists() and not (folder / COMPARISON_JSON).exists() and folder.is_dir() \
            and any(marked_kind(p) == "run" for p in folder.iterdir() if p.is_dir() and not p.is_symlink()):
        return "comparison"
    return None


def folder_completed(folder) -> bool:
    """Whether a result folder tapmp marked holds a completed run or comparison: status
    "completed" in run.json / comparison.json; a run's metrics.json (written only on completion)
    counts as completed too (never reuse what might be good results); a comparison without
    comparison.json is completed if one of its runs is."""
    folder = Path(folder)
    kind = marked_kind(folder)
    if kind == "run":
        return (folder / "metrics.json").exists() or read_json(folder / "run.json").get("status") == "completed"
    if kind == "comparison":
        info = read_json(folder / COMPARISON_JSON)
        if isinstance(info, dict):
            return info.get("status") == "completed"
        return any(folder_completed(p) for p in folder.iterdir() if p.is_dir() and marked_kind(p) == "run")
    return False


def _listing(names: list, limit: int = 5) -> str:
    names = sorted(names)
    more = f" and {len(names) - limit} more" if len(names) > limit else ""
    return ", ".join(names[:limit]) + more


def _entries(folder: Path) -> list:
    """The entries of ``folder`` other than tapmp's lock file ([] if it does not exist)."""
    try:
        return [e for e in folder.iterdir() if e.name != LOCK_FILE]
    except FileNotFoundError:
        return []
    except NotADirectoryError:
        return []


def _unmarked_clobbered(folder: Path, kind: str, runs=(), prefix: str = "") -> list:
    """The entries of the unmarked ``folder`` that a result of ``kind`` would replace: tapmp's
    fixed names, and in a comparison's run folders (``runs``) those of a run, as paths relative to
    the top folder (``prefix``)."""
    names = tapmp_names(kind)
    out = []
    for e in _entries(folder):
        if e.name in names:
            out.append(prefix + e.name)
        elif kind == "comparison" and e.name in runs and e.is_dir() and not e.is_symlink():
            if marked_kind(e) is None:
                out += _unmarked_clobbered(e, "run", prefix=f"{prefix}{e.name}/")
        elif kind == "comparison" and e.name in runs:
            out.append(prefix + e.name)  # a file or link where a run folder goes
    return out


def check_output(out: Path, overwrite: bool, kind: str = "run", runs=(), unmarked_only: bool = False) -> None:
    """Refuse (OutputExistsError, one line naming the folder, nothing changed) to write a result
    of ``kind`` ("run" or "comparison", with the run folders ``runs``) into ``out`` if: it holds
    the other kind; it holds a completed result and not ``overwrite``; tapmp did not mark it
    (marked_kind) and it holds anything but tapmp's lock file, unless ``overwrite`` (then
    results are written beside those files); or an unmarked file would be replaced by one tapmp
    writes (whatever ``overwrite`` says: tapmp never deletes what it did not write).
    ``unmarked_only``: only the last two (before the lock is taken: a folder tapmp marked may be
    another writer's, which the lock reports)."""
    out = Path(out)
    if not out.is_dir():
        return  # made by output_lock (a file there is refused by the file system, one line)
    marked = marked_kind(out)
    if unmarked_only and marked is not None:
        return
    marker = MARKERS[kind]
    if marked is not None and marked != kind:
        raise OutputExistsError(f"output folder {out} holds {WHAT[marked]} ({MARKERS[marked]}), not {WHAT[kind]}: "
                                f"choose another folder with --out")
    if marked is None:
        foreign = [e.name for e in _entries(out)]
        clobbered = _unmarked_clobbered(out, kind, runs)
        if clobbered:
            raise OutputExistsError(f"output folder {out} holds {_listing(clobbered)}, which tapmp did not write (no "
                                    f"{marker} of tapmp marks the folder as {WHAT[kind]}) and would replace: nothing "
                                    f"was changed; move {'it' if len(clobbered) == 1 else 'them'} away or choose "
                                    "another folder with --out")
        if foreign and not overwrite:
            raise OutputExistsError(f"output folder {out} holds files tapmp did not write ({_listing(foreign)}; no "
                                    f"{marker} of tapmp marks it as {WHAT[kind]}): nothing was changed; choose a new "
                                    "or empty folder with --out, or pass --overwrite to write beside them")
        return
    if folder_completed(out) and not overwrite:
        raise OutputExistsError(f"output folder {out} already holds results of a completed {kind}: "
                                "choose another with --out or pass --overwrite")
    for name in runs if kind == "comparison" else ():
        check_output(out / name, True, "run")  # replaced as part of the comparison


def prepare_output(out: Path, overwrite: bool, kind: str = "run", runs=()) -> Path:
    """Create the output folder for a result of ``kind`` ("run" or "comparison", with the run
    folders ``runs``) after :func:`check_output`. A run folder tapmp marked whose run failed, was
    interrupted or never finished (or, with ``overwrite``, completed) is reused: of its files only
    those tapmp writes (tapmp_names) are removed; anything else there stays. Call it holding the
    folder's output_lock."""
    out = Path(out)
    check_output(out, overwrite, kind, runs)
    if kind == "run" and marked_kind(out) == "run":
        for name in tapmp_names("run"):
            (out / name).unlink(missing_ok=True)
    out.mkdir(parents=True, exist_ok=True)
    return out


def write_comparison_status(out: Path, scenario_name: str, runs: dict, status: str, **extra) -> None:
    """comparison.json of a comparison folder: kind, scenario, the compared runs
    {folder name: law}, status ("running", "completed", "failed", "interrupted")."""
    write_result(Path(out) / COMPARISON_JSON, {"kind": "comparison", "scenario": scenario_name,
                                              "runs": dict(runs), "status": status, **extra})
