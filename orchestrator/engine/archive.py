"""Names inside an SSP archive: an SSD source or a zip member, checked to stay inside it.

fmpy's own ``extract`` refuses backslashes, drive letters and a leading ``/`` but lets
zipfile drop ``..`` silently (so a member may land elsewhere than it says), and it does not
look at the SSD's source references at all: the master checks both with this one rule.
"""

import posixpath
import re

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
