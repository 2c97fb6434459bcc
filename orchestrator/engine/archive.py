"""Names inside an SSP archive: an SSD source or a zip member, checked to stay inside it.

fmpy's own ``extract`` refuses backslashes, drive letters and a leading ``/`` but lets
zipfile drop ``..`` silently (so a member may land elsewhere than it says), and it does not
look at the SSD's source references at all: the master checks both with this one rule.

What an SSP and its FMUs may write when extracted is bounded too (:class:`ExtractBudget`): in
total at most $TAPMP_EXTRACT_LIMIT (default 2 GiB), checked against the declared sizes before a
member is written and against the bytes actually written while it is.
"""

import os
import posixpath
import re
import zipfile
from pathlib import Path

MEMBER_RULE = ("allowed is a relative path inside the archive, without a leading /, a URI scheme, "
               "backslashes or .. above its root, e.g. resources/TAPMP_Plant.fmu")


def inside_archive(path: str) -> str | None:
    """``path`` (an SSD source or an archive member name) normalized relative to the archive
    root, or None if it is absolute, a URI, holds a backslash or NUL or climbs out with ``..``."""
    if not isinstance(path, str) or not path or "\\" in path or "\0" in path \
            or path.startswith("/") or re.match(r"[A-Za-z][A-Za-z0-9+.-]*:", path):
        return None
    norm = posixpath.normpath(path)
    if norm in (".", "..") or norm.startswith("../"):
        return None
    return norm


# -- how much an SSP and its FMUs may write when extracted ---------------------------------

LIMIT_ENV = "TAPMP_EXTRACT_LIMIT"
DEFAULT_LIMIT = 2 * 2**30  # bytes: the project's SSPs extract to about 20 MB; a deflate bomb writes ~1 GiB per MB
_UNITS = {"": 1, "k": 2**10, "kib": 2**10, "m": 2**20, "mib": 2**20, "g": 2**30, "gib": 2**30, "t": 2**40,
          "tib": 2**40}
_CHUNK = 1 << 20


class ExtractLimitError(ValueError):
    """Extracting an archive would write more than the limit, or the limit setting is invalid; one line."""


def size_text(n: int) -> str:
    """``n`` bytes as the largest binary unit that keeps it >= 1 (e.g. "2 GiB", "1.5 MiB")."""
    for unit, factor in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if n >= factor:
            return f"{n / factor:.4g} {unit}"
    return f"{n} B"


def extract_limit() -> int:
    """The total number of bytes a co-simulation may extract from its SSP and FMUs:
    $TAPMP_EXTRACT_LIMIT (bytes, or with a binary unit: 8GiB, 500MiB, 8G), else DEFAULT_LIMIT."""
    text = os.environ.get(LIMIT_ENV, "").strip()
    if not text:
        return DEFAULT_LIMIT
    m = re.fullmatch(r"(\d+(?:\.\d+)?)\s*([A-Za-z]*)", text)
    if m and m.group(2).lower() in _UNITS:
        n = int(float(m.group(1)) * _UNITS[m.group(2).lower()])
        if n >= 1:
            return n
    raise ExtractLimitError(f"{LIMIT_ENV} = {text!r} is invalid: allowed is a size >= 1 byte in bytes or with a "
                            "binary unit, e.g. 4294967296 or 4GiB")


class ExtractBudget:
    """The bytes a co-simulation may still extract (``limit`` in total, from ``extract_limit``)."""

    def __init__(self, limit: int | None = None):
        self.limit = extract_limit() if limit is None else limit
        self.used = 0

    def refuse(self, where: str, member: str, size: int) -> ExtractLimitError:
        return ExtractLimitError(
            f"{where}: extracting {member} ({size_text(size)}) would write more than the limit of "
            f"{size_text(self.limit)} uncompressed in total, with what was extracted before: allowed is an "
            f"archive within the limit; set {LIMIT_ENV} (e.g. {LIMIT_ENV}=8GiB) to raise it")

    def copy(self, zf: zipfile.ZipFile, info: zipfile.ZipInfo, target: Path, where: str) -> None:
        """Copy the member ``info`` of ``zf`` to ``target``, refused before writing if its declared
        size exceeds what is left, and stopped (the partial file removed) as soon as the bytes
        actually written do: a declared size may lie."""
        if self.used + info.file_size > self.limit:
            raise self.refuse(where, info.filename, info.file_size)
        try:
            with zf.open(info) as src, open(target, "wb") as dst:
                while chunk := src.read(_CHUNK):
                    self.used += len(chunk)
                    if self.used > self.limit:
                        raise self.refuse(where, info.filename, self.used - self.limit + info.file_size)
                    dst.write(chunk)
        except BaseException:
            target.unlink(missing_ok=True)
            raise


def extract_archive(path: Path, target: Path, budget: ExtractBudget, where: str) -> Path:
    """Extract the zip archive ``path`` (an FMU) into the folder ``target``, every member checked
    to stay inside it (:func:`inside_archive`) and the bytes counted against ``budget``;
    ExtractLimitError or ValueError (a member outside the archive) names ``where``."""
    target = Path(target)
    root = target.resolve()
    with zipfile.ZipFile(path) as zf:
        infos = zf.infolist()
        for info in infos:  # names and declared sizes before anything is written
            if inside_archive(info.filename.rstrip("/") or ".") is None:
                raise ValueError(f"{where}: archive member {info.filename!r} points outside the archive: {MEMBER_RULE}")
        declared = sum(i.file_size for i in infos)
        if budget.used + declared > budget.limit:
            raise budget.refuse(where, "its members", declared)
        for info in infos:
            dest = (root / inside_archive(info.filename.rstrip("/"))).resolve()
            if not dest.is_relative_to(root):
                raise ValueError(f"{where}: archive member {info.filename!r} points outside the archive: {MEMBER_RULE}")
            if info.is_dir():
                dest.mkdir(parents=True, exist_ok=True)
                continue
            dest.parent.mkdir(parents=True, exist_ok=True)
            budget.copy(zf, info, dest, where)
    return target
