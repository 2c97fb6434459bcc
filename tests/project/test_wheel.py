"""The package installed as a wheel (not editable) into a fresh venv works outside a checkout:
from an empty folder, `tapmp build --all-platforms` builds every family for every platform there with
no system compiler (without the option, the host's: tests/cli/test_cli_build.py), `tapmp
run` and `tapmp export` use a shipped scenario and the FMUs of --fmus-dir (or $TAPMP_FMUS_DIR),
and nothing is written into the installed package or the repository."""

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from tests.model.test_toolchain import EXPECTED_BINARIES, shim_path

pytestmark = pytest.mark.slow  # builds a wheel and installs it into a fresh venv

ROOT = Path(__file__).resolve().parents[2]
SKIP = shutil.ignore_patterns(".git", ".venv", "build", "results", "__pycache__", "*.egg-info", ".pytest_cache",
                              ".hypothesis", "dist")


def snapshot(folder: Path, skip=("__pycache__", ".git", ".venv", ".pytest_cache", ".hypothesis")) -> dict:
    """{relative path: (size, mtime)} of every file under ``folder``, outside the ``skip`` folders
    (Python's bytecode caches, git's and pytest's own)."""
    files = {}
    for dirpath, dirnames, filenames in os.walk(folder):
        dirnames[:] = [d for d in dirnames if d not in skip]
        for name in filenames:
            p = Path(dirpath) / name
            st = p.lstat()
            files[str(p.relative_to(folder))] = (st.st_size, st.st_mtime_ns)
    return files


def test_the_wheel_builds_runs_and_exports_from_an_empty_folder(tmp_path):
    src, dist = tmp_path / "src", tmp_path / "dist"
    shutil.copytree(ROOT, src, ignore=SKIP)  # the build leaves its own build/ there, not in the repository
    built = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(dist), str(src)],
                           capture_output=True, text=True, timeout=600)
    assert built.returncode == 0, built.stderr
    (wheel,) = dist.glob("tapmp_cosim-*.whl")
    with zipfile.ZipFile(wheel) as z:
        names = set(z.namelist())
    assert {"tapmp/c/tapmp_model.c", "fmu_plant/plant.c", "fmu_controller/TAPMP_Controller.py",
            "fmu_common/pyfront/fmi2_front.c", "tapmp_data/scenarios/paper_simulation.toml",
            "tapmp_data/studies/tune.toml", "tapmp_data/docs/tuning/sc-dc.toml",
            "orchestrator/paper/paper_tables.toml"} <= names
    print("wheel size", wheel.stat().st_size, "bytes")

    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=300)
    installed = subprocess.run([str(venv / "bin" / "pip"), "install", "-q", str(wheel)], capture_output=True,
                               text=True, timeout=1800)
    assert installed.returncode == 0, installed.stderr
    site = Path(subprocess.run([str(venv / "bin" / "python"), "-c", "import tapmp, pathlib; "
                                "print(pathlib.Path(tapmp.__file__).parent.parent)"],
                               capture_output=True, text=True, check=True, cwd=tmp_path).stdout.strip())
    assert site.name == "site-packages" and str(site).startswith(str(venv))

    work = tmp_path / "work"  # the empty folder a user starts from
    work.mkdir()
    env, compiler_log = shim_path(tmp_path)  # no system compiler reachable: calls are recorded
    env["PATH"] = f"{venv / 'bin'}:{env['PATH']}"
    env.pop("PYTHONPATH", None)
    env.pop("TAPMP_FMUS_DIR", None)
    tapmp = str(venv / "bin" / "tapmp")
    package_before, repo_before = snapshot(site), snapshot(ROOT)

    def run(*args, extra_env=None):
        proc = subprocess.run([tapmp, *args], cwd=work, env={**env, **(extra_env or {})}, capture_output=True,
                              text=True, timeout=1800)
        return proc

    missing = run("run", "paper_simulation", "--set", "stop_time=0.05")
    assert missing.returncode == 2
    assert missing.stderr.startswith("error: the native FMUs are not built (build/native/fmi2/TAPMP.ssp does not "
                                     "exist)"), missing.stderr
    assert "site-packages" not in missing.stderr

    build = run("build", "--out", "b", "--all-platforms")
    assert build.returncode == 0, build.stderr
    assert not compiler_log.exists(), compiler_log.read_text()
    for family, folders in EXPECTED_BINARIES.items():
        with zipfile.ZipFile(work / "b" / "native" / family / "TAPMP_Plant.fmu") as z:
            assert {n.split("/")[1] for n in z.namelist() if n.startswith("binaries/")} == set(folders)
    assert (work / "b" / "TAPMP.ssp").is_file() and (work / "b" / "TAPMP_ClosedLoop.fmu").is_file()

    sim = run("run", "paper_simulation", "--set", "stop_time=0.05", "--fmus-dir", "b", "--no-progress")
    assert sim.returncode == 0, sim.stderr
    assert "tracking MAE [um]:" in sim.stdout
    result = work / "results" / "paper_simulation" / "sc-dc"
    assert (result / "results.csv").is_file() and (result / "metrics.json").is_file()
    assert len((result / "results.csv").read_text().splitlines()) == 502  # header + 501 samples of 0.1 ms

    study = run("study", "gain_swep")  # a shipped study by name: misspelled, then as shipped
    assert study.returncode == 2 and "shipped are gain_sweep, robustness, tune; did you mean gain_sweep?" in study.stderr
    study = run("study", "gain_sweep", "--ssp", "none.ssp")  # found: it reaches the check of its SSP
    assert study.returncode == 2 and study.stderr.startswith("error: SSP file none.ssp does not exist"), study.stderr

    python = run("run", "paper_simulation", "--set", "stop_time=0.01", "--fmus", "python", "--out", "py",
                 "--no-progress", extra_env={"TAPMP_FMUS_DIR": "b"})  # the pythonfmu family, by the variable
    assert python.returncode == 0, python.stderr

    export = run("export", "paper_simulation", "--set", "stop_time=0.05", "--out", "e/paper.ssp",
                 extra_env={"TAPMP_FMUS_DIR": str(work / "b")})
    assert export.returncode == 0, export.stderr
    assert (work / "e" / "paper.ssp").is_file() and (work / "e" / "paper.start-values.txt").is_file()

    assert snapshot(site) == package_before  # nothing written into the installed package
    assert snapshot(ROOT) == repo_before     # nor into the repository
    assert sorted(p.name for p in work.iterdir()) == ["b", "e", "py", "results"]


def test_the_build_backend_warns_of_nothing(tmp_path):
    """setuptools, run verbosely by pip for the wheel and for the editable install, prints no warning:
    the license is an SPDX expression and every folder of C sources is a declared package."""
    src = tmp_path / "src"
    shutil.copytree(ROOT, src, ignore=SKIP)
    for command in (["wheel", "--no-deps", "-v", "-w", str(tmp_path / "dist"), str(src)],
                    ["install", "--no-deps", "-v", "--target", str(tmp_path / "target"), "-e", str(src)]):
        built = subprocess.run([sys.executable, "-m", "pip", *command], capture_output=True, text=True, timeout=600)
        assert built.returncode == 0, built.stderr
        # pip itself switches byte-compiling off in the build backend; that notice is pip's, not ours
        warnings = [line.strip() for line in (built.stdout + built.stderr).splitlines()
                    if "warning" in line.lower() and "byte-compiling is disabled" not in line]
        assert warnings == [], f"pip {command[0]}: {warnings}"
