"""The three FMU families and where `bash build_fmus.sh` puts their SSP systems.

* ``native`` (the default): the self-contained C FMUs, FMI 2.0 (build/native/fmi2/).
  Bit-identical to the pythonfmu FMUs in every test, about three times faster per macro
  step, and the FMUs users hand to other tools, so they are what a run exercises.
* ``fmi3``: the same C FMUs as FMI 3.0 (build/native/fmi3/), through fmpy's FMI 3 API.
* ``python``: the pythonfmu FMUs (build/), the Python-native reference.
"""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
BUILD = ROOT / "build"
FAMILIES = {"python": BUILD / "TAPMP.ssp", "native": BUILD / "native" / "fmi2" / "TAPMP.ssp",
            "fmi3": BUILD / "native" / "fmi3" / "TAPMP.ssp"}
DEFAULT_FAMILY = "native"


class FamilyNotBuilt(FileNotFoundError):
    """The SSP of an FMU family does not exist yet; the message says how to build it."""


def family_ssp(fmus: str) -> Path:
    """The SSP file of family ``fmus`` (ValueError names the allowed families)."""
    try:
        return FAMILIES[fmus]
    except KeyError:
        raise ValueError(f"fmus = {fmus!r} is invalid: allowed are {', '.join(FAMILIES)}") from None


def resolve_ssp(ssp: str | None, fmus: str) -> Path:
    """``--ssp`` if given, else the built SSP of family ``fmus``; FamilyNotBuilt if it is missing."""
    if ssp:
        return Path(ssp)
    path = family_ssp(fmus)
    if not path.is_file():
        raise FamilyNotBuilt(f"the {fmus} FMUs are not built ({path} does not exist): build them with "
                             f"`bash build_fmus.sh` from the repository root")
    return path
