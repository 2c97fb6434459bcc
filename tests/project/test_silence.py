"""No documented long command is silent for more than 30 s: the quick start's build and
`tapmp analyze` (docs/analysis.md's grid of 40 points) run in a fresh clone with their output
(stdout and stderr together) time-stamped as it arrives; the longest gap between two lines (and
before the first, after the last) must be at most SILENCE_S. On a terminal the commands show bars;
here, as in a pipe or a CI log, only lines count."""

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow  # a clone, a build and an analysis: minutes

ROOT = Path(__file__).resolve().parents[2]
SILENCE_S = 30.0  # [s] the longest a documented command may say nothing


def timed_lines(cmd: list, cwd: Path, env: dict) -> tuple[int, list]:
    """Run ``cmd``; returns (exit code, [(seconds since the start, line)]) with an empty line at
    the end marking the exit."""
    start = time.monotonic()
    lines = []
    with subprocess.Popen(cmd, cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                          bufsize=1) as proc:
        for line in proc.stdout:
            lines.append((time.monotonic() - start, line.rstrip("\n")))
    lines.append((time.monotonic() - start, ""))
    return proc.returncode, lines


def longest_silence(lines: list) -> tuple[float, str]:
    """(seconds, the line after which it fell) of the longest gap in ``lines`` of timed_lines."""
    before = [(0.0, "(the start)")] + lines[:-1]
    return max((t - t0, prev) for (t0, prev), (t, _) in zip(before, lines))


@pytest.fixture(scope="module")
def clone(tmp_path_factory):
    """A fresh clone of this repository with this Python's environment as .venv."""
    repo = tmp_path_factory.mktemp("silence") / "repo"
    subprocess.run(["git", "clone", "-q", str(ROOT), str(repo)], check=True)
    (repo / ".venv").symlink_to(Path(sys.prefix))
    return repo


def env_of(repo: Path) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("TAPMP_FMUS_DIR", "PYTHONPATH")}
    env["PYTHONPATH"] = str(repo)  # the clone's code
    return env


def test_the_longest_silence_of_a_timed_run_is_the_largest_gap():
    assert longest_silence([(1.0, "a"), (4.5, "b"), (5.0, "")]) == (3.5, "a")
    assert longest_silence([(40.0, "a"), (41.0, "")]) == (40.0, "(the start)")


@pytest.mark.parametrize("command", [
    "bash build_fmus.sh --host",
    ".venv/bin/tapmp analyze scenarios/paper_simulation.toml --points 40",
], ids=["build", "analyze"])
def test_the_quick_start_build_and_analyze_are_never_silent_for_30_s(clone, command):
    code, lines = timed_lines(command.split(), clone, env_of(clone))
    text = "\n".join(f"{t:7.1f} s  {line}" for t, line in lines)
    assert code == 0, text[-3000:]
    gap, after = longest_silence(lines)
    print(f"{command}: {lines[-1][0]:.0f} s, longest silence {gap:.1f} s after {after!r}")
    assert gap <= SILENCE_S, f"{command}: {gap:.1f} s without a line after {after!r}:\n{text[-3000:]}"
