"""Every command of the README and docs/*.md runs as typed, in the order written, in a fresh clone.

The commands are the lines of the fenced ```bash blocks (a line ending in a backslash continues
on the next; a here-document runs to its closing EOF line). They run with bash from the root of
a `git clone` of this repository, after the quick start: `.venv` is this Python's environment
(linked into the clone, the clone's own code first on PYTHONPATH) and `bash build_fmus.sh` has
built the FMUs once. The README first, then docs/*.md in alphabetical order; each command must
exit 0 (`tapmp check`: 0 or 1, stable or unstable, its answer).

Shorter horizons, where the full one takes minutes (the commands are otherwise as written):

* `tapmp run` and `tapmp compare`: `--set stop_time=0.05` appended (the last --set wins) unless
  the command sets a shorter one;
* `tapmp reproduce`: `--scenarios` a folder of the shipped scenarios with `stop_time = 0.05`,
  `--paper-gains-stop-time 0.001`;
* `tapmp study FILE`: FILE's copy beside it with `stop_time = 0.05` in its [set] table and at
  most 4 Monte Carlo samples;
* `tapmp calibrate`: `--horizon 0.05 --max-nfev 1`;
* the quick start's `python3 -m venv .venv && .venv/bin/pip install -e '.[tools]' && bash build_fmus.sh
  --host &&` prefix is what the clone's set-up already did (every platform, the `test` extra, which
  holds the `tools` extra).

Not run (NOT_RUN below, each with its reason): the test suite itself, installs outside the
checkout and the timing benchmarks; their programs must still be in the quick start's venv
(test_every_program_and_package_the_docs_use_is_installed_by_the_quick_start, which runs in the fast
subset: a docs command needing a package of the `test` extra only fails there). docs/compatibility.md
and docs/other-tools.md are left to tests/interop, which runs their tools and checks their tables.
"""

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
# the third-party tools' pages are run by tests/interop (each tool for real, the tables checked there)
COVERED_BY_INTEROP = {"docs/compatibility.md", "docs/other-tools.md"}
ALL_DOCS = ["README.md"] + sorted(p.relative_to(ROOT).as_posix() for p in (ROOT / "docs").glob("*.md"))
DOCS = [d for d in ALL_DOCS if d not in COVERED_BY_INTEROP]
SHORT = 0.05  # [s] horizon of the shortened runs

# Commands not run, matched by a regular expression, and why.
NOT_RUN = {
    r"^bash tests/run\.sh": "the whole test suite, this test among it",
    r"^pip install \. && tapmp build": "installs the package into the Python on PATH, outside the checkout",
    r"\.venv/bin/python -m pytest": "runs test files of this suite, which CI runs anyway",
    r"benchmarks/(bench_|throughput)": "a timing benchmark, best of several runs of full horizons (minutes)",
    r"tests/interop/measure_export\.py": "a measurement of every third-party master against tapmp run (minutes)",
}
# Commands whose answer is their exit code: tapmp check exits 1 for an unstable loop (the docs show
# unstable gains on purpose); 2, bad input, fails the test as for any command.
# exit codes a documented command may answer besides 0: check's "not stable"; FMIL's exit 1 on the FMI 3.0
# FMUs' terminalsAndIcons.xml, whose standard elements it does not know (docs/other-tools.md says so)
ANSWER_CODES = {r"\.venv/bin/tapmp check ": (0, 1), r"fmil_check parse .*fmi3": (0, 1)}
QUICK_START_SETUP = "python3 -m venv .venv && .venv/bin/pip install -e '.[tools]' && bash build_fmus.sh --host && "


def commands(text: str) -> list[list[str]]:
    """The commands of each ```bash block of a Markdown text, in order (comment lines dropped)."""
    out = []
    for block in re.finditer(r"^( *)```bash\n(.*?)^\1```", text, re.S | re.M):
        indent = len(block.group(1))
        lines = [line[indent:] for line in block.group(2).splitlines()]
        out.append([])
        i = 0
        while i < len(lines):
            line = lines[i]
            i += 1
            if not line.strip() or line.lstrip().startswith("#"):
                continue
            cmd = [line]
            while cmd[-1].endswith("\\") and i < len(lines):
                cmd.append(lines[i])
                i += 1
            heredocs = re.findall(r"<<'(\w+)'", "\n".join(cmd))
            for end in heredocs:
                while i < len(lines) and lines[i] != end:
                    cmd.append(lines[i])
                    i += 1
                cmd.append(lines[i] if i < len(lines) else end)
                i += 1
            out[-1].append("\n".join(cmd))
    return out


def _split_comment(cmd: str) -> tuple[str, str]:
    m = re.match(r"(.*?)(\s+#\s.*)?$", cmd, re.S)
    return m.group(1), m.group(2) or ""


def shorten(cmd: str, repo: Path) -> str:
    """The command with the shorter horizons of the module docstring."""
    if cmd.startswith(QUICK_START_SETUP):
        cmd = cmd[len(QUICK_START_SETUP):]
    if "<<'" in cmd:
        return cmd
    body, comment = _split_comment(cmd)
    if re.search(r"\.venv/bin/tapmp (run|compare) ", body):
        own = [float(t) for t in re.findall(r"--set stop_time=([0-9.e+-]+)", body)]
        if not own or own[-1] > SHORT:  # a horizon already shorter is kept
            body += f" --set stop_time={SHORT}"
    elif re.search(r"\.venv/bin/tapmp reproduce\b", body):
        short = repo / "results" / "short_scenarios"
        short.mkdir(parents=True, exist_ok=True)
        for f in (repo / "scenarios").glob("*.toml"):
            (short / f.name).write_text(re.sub(r"^stop_time = .*$", f"stop_time = {SHORT}", f.read_text(),
                                               flags=re.M))
        body += f" --scenarios {short.relative_to(repo)} --paper-gains-stop-time 0.001"
    elif m := re.search(r"\.venv/bin/tapmp study (\S+)", body):
        study = Path(m.group(1))
        copy = study.with_name(f"{study.stem}_short.toml")
        text = (repo / study).read_text()
        text = re.sub(r"^(\[set\]\n(?:(?!\[).*\n)*?)stop_time = .*\n", rf"\1stop_time = {SHORT}\n", text, flags=re.M)
        text = re.sub(r"^samples = \d+$", "samples = 4", text, flags=re.M)
        (repo / copy).write_text(text)
        body = body.replace(m.group(0), f".venv/bin/tapmp study {copy.as_posix()}")
    elif re.search(r"\.venv/bin/tapmp calibrate ", body):
        body += f" --horizon {SHORT} --max-nfev 1"
    return body + comment


@pytest.fixture(scope="module")
def clone(tmp_path_factory):
    """A fresh clone of this repository with .venv and the FMUs built, as after the quick start;
    ../shared beside it when this checkout has one."""
    base = tmp_path_factory.mktemp("docs")
    repo = base / "repo"
    subprocess.run(["git", "clone", "-q", str(ROOT), str(repo)], check=True)
    (repo / ".venv").symlink_to(Path(sys.prefix))
    if (ROOT.parent / "shared").is_dir():
        (base / "shared").symlink_to(ROOT.parent / "shared")
    env = _env(repo)
    res = subprocess.run(["bash", "build_fmus.sh"], cwd=repo, env=env, capture_output=True, text=True)
    assert res.returncode == 0, res.stderr[-3000:]
    yield repo
    shutil.rmtree(base, ignore_errors=True)  # about 200 MB of runs and FMUs


def _env(repo: Path) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("TAPMP_FMUS_DIR", "PYTHONPATH")}
    env["PYTHONPATH"] = str(repo)  # the clone's code, not this checkout's editable install
    return env


def _marks(doc: str):
    uses = sorted(set(re.findall(r"\.\./shared/(tools/[\w.-]+)", (ROOT / doc).read_text())))
    return [pytest.mark.needs_shared(*uses)] if uses else []


def test_the_extraction_joins_continuations_and_here_documents():
    text = ("```bash\n# a comment\na \\\n  b   # note\n.venv/bin/python - <<'EOF'\nprint(1)\nEOF\nc\n```\n"
            "  ```bash\n  d\n  ```\n")
    assert commands(text) == [["a \\\n  b   # note", ".venv/bin/python - <<'EOF'\nprint(1)\nEOF", "c"], ["d"]]
    assert shorten(".venv/bin/tapmp run x.toml --out y   # z", ROOT) == \
        f".venv/bin/tapmp run x.toml --out y --set stop_time={SHORT}   # z"
    assert shorten(".venv/bin/tapmp run x.toml --set stop_time=0.01", ROOT) == \
        ".venv/bin/tapmp run x.toml --set stop_time=0.01"


@pytest.mark.slow  # every documented command in a fresh clone: minutes
@pytest.mark.parametrize("doc", [pytest.param(d, marks=_marks(d)) for d in DOCS])
def test_the_commands_of_the_docs_run_as_typed(doc, clone):
    ran = []
    for block in commands((ROOT / doc).read_text()):
        script = []  # one shell per block: a variable set by one line is read by the next
        for cmd in block:
            if any(re.search(pattern, cmd) for pattern in NOT_RUN):
                continue
            typed = shorten(cmd, clone)
            allowed = next((codes for pattern, codes in ANSWER_CODES.items() if re.search(pattern, typed)), (0,))
            test = " -o ".join(f"$rc -eq {c}" for c in allowed)
            script.append(f"{typed}\nrc=$?; if [ {test} ]; then :; else echo \"exit $rc of the command above\"; "
                          "exit 1; fi")
            ran.append(typed)
        res = subprocess.run(["bash"], input="\n".join(script) + "\n", cwd=clone, env=_env(clone),
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, timeout=1800)
        assert res.returncode == 0, f"{doc}:\n{res.stdout[-4000:]}"
    print(f"\n{doc}: {len(ran)} commands", *ran, sep="\n  ")


def test_every_program_and_package_the_docs_use_is_installed_by_the_quick_start():
    # the Python snippets of the docs import only the package, its dependencies and the quick start's
    # extras; every .venv/bin/PROGRAM and `.venv/bin/python -m MODULE` of a command is installed by them
    # (the commands this test does not run too: they are typed by users in the quick start's venv)
    import tomllib
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    quick = re.search(r"pip install -e '\.\[(\w+)\]'", (ROOT / "README.md").read_text()).group(1)
    installed = {re.split(r"[<>=\[ ]", d)[0] for d in project["dependencies"] + project["optional-dependencies"][quick]}
    modules = {"libcosimpy": "libcosimpy", "ecospy": "ecospy", "lief": "lief", "hypothesis": "hypothesis",
               "fmu_manipulation_toolbox": "fmu-manipulation-toolbox", "pytest": "pytest"}
    programs = {"fmucontainer": "fmu-manipulation-toolbox", "pytest": "pytest",  # .venv/bin/PROGRAM
                "python -m pytest": "pytest",  # .venv/bin/python -m pytest
                "python tests/": "pytest"}  # a script of the test suite (tests/interop/measure_export.py)
    for doc in ALL_DOCS:
        text = (ROOT / doc).read_text()
        for module, package in modules.items():
            if re.search(rf"^\s*(from|import) {module}\b|import {module}\b", text, re.M):
                assert package in installed, f"{doc} imports {module}, which the quick start does not install"
        for block in commands(text):
            for cmd in block:
                for program, package in programs.items():
                    if re.search(rf"\.venv/bin/{program}", cmd):
                        assert package in installed, f"{doc} runs {program}, which the quick start does not install"
