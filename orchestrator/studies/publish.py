"""Case files written by the worker straight into a location the user names (``--results-url``),
instead of travelling back through the client.

The location is an absolute path that every worker sees (a shared file system), or an fsspec URL
of a file system that can rename a file (``ftp://USER:PASSWORD@HOST:PORT/FOLDER``, tested with a
real FTP server; ``s3://``, ``sftp://`` and the others fsspec knows work if their fsspec package is
installed on every worker). A case's files go to ``LOCATION/CASE/NAME``, each written under a
temporary name in the same folder and then renamed, so a worker killed mid-write leaves a stray
``.NAME.*.tmp`` file at worst, never a cut file under the real name; a case run again replaces its
files. The client checks the location before the first case (check_location: it can make the
folder, write a file and rename it).
"""

import json
import os
from pathlib import Path

from .study_file import StudyError


def _fs(url: str):
    """(fsspec file system, path) of ``url``; StudyError naming it for an unknown protocol or a
    relative path (the workers' working folders are not the client's)."""
    import fsspec
    protocol = url.split("://", 1)[0] if "://" in url else ""
    if not protocol and not os.path.isabs(url):
        raise StudyError(f"--results-url = {url!r} is invalid: allowed is an absolute path every worker sees, or "
                         "an fsspec URL such as ftp://USER:PASSWORD@HOST/FOLDER")
    try:
        return fsspec.core.url_to_fs(url)
    except (ValueError, ImportError) as err:
        raise StudyError(f"--results-url = {url!r} is invalid: {' '.join(str(err).split())}; allowed is an "
                         "absolute path every worker sees, or an fsspec URL such as ftp://USER:PASSWORD@HOST/FOLDER "
                         "(its fsspec package installed)") from None


def shown(url: str) -> str:
    """``url`` with any password replaced by ***, for messages and run records."""
    if "://" in url and "@" in url.split("://", 1)[1].split("/", 1)[0]:
        protocol, rest = url.split("://", 1)
        auth, host = rest.split("@", 1)
        user = auth.split(":", 1)[0]
        return f"{protocol}://{user}:***@{host}" if ":" in auth else url
    return url


def _write(fs, path: str, data: bytes) -> None:
    """``data`` to ``path`` under a temporary name in its folder, then renamed onto it."""
    folder, name = path.rsplit("/", 1)
    tmp = f"{folder}/.{name}.{os.urandom(4).hex()}.tmp"
    try:
        with fs.open(tmp, "wb") as f:
            f.write(data)
        fs.mv(tmp, path)
    except BaseException:
        try:
            fs.rm(tmp)
        except Exception:
            pass  # the connection is gone: a stray temporary file, never a cut file under the real name
        raise


def check_location(url: str) -> None:
    """Make the folder ``url`` and write, rename and remove a file there; StudyError naming the
    location (its password hidden) and the reason if any step fails."""
    try:
        fs, root = _fs(url)  # a server is connected to here (ftp: log in)
        probe = f"{root.rstrip('/')}/.tapmp-probe-{os.urandom(4).hex()}"
        fs.makedirs(root, exist_ok=True)
        _write(fs, probe, b"tapmp\n")
        fs.rm(probe)
    except StudyError:
        raise
    except Exception as err:
        raise StudyError(f"--results-url {shown(url)}: cannot write there ({type(err).__name__}: "
                         f"{' '.join(str(err).split())})") from None


def publish_folder(folder: Path, url: str, case: str, ssp: str) -> int:
    """Write every file a case left in ``folder`` (its lock file aside) to ``url``/``case``/NAME
    (see the module); run.json names the client's SSP path ``ssp``, as after a local study.
    Returns the bytes written."""
    from ..tool.folders import LOCK_FILE
    fs, root = _fs(url)
    target = f"{root.rstrip('/')}/{case}"
    fs.makedirs(target, exist_ok=True)
    total = 0
    for path in sorted(Path(folder).iterdir()):
        if not path.is_file() or path.name == LOCK_FILE:
            continue
        data = path.read_bytes()
        if path.name == "run.json":
            info = json.loads(data)
            info["ssp"] = ssp
            data = (json.dumps(info, indent=2, default=str) + "\n").encode()
        _write(fs, f"{target}/{path.name}", data)
        total += len(data)
    return total
