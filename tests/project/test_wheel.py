"""The binary wheels (build_wheels.py, setup.py) and the x86_64 Linux one installed into a fresh venv.

* Each Linux wheel carries the C model and the compiled stepping core for its platform, tagged
  manylinux2014; the aarch64 wheel's libraries load under qemu-aarch64 and compute what the
  x86_64 wheel's do.
* With no compiler at all (no ziglang in the venv, $CC and every system compiler name failing),
  the installed wheel runs a case, and a fresh Dask worker started from it runs a study's case:
  the libraries compiled into the wheel are loaded, nothing compiles, the cache stays empty.
* It works outside a checkout: from an empty folder, `tapmp build --all-platforms` builds every
  family for every platform there with no system compiler (without the option, the host's:
  tests/cli/test_cli_build.py), `tapmp run` and `tapmp export` use a shipped scenario and the
  FMUs of --fmus-dir (or $TAPMP_FMUS_DIR), and nothing is written into the installed package or
  the repository.

The wheels are built once for the module and one venv serves every test."""

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import lief
import pytest

from ctoolchain import ZIGLANG, compile_c
from ctoolchain.prebuilt import WHEEL_TAGS
from tests.model.test_toolchain import EXPECTED_BINARIES, shim_path

lief.logging.disable()  # its notes on optional sections it skips
pytestmark = pytest.mark.slow  # builds wheels and installs one into a fresh venv

ROOT = Path(__file__).resolve().parents[2]
SKIP = shutil.ignore_patterns(".git", ".venv", "build", "results", "__pycache__", "*.egg-info", ".pytest_cache",
                              ".hypothesis", "dist")
LINUX = ("x86_64-linux", "aarch64-linux")
QEMU, SYSROOT = "qemu-aarch64", Path("/usr/aarch64-linux-gnu")  # Debian's qemu-user and libc6-arm64-cross
HOST_C = Path(__file__).with_name("wheel_model_host.c")
WAIT_S = 300.0  # the longest a step of the Dask study may take on a loaded machine [s]; not a speed target


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


@pytest.fixture(scope="module")
def wheels(tmp_path_factory) -> dict:
    """{platform: wheel} of the Linux platforms, built by build_wheels.py (each in pip's isolated
    build environment, by zig cc for its target)."""
    dist = tmp_path_factory.mktemp("dist")
    built = subprocess.run([sys.executable, str(ROOT / "build_wheels.py"), *(f"--platform={p}" for p in LINUX),
                            "--out", str(dist)], capture_output=True, text=True, timeout=1200, cwd=dist)
    assert built.returncode == 0, built.stderr
    found = {p: list(dist.glob(f"tapmp_cosim-*-py3-none-{WHEEL_TAGS[p]}.whl")) for p in LINUX}
    assert all(len(w) == 1 for w in found.values()) and len(list(dist.iterdir())) == len(LINUX), \
        sorted(dist.iterdir())
    return {p: w[0] for p, w in found.items()}


@pytest.fixture(scope="module")
def venv(wheels, tmp_path_factory) -> Path:
    """A fresh venv with the x86_64 Linux wheel installed, with its dependencies."""
    venv = tmp_path_factory.mktemp("venv")
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=300)
    pip(venv, "install", str(wheels["x86_64-linux"]))
    return venv


def pip(venv: Path, *args) -> None:
    proc = subprocess.run([str(venv / "bin" / "pip"), *args, "-q"], capture_output=True, text=True, timeout=1800)
    assert proc.returncode == 0, proc.stderr


def site_of(venv: Path, cwd: Path) -> Path:
    """The venv's site-packages, where it imports tapmp from."""
    site = Path(subprocess.run([str(venv / "bin" / "python"), "-c", "import tapmp, pathlib; "
                                "print(pathlib.Path(tapmp.__file__).parent.parent)"],
                               capture_output=True, text=True, check=True, cwd=cwd).stdout.strip())
    assert site.name == "site-packages" and str(site).startswith(str(venv))
    return site


def shipped(wheel: Path) -> dict:
    """{name in the wheel: bytes} of the compiled libraries ``wheel`` carries."""
    with zipfile.ZipFile(wheel) as z:
        return {n: z.read(n) for n in z.namelist() if n.endswith((".so", ".dll", ".dylib"))}


def test_each_linux_wheel_carries_its_platforms_libraries_tagged_manylinux2014(wheels):
    for platform, wheel in wheels.items():
        with zipfile.ZipFile(wheel) as z:
            names = set(z.namelist())
            meta = z.read(next(n for n in names if n.endswith(".dist-info/WHEEL"))).decode()
        assert "Root-Is-Purelib: false" in meta
        assert sorted(re.findall(r"^Tag: (.+)$", meta, re.M)) == sorted(
            f"py3-none-{t}" for t in WHEEL_TAGS[platform].split("."))
        assert {"tapmp/c/tapmp_model.c", "orchestrator/engine/stepper.c", "fmu_plant/plant.c",
                "tapmp_data/scenarios/paper_simulation.toml"} <= names
        libraries = shipped(wheel)
        assert sorted(re.sub(r"-[0-9a-f]{16}-", "-HASH-", n) for n in libraries) == [
            f"orchestrator/engine/tapmp_stepper-HASH-{platform}.so", f"tapmp/c/tapmp_model-HASH-{platform}.so"]
        machine = lief.ELF.ARCH.X86_64 if platform == "x86_64-linux" else lief.ELF.ARCH.AARCH64
        for name, data in libraries.items():
            elf = lief.ELF.parse(list(data))
            assert elf.header.machine_type == machine, name
            exports = {s.name for s in elf.exported_symbols}
            assert ("tapmp_advance" if "stepper" in name else "tapmp_loop_run") in exports, name
            # manylinux2014: libc and libm of glibc 2.17 at most, nothing else
            assert set(elf.libraries) <= {"libc.so.6", "libm.so.6"}, (name, elf.libraries)
            versions = {s.symbol_version.symbol_version_auxiliary.name for s in elf.imported_symbols
                        if s.has_version and s.symbol_version.has_auxiliary_version}
            assert versions and max(tuple(map(int, v[6:].split("."))) for v in versions) <= (2, 17), (name, versions)
        print(platform, wheel.name, wheel.stat().st_size, "bytes")


def test_the_aarch64_wheels_libraries_load_under_qemu_and_compute_what_the_x86_64_ones_do(wheels, tmp_path):
    rows = {}
    for platform, wheel in wheels.items():
        folder = tmp_path / platform
        with zipfile.ZipFile(wheel) as z:
            z.extractall(folder, members=list(shipped(wheel)))
        (model,) = folder.glob("tapmp/c/tapmp_model-*.so")
        (core,) = folder.glob("orchestrator/engine/tapmp_stepper-*.so")
        host = compile_c([HOST_C], tmp_path / f"host-{platform}", platform, shared=False,
                         flags=["-O1", "-Wall", "-Wextra", "-Werror"], libs=["dl"])
        command = [str(host), str(model), str(core), "200"]
        if platform == "aarch64-linux":
            assert lief.ELF.parse(str(host)).header.machine_type == lief.ELF.ARCH.AARCH64
            command = [QEMU, "-L", str(SYSROOT), *command]
        proc = subprocess.run(command, capture_output=True, text=True, timeout=300, env={"PATH": os.environ["PATH"]})
        assert proc.returncode == 0, proc.stderr
        *lines, last = proc.stdout.splitlines()
        assert last == "stepper ok" and len(lines) == 200
        rows[platform] = [[float(x) for x in line.split()] for line in lines]
    assert rows["aarch64-linux"] == rows["x86_64-linux"]  # to the bit: no fused multiply-add on either
    assert max(abs(r[0]) for r in rows["x86_64-linux"]) > 1e-3  # the motors moved [m]: this compares something


def test_without_any_compiler_the_wheel_runs_a_case_and_a_fresh_dask_workers_first_case(venv, native_built,
                                                                                         tmp_path):
    pip(venv, "uninstall", "-y", "ziglang")
    site = site_of(venv, tmp_path)
    env, compiler_log = shim_path(tmp_path)  # every system compiler name records its call and fails
    env["CC"] = str(tmp_path / "shims" / "cc")  # and so does $CC, which the host's libraries would use
    env["PATH"] = f"{venv / 'bin'}:{env['PATH']}"
    cache = tmp_path / "cache"
    env.update(TAPMP_CACHE=str(cache), XDG_CACHE_HOME=str(tmp_path / "xdg"))
    env.pop("PYTHONPATH", None)
    work = tmp_path / "work"
    work.mkdir()
    ssp = native_built["fmi2"]["ssp"]  # the client's FMUs, built by this checkout, laid out as --fmus-dir reads them
    (tmp_path / "fmus").mkdir()
    (tmp_path / "fmus" / "native").symlink_to(ssp.parents[1], target_is_directory=True)

    def run(*args, **kwargs):
        return subprocess.run([str(venv / "bin" / args[0]), *args[1:]], cwd=work, env=kwargs.get("env", env),
                              capture_output=True, text=True, timeout=600)

    where = run("python", "-c", "from tapmp import cmodel; from orchestrator.engine import stepper; "
                "print(cmodel.library_path()); print(stepper.build())")
    assert where.returncode == 0, where.stderr
    model, core = map(Path, where.stdout.split())
    assert model.parent == site / "tapmp" / "c" and re.fullmatch(r"tapmp_model-[0-9a-f]{16}-x86_64-linux\.so", model.name)
    assert core.parent == site / "orchestrator" / "engine" and core.name.startswith("tapmp_stepper-")

    case = run("tapmp", "run", "paper_simulation", "--set", "stop_time=0.05", "--fmus-dir", str(tmp_path / "fmus"),
               "--no-progress")
    assert case.returncode == 0, case.stderr
    assert "tracking MAE [um]:" in case.stdout and "stepping in Python" not in case.stderr, case.stderr

    # a fresh Dask worker of this venv joins a study that waits for one; its first case, from its start
    scheduler_file, out = tmp_path / "scheduler.json", work / "study"
    logs = {name: open(tmp_path / f"{name}.log", "w") for name in ("scheduler", "client", "worker")}
    procs = []

    def start(name, *args):
        procs.append(subprocess.Popen([str(venv / "bin" / args[0]), *args[1:]], cwd=work, env=env,
                                      stdout=logs[name], stderr=subprocess.STDOUT, start_new_session=True))
        return procs[-1]

    def wait_until(condition, what):
        deadline = time.monotonic() + WAIT_S
        while not condition():
            assert time.monotonic() < deadline and all(p.poll() in (None, 0) for p in procs), \
                f"{what}: " + "; ".join(f"{n}: {(tmp_path / f'{n}.log').read_text()[-2000:]}" for n in logs)
            time.sleep(0.02)
    try:
        start("scheduler", "dask", "scheduler", "--scheduler-file", str(scheduler_file), "--host", "127.0.0.1",
              "--port", "0", "--no-dashboard")
        wait_until(lambda: scheduler_file.is_file() and scheduler_file.stat().st_size, "the scheduler's address")
        address = json.loads(scheduler_file.read_text())["address"]
        study = work / "s.toml"
        study.write_text(f'[study]\nname = "s"\nbase = "{site}/tapmp_data/scenarios/paper_simulation.toml"\n'
                         '[set]\nstop_time = 0.05\n[grid]\n"gain_overrides.D" = [225.0, 450.0]\n')
        client = start("client", "tapmp", "study", str(study), "--scheduler", address, "--ssp", str(ssp),
                       "--out", str(out), "--worker-timeout", str(WAIT_S))
        time.sleep(1.0)  # the client is connected and waits for a worker (else the worker just waits for it)
        started = time.monotonic()
        start("worker", "dask", "worker", address, "--nthreads", "1", "--no-dashboard")
        wait_until(lambda: any(out.glob("cases/*/metrics.json")), "the first case's files")
        first_case = time.monotonic() - started
        wait_until(lambda: client.poll() is not None, "the study's end")
        assert client.returncode == 0, (tmp_path / "client.log").read_text()
    finally:
        for p in reversed(procs):
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGKILL)
            p.wait(timeout=60)
        for f in logs.values():
            f.close()
    print(f"a fresh worker's first case: {first_case:.2f} s after its start")
    assert len((out / "study.csv").read_text().splitlines()) == 3  # header + both cases
    assert "stepping in Python" not in (tmp_path / "worker.log").read_text()
    assert not compiler_log.exists(), compiler_log.read_text()  # nothing compiled anything
    assert not list(cache.rglob("*.so"))  # nor put a library into the cache (nor Zig's: there is no Zig)
    assert not (tmp_path / "xdg" / "tapmp").exists() and not (tmp_path / "xdg" / "zig").exists()

    # without the shipped library (a wheel of another platform, an sdist) and without a compiler: one line each
    no_cc = {k: v for k, v in env.items() if k != "CC"}
    bare = run("python", "-c", "import ctoolchain.prebuilt as p; p.find_prebuilt = lambda *a: None\n"
               "from tapmp import cmodel\ntry:\n    cmodel.load()\nexcept cmodel.CModelError as e:\n    print(e)",
               env=no_cc)
    assert bare.stdout.strip() == (f"the C model (x86_64-linux): no C compiler: the ziglang package is not installed "
                                   f"(pip install {ZIGLANG}) or set CC to a C compiler"), bare.stderr
    build = run("tapmp", "build", "--out", "b", env=no_cc)
    assert build.returncode == 2 and f"no C compiler: the ziglang package is not installed (pip install {ZIGLANG})" \
        in build.stderr and len(build.stderr.strip().splitlines()) == 1, build.stdout + build.stderr


def test_the_wheel_builds_runs_and_exports_from_an_empty_folder(wheels, venv, tmp_path):
    with zipfile.ZipFile(wheels["x86_64-linux"]) as z:
        names = set(z.namelist())
    assert {"tapmp/c/tapmp_model.c", "fmu_plant/plant.c", "fmu_controller/TAPMP_Controller.py",
            "fmu_common/pyfront/fmi2_front.c", "tapmp_data/scenarios/paper_simulation.toml",
            "tapmp_data/studies/tune.toml", "tapmp_data/docs/tuning/sc-dc.toml",
            "orchestrator/paper/paper_tables.toml"} <= names
    pip(venv, "install", ZIGLANG)  # `tapmp build` compiles the FMUs: the compiler the wheel's dependencies bring
    site = site_of(venv, tmp_path)

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
