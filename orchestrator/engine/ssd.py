"""The SSP reader of the master: read an SSP archive's SystemStructure.ssd (fmpy's
``read_ssd`` parses it against the SSP 1.0 schema), check its elements, extract their FMUs,
and bind parameter tables to its elements.

It knows no particular system: the role names a caller may use for parameter tables (a role
addresses the one element whose FMU has a given modelName) are passed in. Every refusal names
the SSP file and what is allowed.
"""

import difflib
import re
import zipfile
from pathlib import Path

from fmpy.ssp.ssd import read_ssd

from .archive import ExtractBudget, ExtractLimitError, MEMBER_RULE, inside_archive
from .errors import CoSimulationError
from ..errors import UserError

ELEMENT_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
NAME_RULE = "a name matching [A-Za-z_][A-Za-z0-9_]* (letters, digits, _), unique in the system"


class ParameterAddressError(ValueError, UserError):
    """A parameter table addresses no element, several, or sets a value twice; ``element`` names it."""

    def __init__(self, message: str, element: str):
        super().__init__(message)
        self.element = element


def read_ssp(ssp_path: Path, budget: ExtractBudget):
    """(the parsed SSD, the archive's members {normalized name: member name}) of ``ssp_path``;
    the SSD's size counts against ``budget`` (it is parsed in memory). CoSimulationError for an
    unreadable archive and a member named by an absolute path or one with ``..``."""
    try:
        with zipfile.ZipFile(ssp_path) as z:
            size = z.getinfo("SystemStructure.ssd").file_size if "SystemStructure.ssd" in z.namelist() else 0
        if size > budget.limit:
            raise ExtractLimitError(str(budget.refuse(f"SSP file {ssp_path}", "SystemStructure.ssd", size)))
        ssd = read_ssd(str(ssp_path))
        with zipfile.ZipFile(ssp_path) as z:
            names = [i.filename for i in z.infolist() if not i.is_dir()]
    except ExtractLimitError as err:
        raise CoSimulationError(str(err)) from None
    except Exception as err:
        raise CoSimulationError(f"cannot read SSP file {ssp_path}: {err} (an SSP is a zip archive "
                                "holding SystemStructure.ssd and the FMUs)") from err
    members = {}
    for name in names:
        inside = inside_archive(name)
        if inside is None:
            raise CoSimulationError(f"SSP file {ssp_path}: archive member {name!r} points outside the "
                                    f"archive: {MEMBER_RULE}")
        members[inside] = name
    return ssd, members


def check_elements(ssp_path: Path, elements, members: dict) -> dict:
    """{element name: (source, normalized member name)}, in the order of the SSD; CoSimulationError
    unless every element is an FMU component with a unique identifier name (it names a folder) and
    a source that is a member of the archive (``members`` as :func:`read_ssp` returns them)."""
    out = {}
    for e in elements:
        name = getattr(e, "name", None)
        if not isinstance(name, str) or not ELEMENT_NAME.fullmatch(name):
            raise CoSimulationError(f"SSP file {ssp_path}: element name {name!r} is invalid: "
                                    f"allowed is {NAME_RULE}")
        where = f"SSP file {ssp_path}: element {name}"
        if name in out:
            raise CoSimulationError(f"{where} is defined twice: allowed is {NAME_RULE}", name)
        source = getattr(e, "source", None)
        if type(e).__name__ != "Component" or not isinstance(source, str):
            raise CoSimulationError(f"{where} is a {type(e).__name__}: allowed are FMU components "
                                    "(ssd:Component with a source)", name)
        inside = inside_archive(source)
        if inside is None:
            raise CoSimulationError(f"{where}: source {source!r} points outside the archive: "
                                    f"{MEMBER_RULE}", name)
        if inside not in members:
            raise CoSimulationError(f"SSP file {ssp_path}: the FMU {source} of element {name} is missing "
                                    f"from the archive: allowed are its members "
                                    f"{', '.join(m for m in members if m.endswith('.fmu')) or '(no FMU)'}",
                                    name)
        out[name] = (source, inside)
    return out


def extract_fmus(ssp_path: Path, members: dict, elements: dict, root: Path, budget: ExtractBudget) -> dict:
    """Copy the FMU of every element (``elements`` as :func:`check_elements` returns them) out of
    the archive into the folder ``root`` (only those members, each checked to land inside it, their
    sizes counted against ``budget``); returns {element name: FMU path}."""
    folder, root = Path(root), Path(root).resolve()
    paths = {}
    try:
        with zipfile.ZipFile(ssp_path) as z:
            for name, (source, inside) in elements.items():
                target = (root / inside).resolve()
                if not target.is_relative_to(root):  # cannot happen after inside_archive; be sure
                    raise CoSimulationError(f"SSP file {ssp_path}: element {name}: source {source!r} "
                                            f"points outside the archive: {MEMBER_RULE}", name)
                if not target.exists():
                    target.parent.mkdir(parents=True, exist_ok=True)
                    budget.copy(z, z.getinfo(members[inside]), target, f"SSP file {ssp_path}")
                paths[name] = target
    except CoSimulationError:
        raise
    except ExtractLimitError as err:
        raise CoSimulationError(str(err)) from None
    except OSError as err:
        raise CoSimulationError(f"cannot extract SSP file {ssp_path} into {folder.parent}: {err}") from err
    except Exception as err:
        raise CoSimulationError(f"cannot read SSP file {ssp_path}: {err} (an SSP is a zip archive "
                                "holding SystemStructure.ssd and the FMUs)") from err
    return paths


def resolve_parameters(parameters: dict, models: dict, ssp_path, roles: dict | None = None,
                       other_tables=()) -> dict:
    """``parameters`` ({table: {name: value}}) keyed by the SSP's element names.

    A key that names an element addresses it; a role name (a key of ``roles``, {role: modelName})
    the one element whose FMU is that role's model (``models``: {element: modelName}); an empty
    table sets nothing (e.g. a role's table in a system without that role's FMU).
    ParameterAddressError for a role with no or several elements, an unknown key (even with an
    empty table: a misspelled table name; the closest of the elements, roles and the caller's
    ``other_tables`` are offered), or a value set by both name and role.
    """
    roles = roles or {}
    out = {}
    for key, table in parameters.items():
        if key not in models and key not in roles:
            by_role = (f" (or {', '.join(roles)} for the element whose FMU is {next(iter(roles.values()))}, ...)"
                       if roles else "")
            close = difflib.get_close_matches(str(key), list(dict.fromkeys([*models, *roles, *other_tables])),
                                              n=3, cutoff=0.6)
            raise ParameterAddressError(
                f"parameters given for unknown element(s) {key}: allowed are {', '.join(models)}{by_role}"
                + (f"; did you mean {' or '.join(close)}?" if close else ""), key)
        if not table:
            continue
        if key in models:
            element = key
        else:
            hits = [e for e, m in models.items() if m == roles[key]]
            if len(hits) != 1:
                what = "none" if not hits else f"{len(hits)} ({', '.join(hits)})"
                raise ParameterAddressError(
                    f"parameters [{key}] address the element whose FMU is {roles[key]}, and SSP file "
                    f"{ssp_path} has {what}: allowed is a table named after the element, one of "
                    f"{', '.join(models)}", key)
            element = hits[0]
        target = out.setdefault(element, {})
        for name, value in table.items():
            if name in target:
                raise ParameterAddressError(f"{element}.{name} is set twice (by the tables of the element name "
                                            "and of its role): allowed is one value", element)
            target[name] = value
    return out


def column_prefixes(models: dict, roles: dict | None = None) -> dict:
    """{element: prefix of its recorded columns} (``models``: {element: modelName}): the role name
    (a key of ``roles``, {role: modelName}) for the one element whose FMU is that role's model,
    unless another element bears that name, else the element name. So a system records the same
    columns under any element names."""
    prefix = {n: n for n in models}
    for role, model in (roles or {}).items():
        hits = [n for n, m in models.items() if m == model]
        if len(hits) == 1 and (role not in models or role == hits[0]):
            prefix[hits[0]] = role
    return prefix
