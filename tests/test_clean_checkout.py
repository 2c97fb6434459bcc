"""The README's short tour, run as typed in a fresh clone of the repository (shorter horizons:
the runs with --set stop_time=0.05, reproduce on copies of the paper scenarios cut to 0.02 s),
leaves `git status` empty: every command writes under ignored folders. Only
`tapmp reproduce --write-docs` changes a tracked file, docs/paper-reproduction.md."""

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SCENARIOS = ("paper_simulation", "paper_experiment", "paper_simulation_calibrated", "paper_experiment_calibrated")


def tour_commands() -> list[list[str]]:
    """The commands of README.md's "A short tour" code block, split as a shell would."""
    text = (ROOT / "README.md").read_text()
    section = text[text.index("## A short tour"):]
    block = re.search(r"```bash\n(.*?)```", section, re.S).group(1)
    return [shlex.split(line, comments=True) for line in block.splitlines() if line.strip()]


def test_the_tour_has_the_commands_this_test_shortens():
    commands = tour_commands()
    assert all(c[0] == ".venv/bin/tapmp" for c in commands)
    assert {c[1] for c in commands} == {"run", "plot", "check", "export", "study", "reproduce"}


@pytest.fixture(scope="module")
def clone(tmp_path_factory):
    """A fresh clone of this repository, its FMUs (x86_64-linux) built outside it, and the
    environment of the tour's commands."""
    tmp = tmp_path_factory.mktemp("clean")
    repo = tmp / "repo"
    subprocess.run(["git", "clone", "-q", str(ROOT), str(repo)], check=True, timeout=120)
    (tmp / "tmp").mkdir()
    env = dict(os.environ, TMPDIR=str(tmp / "tmp"), TAPMP_FMUS_DIR=str(tmp / "fmus"))
    subprocess.run([sys.executable, "-m", "orchestrator", "build", "--out", str(tmp / "fmus"), "--platform",
                    "x86_64-linux"], cwd=repo, env=env, check=True, capture_output=True, timeout=600)
    short = tmp / "scenarios"
    short.mkdir()
    for name in SCENARIOS:
        text, n = re.subn(r"(?m)^stop_time = [0-9.]+", "stop_time = 0.02", (repo / "scenarios" / f"{name}.toml").read_text())
        assert n == 1
        (short / f"{name}.toml").write_text(text)
    return repo, env, short


def _short(cmd: list[str], scenarios: Path) -> list[str]:
    """The tour's command with a shorter horizon."""
    args = [sys.executable, "-m", "orchestrator", *cmd[1:]]  # the clone's own code (its folder comes first)
    if cmd[1] == "run":
        args += ["--set", "stop_time=0.05"]
    if cmd[1] == "reproduce":
        args += ["--scenarios", str(scenarios), "--paper-gains-stop-time", "0.001", "--workers", "1"]
    return args


def _porcelain(repo: Path) -> list[str]:
    return subprocess.run(["git", "status", "--porcelain"], cwd=repo, capture_output=True, text=True,
                          check=True).stdout.splitlines()


def test_the_readme_tour_leaves_a_fresh_clone_clean_and_write_docs_changes_only_the_page(clone):
    repo, env, short = clone
    assert _porcelain(repo) == []
    for cmd in tour_commands():
        res = subprocess.run(_short(cmd, short), cwd=repo, env=env, capture_output=True, text=True, timeout=900)
        assert res.returncode == (1 if cmd[1] == "check" else 0), (cmd, res.stderr)  # paper gains: unstable
        assert _porcelain(repo) == [], cmd
    page = repo / "results" / "paper-reproduction.md"
    assert page.read_text().startswith("# Reproducing the paper's Tables 1-6")
    assert "0.02 s at a 0.0001 s step" in page.read_text()
    assert (repo / "export" / "paper.ssp").is_file()
    # asked for: the page goes to docs/ too, and that is the only tracked file changed
    reproduce = next(c for c in tour_commands() if c[1] == "reproduce")
    res = subprocess.run(_short(reproduce, short) + ["--write-docs"], cwd=repo, env=env, capture_output=True,
                         text=True, timeout=900)
    assert res.returncode == 0, res.stderr
    assert res.stdout.splitlines()[-2:] == [f"wrote {Path('results') / 'paper-reproduction.md'}",
                                            "wrote docs/paper-reproduction.md"]
    assert _porcelain(repo) == [" M docs/paper-reproduction.md"]
    assert (repo / "docs" / "paper-reproduction.md").read_text() == page.read_text()
