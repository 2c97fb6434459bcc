"""The README's short tour, run as typed in a fresh clone of the repository (shorter horizons:
the runs with --set stop_time=0.05, frf on two periods of 20 ms, reproduce on copies of the paper scenarios cut to 0.02 s),
leaves `git status` empty: every command writes under ignored folders; it runs again as typed. Only
`tapmp reproduce --write-docs` changes a tracked file, docs/paper-reproduction.md."""

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow  # a fresh clone, the README's tour as typed

ROOT = Path(__file__).resolve().parents[2]
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
    assert {c[1] for c in commands} == {"run", "plot", "check", "export", "study", "reproduce", "frf"}


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
        text = (repo / "scenarios" / f"{name}.toml").read_text()
        text, n = re.subn(r"(?m)^stop_time = [0-9.]+", "stop_time = 0.02", text)
        assert n == 1
        (short / f"{name}.toml").write_text(text)
    return repo, env, short


def _short(cmd: list[str], scenarios: Path) -> list[str]:
    """The tour's command with a shorter horizon."""
    args = [sys.executable, "-m", "orchestrator", *cmd[1:]]  # the clone's own code (its folder comes first)
    if cmd[1] == "run":
        args += ["--set", "stop_time=0.05"]
    if cmd[1] == "frf":  # two periods of 20 ms (the excitation's frequencies from 50 Hz) instead of six of 0.2 s
        args += ["--period", "0.02", "--transient", "1", "--periods", "1", "--points", "12"]
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
    # the tour runs again as typed (each line replaces what it wrote), the reproduction aside (its
    # --overwrite replaces its own comparisons: tests/cli/test_cli_commands.py)
    for cmd in tour_commands():
        if cmd[1] != "reproduce":
            res = subprocess.run(_short(cmd, short), cwd=repo, env=env, capture_output=True, text=True, timeout=900)
            assert res.returncode == (1 if cmd[1] == "check" else 0), ("again", cmd, res.stderr)
    assert _porcelain(repo) == []
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


@pytest.mark.parametrize("args, message", [
    (["--out", "page.txt"], "error: --out = 'page.txt' is invalid: allowed is a Markdown file ending in .md"),
    (["--paper-gains-stop-time", "0"], "error: --paper-gains-stop-time = 0 is invalid: allowed is a finite horizon "
                                       "> 0 s"),
    (["--paper-gains-stop-time", "nan"], "error: --paper-gains-stop-time = nan is invalid: allowed is a finite "
                                         "horizon > 0 s"),
    (["--workers", "0"], "error: --workers = 0 is invalid: allowed is an integer >= 1"),
    (["--scenarios", "nowhere"], "error: --scenarios = 'nowhere': no paper_simulation.toml there: allowed is a folder "
                                 "with paper_simulation.toml and paper_experiment.toml"),
])
def test_bad_reproduce_options_are_one_line_exit_2_and_write_nothing(tmp_path, args, message):
    res = subprocess.run([sys.executable, "-m", "orchestrator", "reproduce", *args], cwd=tmp_path, capture_output=True,
                         text=True, timeout=120, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert (res.returncode, res.stderr.splitlines(), res.stdout) == (2, [message], "")
    assert list(tmp_path.iterdir()) == []


def test_write_docs_of_a_study_without_a_tuning_is_refused(tmp_path):
    res = subprocess.run([sys.executable, "-m", "orchestrator", "study", str(ROOT / "studies" / "gain_sweep.toml"),
                          "--write-docs", "--out", str(tmp_path / "out")], cwd=tmp_path, capture_output=True,
                         text=True, timeout=120, env=dict(os.environ, PYTHONPATH=str(ROOT),
                                                          TAPMP_FMUS_DIR=str(tmp_path / "fmus")))
    assert res.returncode == 2
    assert res.stderr.splitlines() == [f"error: --write-docs: {ROOT / 'studies' / 'gain_sweep.toml'} has no [tune] "
                                       "table; only a tuning writes a write_to folder"]
    assert not (tmp_path / "out").exists()
