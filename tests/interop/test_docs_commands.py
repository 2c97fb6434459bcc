"""Every command block of docs/other-tools.md and docs/compatibility.md, and every command in their tables
(a code span starting with .venv/bin/ or ../shared/tools/), runs as typed from the repository root after
the quick start: here in a scratch copy of the repository (its files linked, the quick start's
`.venv` the test's own interpreter's, `../shared` beside it, `build/` built fresh by `tapmp build`), one
block after the other in the page's order, each with `bash -e -o pipefail`; a block that ends with an exit
code other than 0 fails the test, naming the page and line."""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests.support.shared import ROOT

PAGES = ("docs/other-tools.md", "docs/compatibility.md")
BLOCK = re.compile(r"^```bash\n(.*?)^```", re.M | re.S)


def blocks(page: str) -> list[tuple[int, str]]:
    """(line, text) of every ```bash block of ``page``, in order."""
    text = (ROOT / page).read_text()
    return [(text.count("\n", 0, m.start()) + 1, m.group(1)) for m in BLOCK.finditer(text)]


CELL = re.compile(r"`((?:\.venv/bin/|\.\./shared/tools/)[^`]*)`")


COMMAND_COLUMN = re.compile(r"^(?:\|[^|]*){5}\| `((?:[^`\\]|\\.)*)` \|")  # compatibility.md's sixth column


def table_commands(page: str) -> list[tuple[int, str]]:
    """(line, command) of every command in a table row of ``page``, in order: on compatibility.md the
    command column of every row (its ``\\|`` unescaped), elsewhere every code span that starts a command."""
    lines = (ROOT / page).read_text().splitlines()
    if page == "docs/compatibility.md":
        rows = [(n, COMMAND_COLUMN.match(line)) for n, line in enumerate(lines, 1) if line.startswith("| ")]
        return [(n, m.group(1).replace("\\|", "|")) for n, m in rows if m]
    return [(n, m) for n, line in enumerate(lines, 1) if line.startswith("|") for m in CELL.findall(line)]


CASES = [(page, line, code) for page in PAGES for line, code in blocks(page)]
CELLS = [(page, line, code) for page in PAGES for line, code in table_commands(page)]


@pytest.fixture(scope="module")
def repository(tmp_path_factory):
    """A scratch repository root: every top-level entry of the checkout linked (but build/ and results/),
    .venv/bin/* the test interpreter's scripts, ../shared the shared folder, build/ built by `tapmp build`."""
    top = tmp_path_factory.mktemp("docs_commands")
    repo = top / "repo"
    repo.mkdir()
    for entry in ROOT.iterdir():
        if entry.name not in ("build", "results", ".venv", ".git"):
            (repo / entry.name).symlink_to(entry)
    (repo / ".venv").symlink_to(Path(sys.executable).parents[1])  # the environment running the tests
    (top / "shared").symlink_to(ROOT.parent / "shared")
    done = subprocess.run([str(repo / ".venv" / "bin" / "tapmp"), "build", "--out", str(repo / "build")],
                          cwd=repo, capture_output=True, text=True, timeout=1800)
    assert done.returncode == 0, done.stdout + done.stderr
    return repo


@pytest.mark.needs_shared("tools/OMSimulator/bin/OMSimulator", "tools/fmusim/bin/fmusim", "tools/fmil/fmil_check",
                          "tools/fmuCheck/fmuCheck.linux64")
@pytest.mark.parametrize("page,line,code", CASES, ids=[f"{p.removeprefix('docs/')}:{n}" for p, n, _ in CASES])
def test_the_command_block_runs_as_typed_from_the_repository_root(repository, page, line, code):
    # the built FMUs of the scratch repository: the tapmp commands' default, which would otherwise be
    # the checkout's build/ (the package is installed from the checkout)
    env = {**os.environ, "TAPMP_FMUS_DIR": str(repository / "build")}
    done = subprocess.run(["bash", "-e", "-o", "pipefail", "-c", code], cwd=repository, capture_output=True,
                          text=True, timeout=1800, env=env)
    assert done.returncode == 0, f"{page}:{line}: exit code {done.returncode}\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"


@pytest.mark.needs_shared("tools/OMSimulator/bin/OMSimulator", "tools/fmusim/bin/fmusim", "tools/fmil/fmil_check",
                          "tools/fmuCheck/fmuCheck.linux64")
@pytest.mark.parametrize("page,line,code", CELLS, ids=[f"{p.removeprefix('docs/')}:{n}:table" for p, n, _ in CELLS])
def test_the_command_in_a_table_runs_as_typed_from_the_repository_root(repository, page, line, code):
    """After the page's blocks (which create results/), in the same scratch repository."""
    test_the_command_block_runs_as_typed_from_the_repository_root(repository, page, line, code)
