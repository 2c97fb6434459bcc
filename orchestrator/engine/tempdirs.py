"""Temporary folders of co-simulations (the extracted FMUs), made by tempfile.mkdtemp.

A folder is removed when its co-simulation closes (or its object is collected). A process
killed outright (SIGKILL, a worker ended by its pool) cannot remove its own, so every
folder is named after its process, tapmp_cosim_<pid>_<host>_*, and remove_stale_folders
(called at the start of every run and at the end of a study) removes those whose process
no longer exists.
"""

import os
import re
import shutil
import socket
import tempfile
from pathlib import Path

PREFIX = "tapmp_cosim_"
_NAME = re.compile(r"tapmp_cosim_(\d+)_([A-Za-z0-9.-]*)_.+")


def host() -> str:
    """This machine's name as it appears in temporary folder names."""
    return re.sub(r"[^A-Za-z0-9.-]", "-", socket.gethostname())[:64]


def make_folder() -> Path:
    """A new temporary folder of this process (tempfile.mkdtemp, tapmp_cosim_<pid>_<host>_*)."""
    return Path(tempfile.mkdtemp(prefix=f"{PREFIX}{os.getpid()}_{host()}_"))


def _alive(pid: int) -> bool:
    """Whether a process ``pid`` exists on this machine (owned by anyone)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale_folders(tmpdir=None) -> list:
    """Remove the temporary folders that processes of this machine left in ``tmpdir``
    (default: tempfile.gettempdir()) when they were killed: only those whose owner pid no
    longer exists. Returns the removed paths."""
    root = Path(tmpdir or tempfile.gettempdir())
    removed, here = [], host()
    try:
        entries = list(os.scandir(root))
    except OSError:
        return removed
    for entry in entries:
        m = _NAME.fullmatch(entry.name)
        if not m or m.group(2) != here or int(m.group(1)) == os.getpid() or _alive(int(m.group(1))):
            continue
        if entry.is_dir(follow_symlinks=False):
            shutil.rmtree(entry.path, ignore_errors=True)
            removed.append(Path(entry.path))
    return removed
