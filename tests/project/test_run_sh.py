"""tests/run.sh, the README's test command: which Debian packages it installs, how (root, sudo,
apt-get update only after a failed install), and that it ends in pytest with every test.

The script runs for real under bash, copied into a scratch repository, with dpkg, apt-get, id,
sudo and python3 replaced by recording stand-ins first on PATH (nothing is installed)."""

import os
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
FUZZ_PACKAGES = ["clang", "libclang-rt-14-dev", "chromium"]  # libFuzzer and the sanitizers; the FMU docs' renderer
PACKAGES = ["libtbb12", "wine64", "qemu-user", "libc6-arm64-cross", "libminizip1", "libxml2", *FUZZ_PACKAGES]
TOOLS = ("bash", "dirname", "env", "mkdir", "cat", "chmod", "sleep", "nproc")  # the real programs the script and stand-ins use

STANDINS = {
    "dpkg": '[ "$1" = -s ] || exit 2\ncase " $INSTALLED " in *" $2 "*) exit 0;; esac\nexit 1\n',
    "apt-get": 'echo "apt-get $* [$DEBIAN_FRONTEND]" >> "$LOG"\n'
               'if [ "$1" = install ] && [ -n "$APT_FAILS_ONCE" ] && [ ! -e "$LOG.failed" ]; then\n'
               '    : > "$LOG.failed"; exit 100\nfi\n',
    "id": 'echo "$STANDIN_UID"\n',
    "sudo": 'echo "sudo $*" >> "$LOG"\nexec env "$@"\n',
    "python3": 'if [ "$1" = -c ]; then echo "$PYTHON_INCLUDE"; exit 0; fi\n'  # where Python.h would be
               'echo "python3 $* in $PWD" >> "$LOG"\nmkdir -p .venv/bin\n'
               'printf \'#!/bin/bash\\necho "pip $*" >> "$LOG"\\n\' > .venv/bin/pip\n'
               'printf \'#!/bin/bash\\necho "python $*" >> "$LOG"\\nexit 7\\n\' > .venv/bin/python\n'
               'chmod +x .venv/bin/pip .venv/bin/python\n'
               'if [ -n "$VENV_SECONDS" ]; then sleep "$VENV_SECONDS"; fi\n',
}


def run_sh(tmp_path: Path, installed=PACKAGES, uid=0, sudo=False, apt_fails_once=False, args=(), headers=True,
           venv_seconds=None, heartbeat_s=None, env_more=None):
    """Run a copy of tests/run.sh; returns (exit code, stderr, lines of the command log).
    ``headers``: whether the stand-in python3's include folder holds Python.h; ``venv_seconds``: how
    long its venv creation takes; ``heartbeat_s``: TAPMP_HEARTBEAT_S; ``env_more``: more variables."""
    repo, bin_dir, log = tmp_path / "repo", tmp_path / "bin", tmp_path / "log"
    include = tmp_path / "include"
    include.mkdir(parents=True)
    if headers:
        (include / "Python.h").write_text("/* stand-in */\n")
    (repo / "tests").mkdir(parents=True)
    shutil.copy(ROOT / "tests" / "run.sh", repo / "tests" / "run.sh")
    bin_dir.mkdir()
    for tool in TOOLS:
        (bin_dir / tool).symlink_to(shutil.which(tool))
    for name, body in STANDINS.items():
        if name == "sudo" and not sudo:
            continue
        (bin_dir / name).write_text("#!/bin/bash\n" + body)
        (bin_dir / name).chmod(0o755)
    log.write_text("")
    env = {"PATH": str(bin_dir), "LOG": str(log), "INSTALLED": " ".join(installed), "STANDIN_UID": str(uid),
           "APT_FAILS_ONCE": "1" if apt_fails_once else "", "HOME": str(tmp_path), "PYTHON_INCLUDE": str(include)}
    if venv_seconds is not None:
        env["VENV_SECONDS"] = str(venv_seconds)
    if heartbeat_s is not None:
        env["TAPMP_HEARTBEAT_S"] = str(heartbeat_s)
    env.update(env_more or {})
    res = subprocess.run([str(bin_dir / "bash"), str(repo / "tests" / "run.sh"), *args], cwd=tmp_path, env=env,
                         capture_output=True, text=True, timeout=60)
    return res.returncode, res.stderr, log.read_text().splitlines()


def workers() -> int:
    """The pytest-xdist workers tests/run.sh starts here: one per CPU this process may use, at most 4."""
    return min(4, len(os.sched_getaffinity(0)))


def the_tests(repo: Path, args: str, n: int | None = None) -> list:
    return [f"python3 -m venv .venv in {repo}", "pip install -e .[test]",
            f"python -m pytest -q -n {workers() if n is None else n} --dist loadfile {args}".rstrip()]


def test_with_every_package_present_it_installs_nothing_and_runs_pytest_with_the_arguments(tmp_path):
    code, err, log = run_sh(tmp_path, args=("-k", "ssp"))
    assert code == 7, err  # pytest's exit code, through exec
    assert log == the_tests(tmp_path / "repo", "-k ssp")


def test_tapmp_test_workers_sets_the_number_of_workers_and_zero_runs_the_tests_in_one_process(tmp_path):
    for n in (0, 3):
        code, err, log = run_sh(tmp_path / str(n), env_more={"TAPMP_TEST_WORKERS": str(n)})
        assert code == 7, err
        assert log == the_tests(tmp_path / str(n) / "repo", "", n)


def test_as_root_it_installs_only_the_missing_packages_without_questions(tmp_path):
    code, err, log = run_sh(tmp_path, installed=["wine64", "libc6-arm64-cross", *FUZZ_PACKAGES])
    assert code == 7, err
    assert log == ["apt-get install -y libtbb12 qemu-user libminizip1 libxml2 [noninteractive]",
                   *the_tests(tmp_path / "repo", "")]


def test_a_python_without_c_headers_gets_python3_dev(tmp_path):
    code, err, log = run_sh(tmp_path, headers=False)
    assert code == 7, err
    assert log == ["apt-get install -y python3-dev [noninteractive]", *the_tests(tmp_path / "repo", "")]


def test_the_package_lists_are_updated_only_if_installing_fails(tmp_path):
    code, err, log = run_sh(tmp_path, installed=[], apt_fails_once=True)
    assert code == 7, err
    assert log[:3] == [f"apt-get install -y {' '.join(PACKAGES)} [noninteractive]",
                       "apt-get update [noninteractive]",
                       f"apt-get install -y {' '.join(PACKAGES)} [noninteractive]"]


def test_a_user_installs_through_sudo(tmp_path):
    code, err, log = run_sh(tmp_path, installed=[p for p in PACKAGES if p != "wine64"], uid=1000,
                            sudo=True)
    assert code == 7, err
    assert log[:2] == ["sudo DEBIAN_FRONTEND=noninteractive apt-get install -y wine64",
                       "apt-get install -y wine64 [noninteractive]"]


def test_a_user_without_sudo_gets_one_line_naming_the_packages_and_nothing_runs(tmp_path):
    code, err, log = run_sh(tmp_path, installed=["qemu-user", "libc6-arm64-cross", *FUZZ_PACKAGES], uid=1000)
    assert code == 1 and log == []
    assert err == ("tests/run.sh: the Debian packages libtbb12 wine64 libminizip1 libxml2 are missing and this user is not root and "
                   "has no sudo: install them as root (apt-get install libtbb12 wine64 libminizip1 libxml2) and run this again\n")


def test_the_fast_subset_does_not_install_chromium(tmp_path):
    code, err, log = run_sh(tmp_path, installed=[], args=("-m", "not slow"))
    assert code == 7, err
    assert log[0] == f"apt-get install -y {' '.join(p for p in PACKAGES if p != 'chromium')} [noninteractive]"


def test_every_setup_step_says_what_it_starts_and_when_it_is_done(tmp_path):
    code, err, log = run_sh(tmp_path, installed=["wine64"], args=("-k", "ssp"))
    assert code == 7, err
    said = [line.split(": done in ")[0] + (": done" if ": done in " in line else "") for line in err.splitlines()]
    missing = " ".join(p for p in PACKAGES if p != "wine64")
    assert said == [f"tests/run.sh: installing the Debian packages {missing} (apt-get)",
                    f"tests/run.sh: installing the Debian packages {missing} (apt-get): done",
                    "tests/run.sh: creating .venv (python3 -m venv)",
                    "tests/run.sh: creating .venv (python3 -m venv): done",
                    *[line for line in said if "pip install" in line],
                    f"tests/run.sh: running the tests (pytest -q -n {workers()} --dist loadfile -k ssp)"]
    assert len([line for line in said if "pip install" in line]) == 2


def test_a_long_setup_step_repeats_its_line_while_it_runs(tmp_path):
    # a venv creation of 3 s with a heartbeat every second: its line again, with the seconds so far
    code, err, log = run_sh(tmp_path, venv_seconds=3, heartbeat_s=1)
    assert code == 7, err
    beats = [line for line in err.splitlines() if line.startswith("tests/run.sh: creating .venv (python3 -m venv) "
                                                                 "(still running, ")]
    assert beats and all(line.endswith(" s)") for line in beats), err
    assert log == the_tests(tmp_path / "repo", "")  # the heartbeat ends with the step


@pytest.mark.parametrize("path", ["README.md", ".ci/run"])
def test_the_readme_and_ci_use_exactly_this_command(path):
    text = (ROOT / path).read_text()
    if path == ".ci/run":
        lines = [ln for ln in text.splitlines() if ln.strip() and not ln.startswith("#")]
        assert lines == ["set -euo pipefail", 'cd "$(dirname "$0")/.."', "export TAPMP_REQUIRE_SHARED=1",
                         "bash tests/run.sh"]
    else:
        quick = text[text.index("## Quick start"):text.index("## Layout")]
        assert "```bash\nbash tests/run.sh\n```" in quick and "python -m pytest" not in quick
    assert os.access(ROOT / "tests" / "run.sh", os.R_OK)
