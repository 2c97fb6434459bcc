"""The FMI runtime's C sources (fmu_common/c), read as text: split by concern into files of at most
500 lines; every operation behind the FMI 2.0 and 3.0 functions begins with the one-line allowed-call
check (ALLOW, against its row of the table in instance.c) and the API files read no mode themselves;
and every builder takes the runtime's files from the one list, build_native.RUNTIME_SOURCES and API."""

import re

import pytest

from orchestrator.builder import build_native
from orchestrator.builder.build import python_unity
from orchestrator.builder.build_native import API, RUNTIME, RUNTIME_SOURCES
from tapmp.interface import FMU_NAMES

PYFRONT = RUNTIME.parent / "pyfront"
# Runtime functions on an instance that are not FMI operations: messages, argument checks, the check itself.
HELPERS = {"tapmp_fail", "tapmp_invalid", "tapmp_require_pointer", "tapmp_allowed", "tapmp_check_arrays",
           "tapmp_outputs_finite"}
# A definition `int tapmp_x(tapmp_instance *inst, ...)` and the first statement of its body.
OPERATION = re.compile(r"^int (tapmp_\w+)\(tapmp_instance \*inst\b[^;{]*\)\s*\{\s*\n\s*([^\n]*)", re.M)


def _runtime_c_files():
    return sorted(RUNTIME.glob("*.c")) + sorted(PYFRONT.glob("*.c"))


def _operations():
    """(file name, function, first statement) of every runtime operation."""
    found = []
    for path in sorted(RUNTIME.glob("*.c")):
        for name, first in OPERATION.findall(path.read_text()):
            if name not in HELPERS:
                found.append((path.name, name, first.strip()))
    return found


@pytest.mark.parametrize("path", _runtime_c_files(), ids=lambda p: f"{p.parent.name}/{p.name}")
def test_no_c_file_of_the_runtime_is_over_500_lines(path):
    lines = path.read_text().count("\n")
    assert lines <= 500, f"{path.name} has {lines} lines"


def test_every_operation_begins_with_the_allowed_call_check():
    """The operations both FMI versions map onto (tapmp_*), each with ALLOW(inst, OP_...) or, for a call
    on n values, ALLOW_VALUES(inst, OP_..., n) as its first statement."""
    operations = _operations()
    assert len(operations) >= 30, operations  # the parse found the operations (life cycle, values, states, events, ME)
    unchecked = [(f, name, first) for f, name, first in operations
                 if not re.fullmatch(r"ALLOW(_VALUES)?\(inst, OP_\w+(, n)?\);(\s*/\*.*\*/)?", first)]
    assert not unchecked, unchecked


def test_every_row_of_the_allowed_call_table_is_checked_by_an_operation():
    header = (RUNTIME / "runtime.h").read_text()
    ops = set(re.findall(r"\bOP_\w+", header[header.index("typedef enum {"):header.index("} tapmp_op;")])) - {"OP_COUNT"}
    text = "\n".join(p.read_text() for p in RUNTIME.glob("*.c"))
    checked = set(re.findall(r"(?:ALLOW|ALLOW_VALUES|tapmp_allowed)\(inst, (OP_\w+)", text))
    assert ops and ops == checked, (ops - checked, checked - ops)


def test_the_fmi_api_files_read_no_mode_of_their_own():
    """The API files map calls onto the operations: a mode is looked at only behind them."""
    for path in (*API["fmi2"], *API["fmi3"]):
        text = path.read_text()
        assert not re.search(r"inst->mode\b", text), path.name
        assert "MODE_" not in text, path.name


def test_every_build_takes_the_runtime_files_from_the_one_list():
    """Every C file of fmu_common/c is in RUNTIME_SOURCES or one FMI version's API, and each native FMU's
    sources/ (and its all.c) and the pythonfmu binding's unity file have exactly those of its version."""
    c_files = {p.name for p in RUNTIME.glob("*.c")}
    neutral = {p.name for p in RUNTIME_SOURCES}
    api = {family: {p.name for p in paths} for family, paths in API.items()}
    assert neutral | api["fmi2"] | api["fmi3"] == c_files and not neutral & (api["fmi2"] | api["fmi3"])
    assert {"instance.c", "values.c"} <= neutral and {"fmi2_api.c"} <= api["fmi2"] and {"fmi3_api.c"} <= api["fmi3"]
    headers = {p.name for p in RUNTIME.glob("*.h")}
    for family in build_native.FAMILIES:
        for model in FMU_NAMES:
            files = build_native.source_files(model, family)
            ours = {n for n in files if n in c_files | headers}
            assert ours == neutral | api[family] | headers, (model, family, ours)
            included = set(re.findall(r'#include "([^"]+)"', files[build_native.UNITY].decode()))
            assert neutral | api[family] <= included, (model, family, included)
    included = set(re.findall(r'#include "([^"]+)"', python_unity()))
    assert included == neutral | api["fmi2"] | {"python_model.c"}, included
