"""The three FMU families and where `bash build_fmus.sh` puts their SSP systems.

The FMU folder is --fmus-dir, else $TAPMP_FMUS_DIR, else the repository's build/ (in a
checkout) or ./build (installed as a wheel); the families' SSPs inside it:

* ``native`` (the default): the self-contained C FMUs, FMI 2.0 (build/native/fmi2/).
  Bit-identical to the pythonfmu FMUs in every test, about three times faster per macro
  step, and the FMUs users hand to other tools, so they are what a run exercises.
* ``fmi3``: the same C FMUs as FMI 3.0 (build/native/fmi3/), through fmpy's FMI 3 API.
* ``python``: the pythonfmu FMUs (build/), the Python-native reference.
"""

import os
from pathlib import Path

from tapmp.errors import allowed_are

from ..errors import UsageError

# The package's root: the repository in a checkout, site-packages in an installed wheel.
ROOT = Path(__file__).resolve().parents[2]
ENV = "TAPMP_FMUS_DIR"
# SSP of each family, relative to the FMU folder (an absolute path is taken as it is)
FAMILIES = {"python": Path("TAPMP.ssp"), "native": Path("native") / "fmi2" / "TAPMP.ssp",
            "fmi3": Path("native") / "fmi3" / "TAPMP.ssp"}
DEFAULT_FAMILY = "native"
# The families with the optional drive FMU (native only) and the SSP of its system, beside TAPMP.ssp
DRIVE_FAMILIES = ("native", "fmi3")
DRIVE_SSP = "TAPMP_Drive.ssp"


def with_drive(fmus: str) -> bool:
    """Whether the family ``fmus`` has the drive FMU (TAPMP_Drive.ssp)."""
    return fmus in DRIVE_FAMILIES


def in_checkout() -> bool:
    """True if the package runs from the repository (an editable install or PYTHONPATH), not
    from an installed wheel."""
    return (ROOT / "build_fmus.sh").is_file() and (ROOT / "pyproject.toml").is_file()


def default_build_dir() -> Path:
    """Where `tapmp build` writes and `tapmp run` looks by default: $TAPMP_FMUS_DIR if set,
    else the repository's build/ in a checkout, else build/ in the current directory (never
    inside the installed package)."""
    if os.environ.get(ENV):
        return Path(os.environ[ENV])
    return ROOT / "build" if in_checkout() else Path("build")


def fmus_dir(explicit: str | Path | None = None) -> Path:
    """The folder of the built FMU families: ``explicit`` (--fmus-dir) if given, else
    :func:`default_build_dir`."""
    return Path(explicit) if explicit else default_build_dir()


def data_dir(name: str) -> Path:
    """A folder of files shipped with the package, ``name`` "scenarios" or "studies": the
    repository's folder in a checkout, the package data folder tapmp_data/<name> in a wheel."""
    return ROOT / name if in_checkout() else ROOT / "tapmp_data" / name


SCENARIOS_DIR = data_dir("scenarios")


class FamilyNotBuilt(FileNotFoundError):
    """The SSP of an FMU family does not exist yet; the message says how to build it."""


def family_ssp(fmus: str, folder: str | Path | None = None, drive: bool = False) -> Path:
    """The SSP file of family ``fmus`` in the FMU folder ``folder`` (default: :func:`fmus_dir`), with the
    drive in the loop if ``drive``; UsageError names the allowed families."""
    try:
        path = fmus_dir(folder) / FAMILIES[fmus]
    except KeyError:
        raise UsageError(f"fmus = {fmus!r} is invalid: {allowed_are(fmus, FAMILIES)}") from None
    if drive and not with_drive(fmus):
        raise UsageError(f"drive = true is invalid with fmus = {fmus!r}: allowed is fmus = \"native\" or \"fmi3\" "
                         "(the families with the drive FMU TAPMP_Drive), or drive = false")
    return path.with_name(DRIVE_SSP) if drive else path


def resolve_ssp(ssp: str | None, fmus: str, folder: str | Path | None = None, drive: bool = False) -> Path:
    """``--ssp`` if given (UsageError if it is a folder), else the built SSP of family ``fmus`` in
    ``folder`` (--fmus-dir, default :func:`fmus_dir`), with the drive if ``drive``; FamilyNotBuilt if it is
    missing."""
    if ssp:
        if Path(ssp).is_dir():
            inside = [p for p in (Path(ssp) / "TAPMP.ssp", Path(ssp) / FAMILIES[fmus]) if p.is_file()]
            hint = f", e.g. {inside[0]}" if inside else "; a folder of built FMUs goes to --fmus-dir"
            raise UsageError(f"--ssp = {ssp!r} is a folder: allowed is an SSP file (a zip archive holding "
                             f"SystemStructure.ssd and the FMUs){hint}")
        return Path(ssp)
    path = family_ssp(fmus, folder, drive)
    if not path.is_file():
        raise FamilyNotBuilt(f"the {fmus} FMUs are not built ({path} does not exist): build them with "
                             f"`bash build_fmus.sh` from the repository root, or `tapmp build --out DIR` "
                             f"and pass --fmus-dir DIR (or set {ENV}=DIR)")
    return path
