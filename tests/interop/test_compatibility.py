"""docs/compatibility.md is the rendering of docs/compatibility.json, and every row names a test
that exists and records it (the rows themselves are checked by the tests that record them,
tests/interop/compatibility.py)."""

import json
import subprocess
import sys

from tests.interop import compatibility
import pytest


def test_the_page_is_the_rendering_of_the_committed_rows_sorted_and_unique():
    data = json.loads(compatibility.JSON_FILE.read_text())
    rows = data["rows"]
    assert data["fields"] == list(compatibility.FIELDS)
    assert all(list(r) == list(compatibility.FIELDS) for r in rows)
    keys = [compatibility.key_of(r) for r in rows]
    assert keys == sorted(set(keys))  # sorted, no key twice
    assert compatibility.JSON_FILE.read_text() == compatibility.json_text(rows)
    assert compatibility.MD_FILE.read_text() == compatibility.render(rows)
    assert all(r["result"] and r["difference"] for r in rows)
    # a row that did not pass says what the tool does instead and that nothing is compared
    # (a tool that runs the clocked controller without ticking its clock)
    assert all(r["difference"].startswith("not comparable: ") for r in rows if not r["result"].startswith("passed"))


def test_the_table_covers_every_tool_and_platform_the_suite_runs():
    rows = compatibility.committed_rows().values()
    tools = {r["tool"] for r in rows}
    assert tools >= {"FMPy", "fmusim", "OMSimulator", "FMIL", "fmuCheck", "libcosim", "Ecos",
                     "FMU Manipulation Toolbox"}, tools
    platforms = {r["platform"] for r in rows}
    assert any("wine" in p for p in platforms) and any("qemu" in p for p in platforms), platforms
    assert {r["fmi"] for r in rows} == {"2.0", "3.0"}


def test_every_row_names_a_collected_test():
    files = sorted({r["test"].split("::")[0] for r in compatibility.committed_rows().values()})
    proc = subprocess.run([sys.executable, "-m", "pytest", "--collect-only", "-q", "-p", "no:cacheprovider", *files],
                          cwd=compatibility.ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    collected = set(proc.stdout.split())
    missing = sorted({r["test"] for r in compatibility.committed_rows().values()} - collected)
    assert not missing, missing


@pytest.mark.parametrize("value, text", [(0.0, "0 (bit for bit) vs X"), (3.2e-16, "< 1e-15 m vs X"),
                                         (1e-15, "< 1e-14 m vs X"), (20.3, "< 1e2 m vs X")])
def test_a_difference_is_bucketed_to_the_next_power_of_ten(value, text):
    assert compatibility.difference(value, "m", "X") == text
