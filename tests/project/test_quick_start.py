"""The README's first command on a new machine: its build part, run in a fresh clone with an empty
Zig cache and an empty tapmp cache, prints a line for each phase, family and platform, and says how
the other platforms are built; while compilers run, a line comes at least every `every` seconds.

The time it takes is measured by benchmarks/bench_quick_start.py, not here."""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from orchestrator.builder import build_native
from orchestrator.builder.build import build_all
import ctoolchain as toolchain

pytestmark = pytest.mark.slow  # a clone, a build, child processes

ROOT = Path(__file__).resolve().parents[2]


def quick_start_build() -> str:
    """The build part of the README's first command (its `bash build_fmus.sh ...` step)."""
    text = (ROOT / "README.md").read_text()
    first = re.search(r"^```bash\n(.*?)\n", text[text.index("## Quick start"):], re.M).group(1)
    (build,) = [step.strip() for step in first.split("&&") if step.strip().startswith("bash build_fmus.sh")]
    return build


def test_the_quick_start_builds_in_a_fresh_clone_with_empty_caches_saying_what_it_does(tmp_path):
    repo = tmp_path / "repo"
    subprocess.run(["git", "clone", "-q", str(ROOT), str(repo)], check=True)
    (repo / ".venv").symlink_to(Path(sys.prefix))
    zig, cache = tmp_path / "zig-cache", tmp_path / "tapmp-cache"
    zig.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("TAPMP_FMUS_DIR", "ZIG_LOCAL_CACHE_DIR")}
    env.update(PYTHONPATH=str(repo), ZIG_GLOBAL_CACHE_DIR=str(zig), TAPMP_CACHE=str(cache))
    command = quick_start_build()
    assert command == "bash build_fmus.sh --host"
    res = subprocess.run(["bash", "-c", command], cwd=repo, env=env, capture_output=True, text=True, timeout=1800)
    assert res.returncode == 0, res.stderr[-3000:]
    lines = res.stdout.splitlines()
    expected = ["pythonfmu: compiling the FMI front and the three Python bindings (x86_64-linux)",
                "native: compiling 9 FMUs (fmi2, fmi3) for 1 platform(s): x86_64-linux",  # with the drive
                "native fmi2: x86_64-linux binaries done", "native fmi3: x86_64-linux binaries done",
                "native fmi2: writing the FMUs", "native fmi3: writing the FMUs",
                "the native FMUs hold binaries for x86_64-linux only (and their C sources); `tapmp build "
                "--all-platforms` adds aarch64-linux, x86_64-windows, x86-windows, x86_64-darwin, aarch64-darwin",
                "fmpy validate: every FMU", "FMUs and SSPs in "]
    at = [next(i for i, line in enumerate(lines) if line.startswith(e)) for e in expected]
    assert at == sorted(at), lines  # in this order
    assert any((zig / d).is_dir() and any((zig / d).iterdir()) for d in ("o", "h")), "zig used another cache"
    assert sorted(p.name for p in cache.glob("tapmp_model_*.so")), "the C model was compiled into the empty cache"
    for family in ("fmi2", "fmi3"):
        assert (repo / "build" / "native" / family / "TAPMP.ssp").is_file()


def slow_compiler(folder, seconds: int) -> str:
    """Path of a host compiler (zig cc for x86_64 Linux) that waits ``seconds`` s before compiling."""
    slow = folder / "slow-cc"
    zig = " ".join(toolchain.zig_command())
    slow.write_text(f"#!/bin/sh\nsleep {seconds}\nexec {zig} -target x86_64-linux-gnu.2.17 \"$@\"\n")
    slow.chmod(0o755)
    return str(slow)


def test_the_pythonfmu_compile_says_it_is_still_compiling_while_it_runs(tmp_path, monkeypatch):
    # every compile of the pythonfmu binaries waits 2 s: a line at least every second meanwhile
    monkeypatch.setenv("CC", slow_compiler(tmp_path, 2))
    lines = []
    paths = build_all(tmp_path / "fmus", lines.append, every=1.0)
    assert paths["ssp"].is_file()
    start = lines.index(next(line for line in lines if line.startswith("pythonfmu: compiling ")))
    beats = [line for line in lines if line.startswith("pythonfmu: still compiling (")]
    assert len(beats) >= 4 and lines[start + 1].startswith("pythonfmu: still compiling ("), lines
    assert all(lines.index(b) < lines.index(next(x for x in lines if x.startswith("built "))) for b in beats)


def test_a_compile_longer_than_the_interval_is_reported_while_it_runs(tmp_path, monkeypatch):
    # the host's compiler waits 3 s before compiling: the build says what it is still doing
    monkeypatch.setenv("CC", slow_compiler(tmp_path, 3))
    units = {("TAPMP_Plant", "fmi2"): build_native.staged_sources(build_native.source_files("TAPMP_Plant", "fmi2"),
                                                                  "TAPMP_Plant", "fmi2")}
    lines = []
    built = build_native.compile_every_binary(units, ["x86_64-linux"], tmp_path, lines.append, every=1.0)
    assert built[("TAPMP_Plant", "fmi2")]["x86_64-linux"][:4] == b"\x7fELF"
    assert lines[-1].startswith("native fmi2: x86_64-linux binaries done (")
    assert lines[0].startswith("native: still compiling for x86_64-linux ("), lines
