"""docs/theorem1.md shows what its two `tapmp check` commands print, to the digit."""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow  # seconds: runs tapmp or pytest in a fresh Python process
def test_the_theorem1_page_shows_the_lines_its_checks_print(tmp_path):
    page = (ROOT / "docs" / "theorem1.md").read_text()
    make = re.search(r"^mkdir -p results && (printf .*)$", page, re.M).group(1)
    (tmp_path / "results").mkdir()
    subprocess.run(["bash", "-c", make], cwd=tmp_path, check=True)
    printed = []
    for law in ("sc-dc", "apd-dc"):
        res = subprocess.run([sys.executable, "-m", "orchestrator", "check", "results/theorem1.toml", "--set",
                              f'law="{law}"'], cwd=tmp_path, capture_output=True, text=True,
                             env=dict(os.environ, PYTHONPATH=str(ROOT)))
        assert res.returncode == (1 if law == "sc-dc" else 0), res.stderr
        printed.append(res.stdout.strip())
    assert "```\n" + "\n".join(printed) + "\n```" in page, printed
