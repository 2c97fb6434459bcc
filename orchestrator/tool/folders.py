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

Never delete or replace what tapmp did not write. A folder is tapmp's only if its marker at the top
(run.json, comparison.json, or plots.json of `tapmp plot`; a regular file, never a link) is a JSON
object of its "kind" that lists, under "tapmp_files", every file tapmp wrote there with its size
and sha256 (a file still being written: its inode). A hand-written JSON file does not carry that
list by accident, and a subfolder never vouches for its parent. Reusing or overwriting a marked
folder removes only the listed files whose size and sha256 still match: a listed file changed since
is the user's and stays; if the command would write a file of that name it refuses, one line naming
it, before anything is changed. A folder tapmp did not mark is written into only if it is empty, or
with overwrite if no file there has a name tapmp writes; otherwise it is refused before anything,
even the lock file, is made there.

Every file tapmp writes in an output folder is made under a unique temporary name in the same
folder and renamed over its target (os.replace, which replaces a link rather than following it); a
symbolic link where a file would go is refused with one line naming it (LinkInTheWayError), never
opened through.
"""

import hashlib
import json
import os
import stat
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

from filelock import FileLock, Timeout

from ..errors import UserError

FORMATS = {"csv": "results.csv", "mat": "results.mat"}  # scenario key format / --format -> file
RESULT_FORMATS = tuple(FORMATS)  # the allowed values of a scenario's format and of --format
PART_FILE = "results.part.npy"  # a MAT run's rows while it runs (writers.MatBlocks)
RUN_FILES = (*FORMATS.values(), PART_FILE, "run.json", "metrics.json")
REAL_TIME_FILES = ("real_time.png", "real_time_trace.csv")  # a paced run's figure, its per-step trace if asked
COMPARISON_JSON = "comparison.json"  # marks a comparison folder (kind "comparison")
LOCK_FILE = ".tapmp.lock"  # in every output folder while a tapmp writer holds it


class OutputExistsError(RuntimeError, UserError):
    """The output folder already holds results and overwriting was not asked for."""


class OutputInUseError(RuntimeError, UserError):
    """Another tapmp process (or thread) is writing into the output folder."""


class LinkInTheWayError(OutputExistsError):
    """A symbolic link stands where tapmp would write a file (never written through)."""


class ResultsWriteError(RuntimeError, UserError):
    """A result file could not be written (e.g. the disk is full); the message names it."""


def refuse_link(path: Path) -> None:
    """LinkInTheWayError (one line naming the link and its target) if ``path`` is a symbolic link."""
    if os.path.islink(path):
        raise LinkInTheWayError(f"{path} is a symbolic link (to {os.readlink(path)}): tapmp never writes through a "
                                "link; nothing was written there; remove the link or choose another folder with --out")


def _temporary(path: Path) -> tuple[int, str]:
    """A new file (fd, name) under a unique temporary name beside ``path``, readable by everyone."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.fchmod(fd, 0o644)  # mkstemp makes 0600; results are for everyone to read
    return fd, tmp


@contextmanager
def atomic_file(path: Path, mode: str = "w"):
    """A new file object (``mode`` "w" or "wb") that replaces ``path`` when the block ends
    without an error: a reader sees the old file or the whole new one. The temporary file
    has a unique name in the same folder and is removed on failure; a symbolic link at
    ``path`` is refused (refuse_link) before anything is written."""
    path = Path(path)
    refuse_link(path)
    fd, tmp = _temporary(path)
    try:
        with os.fdopen(fd, mode) as f:
            yield f
        _announce(path, os.stat(tmp).st_ino)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


_ANNOUNCERS = {}  # {absolute folder: announce(name, inode)} of the folders a run is writing (announcing)


@contextmanager
def announcing(folder: Path, announce):
    """While the block runs, each file atomic_file or new_stream makes directly in ``folder`` (but
    a marker: run.json, ...) is put on record by ``announce(name, inode)`` before the rename that
    gives it its name (the inode stays). A run killed at any moment then leaves no file of its
    names that its marker does not list as tapmp's, and the next run into the folder may replace it."""
    key = os.path.abspath(folder)
    _ANNOUNCERS[key] = announce
    try:
        yield
    finally:
        _ANNOUNCERS.pop(key, None)


def _announce(path: Path, inode: int) -> None:
    announce = _ANNOUNCERS.get(os.path.abspath(path.parent))
    if announce is not None and path.name not in MARKERS.values():
        announce(path.name, inode)


def new_stream(path: Path) -> int:
    """A writable descriptor of a new, empty file at ``path`` for a file written while a run goes on
    (results.csv, results.part.npy): made under a temporary name and renamed over ``path`` at once,
    so an existing file or link there is replaced, never opened. A link there is refused first."""
    path = Path(path)
    refuse_link(path)
    fd, tmp = _temporary(path)
    try:
        _announce(path, os.fstat(fd).st_ino)
        os.replace(tmp, path)
    except BaseException:
        os.close(fd)
        Path(tmp).unlink(missing_ok=True)
        raise
    return fd


def save_figure(fig, path: Path, **kwargs) -> Path:
    """Write the matplotlib figure ``fig`` to ``path`` (format from its suffix: png, svg) through
    atomic_file; ``kwargs`` go to savefig (e.g. dpi). Returns ``path``."""
    path = Path(path)
    with atomic_file(path, "wb") as f:
        fig.savefig(f, format=path.suffix[1:], **kwargs)
    return path


def write_text(path: Path, text: str) -> Path:
    """Write ``text`` to ``path`` through atomic_file; returns ``path``."""
    with atomic_file(path) as f:
        f.write(text)
    return Path(path)


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
PLOTS_JSON = "plots.json"  # marks a folder of tapmp plot's figures that is no run or comparison (kind "plots")
MARKERS = {"run": "run.json", "comparison": COMPARISON_JSON, "plots": PLOTS_JSON}  # files whose content marks a folder
WHAT = {"run": "a single run", "comparison": "a comparison", "plots": "figures of tapmp plot"}


def tapmp_names(kind: str) -> frozenset:
    """The fixed names of the files tapmp writes into a result folder of ``kind`` ("run" or
    "comparison"); besides them tapmp writes only its lock file, temporary files named
    ``.<name>.*.tmp`` while it writes (renamed or removed at once) and, in a comparison, one run
    folder per compared run."""
    if kind == "run":
        figs = [f"run_{stem}.{ext}" for stem in FIGURE_STEMS for ext in _FIGURE_EXTS]
        return frozenset((*RUN_FILES, *REAL_TIME_FILES, *figs, *(f"signals.{ext}" for ext in _FIGURE_EXTS)))
    figs = [f"{stem}.{ext}" for stem in (*FIGURE_STEMS, "signals") for ext in _FIGURE_EXTS]
    return frozenset((COMPARISON_JSON, "comparison.md", *figs))


MANIFEST = "tapmp_files"  # the marker's key: {name: file_record or stream_record} of the files tapmp wrote
_HEX = frozenset("0123456789abcdef")


def file_record(path: Path) -> dict:
    """The proof that tapmp wrote the regular file ``path``: {"size": bytes, "sha256": hex digest}
    (read without following a link)."""
    fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_CLOEXEC)
    digest, size = hashlib.sha256(), 0
    with os.fdopen(fd, "rb") as f:
        while chunk := f.read(1 << 20):  # hashlib.file_digest is Python 3.11+; 3.10 is supported
            digest.update(chunk)
            size += len(chunk)
    return {"size": size, "sha256": digest.hexdigest()}


def stream_record(inode: int) -> dict:
    """The proof for a file tapmp is writing (results.csv while a run goes on, any file of a run
    about to take its name: announcing): its inode, replaced by file_record when the run ends (only
    a killed run leaves it)."""
    return {"writing": True, "inode": int(inode)}


def _valid_record(rec) -> bool:
    if not isinstance(rec, dict):
        return False
    if rec.get("writing") is True:
        return isinstance(rec.get("inode"), int)
    sha = rec.get("sha256")
    return (isinstance(rec.get("size"), int) and not isinstance(rec.get("size"), bool) and isinstance(sha, str)
            and len(sha) == 64 and set(sha) <= _HEX)


def matches(path: Path, rec: dict) -> bool:
    """Whether ``path`` is still the regular file tapmp wrote as ``rec`` records it (same size and
    sha256, or for a file it was writing the same inode); a link never matches."""
    try:
        st = os.lstat(path)
        if not stat.S_ISREG(st.st_mode):
            return False
        if rec.get("writing") is True:
            return st.st_ino == rec["inode"]
        return st.st_size == rec["size"] and file_record(path)["sha256"] == rec["sha256"]
    except OSError:
        return False


def marker(folder) -> tuple[str, dict] | None:
    """(kind, {name: record}) if tapmp marked ``folder`` as its own: a marker file of MARKERS at its
    top (a regular file, not a link) holding a JSON object of that "kind" with a valid MANIFEST of
    files directly in the folder; else None."""
    for kind, name in MARKERS.items():
        path = Path(folder) / name
        if os.path.islink(path):
            continue
        info = read_json(path)
        files = info.get(MANIFEST) if isinstance(info, dict) and info.get("kind") == kind else None
        if isinstance(files, dict) and all(isinstance(n, str) and n and "/" not in n and n not in (".", "..", name)
                                           and _valid_record(r) for n, r in files.items()):
            return kind, files
    return None


def marked_kind(folder) -> str | None:
    """"run", "comparison" or "plots" if tapmp marked ``folder`` as its own (marker), else None.
    Only a marked folder is tapmp's to reuse or overwrite; what its subfolders hold says nothing
    about it."""
    found = marker(folder)
    return found[0] if found else None


def record_files(folder: Path, files: dict, names, known: dict | None = None) -> dict:
    """Put on record in ``files`` (a marker's MANIFEST) each of ``names`` in ``folder`` as it is
    now (file_record, or the record in ``known`` {name: record} computed as the file was written,
    if its size agrees); a name that is no regular file there is dropped. Returns ``files``."""
    for name in names:
        path = Path(folder) / name
        try:
            st = os.lstat(path)
            if stat.S_ISREG(st.st_mode):
                rec = (known or {}).get(name)
                files[name] = rec if rec and rec["size"] == st.st_size else file_record(path)
                continue
        except OSError:
            pass
        files.pop(name, None)
    return files


def add_to_marker(folder: Path, names) -> None:
    """Put the files ``names`` just written into ``folder`` on record in its marker (a run.json or
    comparison.json tapmp wrote is rewritten with them; a folder without a marker gets plots.json,
    kind "plots"). Call it holding the folder's output_lock."""
    folder = Path(folder)
    found = marker(folder)
    kind = found[0] if found else "plots"
    info = read_json(folder / MARKERS[kind]) if found else {"kind": "plots"}
    info[MANIFEST] = record_files(folder, dict(found[1]) if found else {}, names)
    write_result(folder / MARKERS[kind], info)


def folder_completed(folder) -> bool:
    """Whether a result folder tapmp marked holds a completed run or comparison: status
    "completed" in run.json / comparison.json; a run's metrics.json (written only on completion)
    counts as completed too (never reuse what might be good results); figures of `tapmp plot`
    (plots.json) count as completed."""
    folder = Path(folder)
    kind = marked_kind(folder)
    if kind == "run":
        return (folder / "metrics.json").exists() or read_json(folder / "run.json").get("status") == "completed"
    if kind == "comparison":
        return read_json(folder / COMPARISON_JSON).get("status") == "completed"
    return kind == "plots"


def writes(kind: str) -> tuple:
    """The files (besides its marker) a run or a comparison writes at the top of its folder."""
    if kind == "run":
        return tuple(n for n in RUN_FILES if n != MARKERS["run"])
    return ("comparison.md", *(f"{stem}.png" for stem in FIGURE_STEMS))


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


def check_targets(folder: Path, names, found: tuple | None) -> None:
    """Refuse (one line, nothing changed) to write the files ``names`` into ``folder`` if one is a
    symbolic link (LinkInTheWayError) or a file that the folder's marker (``found``, as marker
    returns it) does not list as tapmp wrote it: the user's, or changed since (OutputExistsError)."""
    folder = Path(folder)
    for name in names:
        refuse_link(folder / name)
    files = found[1] if found else {}
    theirs = [n for n in names if os.path.lexists(folder / n) and not (n in files and matches(folder / n, files[n]))]
    if theirs:
        it = "it" if len(theirs) == 1 else "them"
        record = (f"{MARKERS[found[0]]} does not list {it} as tapmp wrote {it}" if found
                  else f"no {', '.join(MARKERS.values())} of tapmp lists {it}")
        raise OutputExistsError(f"output folder {folder} holds {_listing(theirs)}, which tapmp did not write or which "
                                f"was changed since ({record}) and would replace: nothing was changed; move {it} "
                                "away or choose another folder with --out")


def check_output(out: Path, overwrite: bool, kind: str = "run", runs=(), unmarked_only: bool = False) -> None:
    """Refuse (OutputExistsError, one line naming the folder, nothing changed) to write a result
    of ``kind`` ("run" or "comparison", with the run folders ``runs``) into ``out`` if: it holds
    another kind; it holds a completed result and not ``overwrite``; tapmp did not mark it
    (marker) and it holds anything but tapmp's lock file, unless ``overwrite`` (then results are
    written beside those files); a file tapmp did not write (unmarked, or not on record as
    written) would be replaced by one tapmp writes, whatever ``overwrite`` says; or a symbolic
    link stands where tapmp writes a file (LinkInTheWayError).
    ``unmarked_only``: only the unmarked checks (before the lock is taken: a folder tapmp marked
    may be another writer's, which the lock reports)."""
    out = Path(out)
    if not out.is_dir():
        return  # made by output_lock (a file there is refused by the file system, one line)
    found = marker(out)
    marked = found[0] if found else None
    if unmarked_only and marked is not None:
        return
    name = MARKERS[kind]
    if marked is not None and marked != kind:
        raise OutputExistsError(f"output folder {out} holds {WHAT[marked]} ({MARKERS[marked]}), not {WHAT[kind]}: "
                                f"choose another folder with --out")
    if marked is None:
        for target in (name, *writes(kind)):
            refuse_link(out / target)
        foreign = [e.name for e in _entries(out)]
        clobbered = _unmarked_clobbered(out, kind, runs)
        if clobbered:
            raise OutputExistsError(f"output folder {out} holds {_listing(clobbered)}, which tapmp did not write (no "
                                    f"{name} of tapmp marks the folder as {WHAT[kind]}) and would replace: nothing "
                                    f"was changed; move {'it' if len(clobbered) == 1 else 'them'} away or choose "
                                    "another folder with --out")
        if foreign and not overwrite:
            raise OutputExistsError(f"output folder {out} holds files tapmp did not write ({_listing(foreign)}; no "
                                    f"{name} of tapmp marks it as {WHAT[kind]}): nothing was changed; choose a new "
                                    "or empty folder with --out, or pass --overwrite to write beside them")
        return
    if folder_completed(out) and not overwrite:
        raise OutputExistsError(f"output folder {out} already holds results of a completed {kind}: "
                                "choose another with --out or pass --overwrite")
    check_targets(out, writes(kind), found)
    for run in runs if kind == "comparison" else ():
        check_output(out / run, True, "run")  # replaced as part of the comparison


def prepare_output(out: Path, overwrite: bool, kind: str = "run", runs=()) -> Path:
    """Create the output folder for a result of ``kind`` ("run" or "comparison", with the run
    folders ``runs``) after :func:`check_output`. A folder tapmp marked whose run or comparison
    failed, was interrupted or never finished (or, with ``overwrite``, completed) is reused: of
    its files only those its marker lists as tapmp wrote them, unchanged since, are removed;
    anything else there stays. Call it holding the folder's output_lock."""
    out = Path(out)
    check_output(out, overwrite, kind, runs)
    found = marker(out)
    if found and found[0] == kind:
        for name, rec in found[1].items():
            if matches(out / name, rec):
                (out / name).unlink()
    out.mkdir(parents=True, exist_ok=True)
    return out


def write_comparison_status(out: Path, scenario_name: str, runs: dict, status: str, files: dict | None = None,
                            **extra) -> None:
    """comparison.json of a comparison folder: kind, scenario, the compared runs
    {folder name: law}, status ("running", "completed", "failed", "interrupted") and the
    files tapmp wrote at its top (``files``, MANIFEST)."""
    write_result(Path(out) / COMPARISON_JSON, {"kind": "comparison", "scenario": scenario_name,
                                              "runs": dict(runs), "status": status, **extra,
                                              MANIFEST: dict(files or {})})
