"""Studies on a real Dask cluster that shares no files with the client: `dask scheduler` and
`dask worker` processes on loopback, each in a mount namespace of its own where the checkout,
pytest's temporary folder (the client's SSP, gain files and output folders) and the cache of
the client's user are empty folders, with a HOME of its own and tapmp installed from a wheel of
this checkout (its dependencies are the client's, bind-mounted read-only before the checkout is
hidden, so the venv is made in seconds). The client is the real `tapmp study`
(orchestrator.cli.main, or a child process where a signal is sent).

Needs root (mount namespaces), as CI runs."""

import csv
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import sysconfig
import tempfile
import time
from pathlib import Path

import pytest

from ctoolchain.prebuilt import host_platform

from orchestrator.cli import main
from orchestrator.studies.study import close_client, open_client

pytestmark = pytest.mark.slow  # a wheel venv, a Dask scheduler and workers in child processes

ROOT = Path(__file__).resolve().parents[2]
BASE = ROOT / "scenarios" / "paper_simulation.toml"
SKIP = shutil.ignore_patterns(".git", ".venv", "build", "results", "__pycache__", "*.egg-info", ".pytest_cache",
                              ".hypothesis", "dist")
# A worker plugin loaded with `dask worker --preload`: every case that finishes on the worker is a
# line in RUNS/runs.txt (appended, so a killed worker's lines stay), and the worker's pid a file
# RUNS/pid-PID.
COUNT_RUNS = '''
import os
from distributed.diagnostics.plugin import WorkerPlugin

RUNS = os.environ["TAPMP_TEST_RUNS"]


class CountRuns(WorkerPlugin):
    def transition(self, key, start, finish, **kwargs):
        if finish == "memory" and str(key).startswith("case-"):
            with open(os.path.join(RUNS, "runs.txt"), "a") as f:
                f.write(str(key) + "\\n")


def dask_setup(worker):
    open(os.path.join(RUNS, f"pid-{os.getpid()}"), "w").close()
    worker.plugins["count-runs"] = CountRuns()
'''


WAIT_S = 120.0  # the longest any step of these tests may take on a loaded machine [s]


def wait_until(condition, process: subprocess.Popen, what: str, log) -> None:
    """Poll ``condition`` until it holds; fail naming ``what`` (with ``log()``) if ``process`` ends
    first or WAIT_S passes, so a study that hangs fails the test instead of hanging the suite."""
    deadline = time.monotonic() + WAIT_S
    while not condition():
        assert process.poll() is None, f"{what}: the process ended: {log()}"
        assert time.monotonic() < deadline, f"{what}: not within {WAIT_S:g} s: {log()}"
        time.sleep(0.05)


@pytest.fixture(scope="module")
def wheel_venv(tmp_path_factory):
    """A folder outside pytest's temporary folder holding a venv with tapmp installed from a wheel
    of this checkout (the workers' installation) and the workers' HOME; removed at the end."""
    if os.geteuid() != 0:
        pytest.fail("these tests start the Dask workers in mount namespaces: run them as root (as CI does)")
    top = Path(tempfile.mkdtemp(prefix="tapmp_remote_", dir="/tmp"))
    tmp = tmp_path_factory.mktemp("wheel")
    shutil.copytree(ROOT, tmp / "src", ignore=SKIP)
    # the binary wheel of this machine (setup.py): the workers load the shipped C model, compiling nothing
    built = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w",
                            str(tmp / "dist"), str(tmp / "src")], capture_output=True, text=True, timeout=600,
                           env={**os.environ, "TAPMP_WHEEL_PLATFORM": host_platform()})
    assert built.returncode == 0, built.stderr
    (wheel,) = (tmp / "dist").glob("tapmp_cosim-*.whl")
    venv = top / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=300)
    installed = subprocess.run([str(venv / "bin" / "pip"), "install", "-q", "--no-deps", str(wheel)],
                               capture_output=True, text=True, timeout=600)
    assert installed.returncode == 0, installed.stderr
    (top / "deps").mkdir()  # the client's site-packages are mounted here (after the wheel's tapmp on sys.path)
    site = Path(sysconfig.get_paths()["purelib"].replace(sys.prefix, str(venv)))
    (site / "client_deps.pth").write_text(str(top / "deps") + "\n")
    (top / "home" / "tmp").mkdir(parents=True)
    (top / "home" / "count_runs.py").write_text(COUNT_RUNS)
    yield venv
    shutil.rmtree(top, ignore_errors=True)


@pytest.fixture(scope="module")
def ssp(tmp_path_factory):
    """The native FMI 2.0 FMUs for this machine and their SSP, in the client's (hidden) folder."""
    from orchestrator.builder.build_native import build_native
    return build_native(tmp_path_factory.mktemp("native"), families=("fmi2",), log=lambda *_: None,
                        windows=False)["fmi2"]["ssp"]


class Cluster:
    """A `dask scheduler` and `dask worker` processes of the wheel venv, each in a mount namespace
    where the checkout, pytest's temporary folder and ~/.cache of the client's user are empty."""

    def __init__(self, venv: Path, hidden: list):
        self.venv, self.home = venv, venv.parent / "home"
        self.hidden = hidden
        self.procs = []
        self.folder = Path(tempfile.mkdtemp(dir=self.home / "tmp"))  # the worker's record (COUNT_RUNS)
        self.scheduler_file = self.folder / "scheduler.json"
        self.scheduler = self._start("scheduler", "--scheduler-file", str(self.scheduler_file), "--host",
                                     "127.0.0.1", "--port", "0", "--no-dashboard")
        wait_until(lambda: self.scheduler_file.exists() and self.scheduler_file.stat().st_size, self.scheduler,
                   "the scheduler's address file",
                   lambda: self.scheduler.stderr.read() if self.scheduler.poll() is not None else "still running")
        self.address = json.loads(self.scheduler_file.read_text())["address"]

    def _start(self, *args, env=None) -> subprocess.Popen:
        deps = sysconfig.get_paths()["purelib"]
        mounts = [f"mount --bind -o ro {deps} {self.venv.parent / 'deps'}",
                  *(f"mount -t tmpfs tmpfs {p}" for p in self.hidden)]
        environment = {"HOME": str(self.home), "PATH": f"{self.venv / 'bin'}:/usr/bin:/bin",
                       "TMPDIR": str(self.home / "tmp"), "TAPMP_TEST_RUNS": str(self.folder), **(env or {})}
        command = ["unshare", "--mount", "--propagation", "private", "sh", "-c",
                   " && ".join(mounts) + ' && exec "$@"', "sh", "env", "-i",
                   *(f"{k}={v}" for k, v in environment.items()), str(self.venv / "bin" / "python"), "-m", "dask",
                   *args]
        proc = subprocess.Popen(command, cwd=self.home, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                text=True, start_new_session=True)
        self.procs.append(proc)
        return proc

    def worker(self, n: int = 1, env=None) -> subprocess.Popen:
        """`dask worker` with ``n`` single-threaded worker processes (each under a nanny)."""
        return self._start("worker", self.address, "--nworkers", str(n), "--nthreads", "1", "--no-dashboard",
                           "--preload", str(self.home / "count_runs.py"), env=env)

    def runs(self) -> list[str]:
        """The case of every case run to its end on a worker, once per run (a task's key is "case-",
        its batch's case ids joined by ",", and a random suffix: orchestrator.studies.batches.batch_key)."""
        path = self.folder / "runs.txt"
        keys = path.read_text().split() if path.exists() else []
        return [case for key in keys for case in key[len("case-"):].rsplit("-", 1)[0].split(",")]

    def worker_pids(self) -> list[int]:
        return [int(p.name[4:]) for p in self.folder.glob("pid-*")]

    def stop(self) -> None:
        for proc in reversed(self.procs):
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=60)


@pytest.fixture(scope="module")
def hidden(tmp_path_factory):
    """What the workers must not see: the checkout, pytest's temporary folder, the client's cache."""
    cache = Path.home() / ".cache"
    return [ROOT, tmp_path_factory.getbasetemp(), *([cache] if cache.is_dir() else [])]


@pytest.fixture
def cluster_factory(wheel_venv, hidden):
    made = []

    def make() -> Cluster:
        made.append(Cluster(wheel_venv, hidden))
        return made[-1]

    yield make
    for c in made:
        c.stop()


@pytest.fixture(scope="module")
def cluster(wheel_venv, hidden):
    """One scheduler with one worker of two processes, shared by the tests that do not break it."""
    c = Cluster(wheel_venv, hidden)
    c.worker(2)
    yield c
    c.stop()


@pytest.fixture(scope="module")
def local():
    """The local cluster the remote runs are compared with."""
    client = open_client(workers=1)
    yield client
    close_client(client)


def write_study(folder: Path, text: str, name: str) -> Path:
    path = folder / f"{name}.toml"
    path.write_text(f'[study]\nname = "{name}"\nbase = "{BASE}"\n' + text)
    return path


def table(out: Path) -> dict:
    """study.csv by case, without the columns that differ between runs (wall time, worker); the
    stability check's spectral radius to 12 digits (its eigenvalues come from LAPACK, whose last
    bits differ between processes; the co-simulation's numbers are compared whole)."""
    with open(out / "study.csv", newline="") as f:
        return {r["case"]: {k: (f"{float(v):.12g}" if k == "spectral_radius" and v else v) for k, v in r.items()
                            if k not in ("wall_time_s", "worker")} for r in csv.DictReader(f)}


def case_files(out: Path) -> dict:
    """{case/file: content} of every case folder, run.json without its wall times, the output
    folder's path as OUT (a tuning's comparison runs name the preset it wrote there)."""
    files = {}
    for path in sorted((out / "cases").glob("*/*")):
        if path.name == ".tapmp.lock":
            continue
        data = path.read_text().replace(str(out), "OUT")
        if path.name == "run.json":
            data = {k: v for k, v in json.loads(data).items() if k not in ("wall_time_s", "real_time_factor")}
        files[f"{path.parent.name}/{path.name}"] = data
    return files


STUDIES = {
    "grid": '[set]\nstop_time = 0.02\n[grid]\nlaw = ["sc-dc", "apd-dc"]\n"gain_overrides.Lambda_v" = [0.36, 0.72]\n',
    "monte_carlo": ('[set]\nstop_time = 0.02\n[monte_carlo]\nsamples = 3\nseed = 5\n'
                    '[monte_carlo.vary.mass]\ntargets = ["plant.m_1"]\ndistribution = "uniform"\n'
                    'low = 0.9\nhigh = 1.1\nrelative = true\n'),
    "tune": ('[set]\nstop_time = 0.01\n[tune]\nlaws = ["apd-dc"]\npopulation = 2\ngenerations = 1\nseed = 1\n'
             'write_to = "unused"\ncompare_stop_time = 0.02\n[tune.bounds.apd-dc]\nLambda_v = [0.2, 2.0]\n'),
}


@pytest.mark.parametrize("kind", list(STUDIES))
def test_a_study_on_a_worker_that_cannot_see_the_checkout_leaves_the_output_of_a_local_run(
        kind, cluster, local, ssp, tmp_path, capsys):
    study = write_study(tmp_path, STUDIES[kind], kind)
    remote, here = tmp_path / "remote", tmp_path / "local"
    code = main(["study", study, "--scheduler", cluster.address, "--ssp", ssp, "--out", remote, "--no-progress"])
    out = capsys.readouterr()
    assert code == 0, out.err
    assert "starting the Dask workers" not in out.err and "failed: " not in out.out
    from orchestrator.studies.run import run_study
    from orchestrator.studies.study import load_study
    run_study(load_study(study), ssp, local, here, progress=False)
    assert table(remote) == table(here)
    # every case ran; a tuning also rejects, without running, candidates beyond its Ms bound
    assert {r["status"] for r in table(remote).values()} == ({"completed", "rejected"} if kind == "tune"
                                                           else {"completed"})
    ran = [r for r in table(here).values() if r["status"] != "rejected"]  # a rejected candidate has no folder
    assert case_files(remote) == case_files(here) and len(case_files(remote)) >= 2 * len(ran)
    if kind == "tune":  # the comparison ran the preset the client wrote, and read every case's metrics
        def results(path: Path) -> str:  # what follows the line naming the command
            return path.read_text().split("\n", 3)[3]
        assert results(remote / "tuning" / "comparison.md") == results(here / "tuning" / "comparison.md")
        assert results(remote / "tuning" / "apd-dc.toml") == results(here / "tuning" / "apd-dc.toml")
        assert "failed:" not in (remote / "tuning" / "comparison.md").read_text()
    workers = {r["worker"] for r in csv.DictReader(open(remote / "study.csv")) if r["status"] != "rejected"}
    assert workers and not {w.split(":")[1] for w in workers} & {str(os.getpid())}


def test_a_gains_file_is_read_by_the_client_and_its_values_sent(cluster, ssp, tmp_path, capsys):
    preset = tmp_path / "mine.toml"  # in the client's root-only folder: the worker cannot read it
    preset.write_text('[gains]\nLambda_p = 1.2\nLambda_v = 0.5\nK_T = 60.0\nb = 5.0\nD = 900.0\n')
    study = write_study(tmp_path, f'[set]\nstop_time = 0.02\ngains_file = "{preset}"\n[grid]\n'
                        f'law = ["sc-dc", "apd-dc"]\n', "gf")
    code = main(["study", study, "--scheduler", cluster.address, "--ssp", ssp, "--out", tmp_path / "o",
                 "--no-progress"])
    assert code == 0, capsys.readouterr().err
    for case in ("c0000", "c0001"):
        run = json.loads((tmp_path / "o" / "cases" / case / "run.json").read_text())
        assert run["status"] == "completed" and run["scenario"]["gains_file"] == str(preset)
        assert run["scenario"]["gain_values"]["Lambda_v"] == [0.5] * 3 and run["ssp"] == str(Path(ssp).resolve())


def start_client(*args, tmp: Path) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "orchestrator", "study", *map(str, args), "--no-progress"],
                            env=dict(os.environ, TMPDIR=str(tmp)), stdout=subprocess.PIPE,
                            stderr=open(tmp / "stderr.txt", "w"), text=True)


def rows_in(out: Path) -> list[str]:
    path = out / "study.csv"
    return [line.split(",")[0] for line in path.read_text().splitlines()[1:]] if path.exists() else []


def test_a_worker_killed_mid_batch_loses_and_duplicates_no_case(cluster_factory, ssp, tmp_path):
    """40 cases in batches of 4 on one worker process, killed (SIGKILL) once rows have come: the
    batch it was running is run again by the new worker its nanny starts, the recorded ones never;
    every case has exactly one row. A batch counts as run when its task ends on a worker (COUNT_RUNS)."""
    c = cluster_factory()
    c.worker(1)
    values = ", ".join(f"{400.0 + 10 * i}" for i in range(40))
    study = write_study(tmp_path, f'[set]\nstop_time = 0.2\n[grid]\n"gain_overrides.D" = [{values}]\n', "kill")
    client = start_client(study, "--scheduler", c.address, "--ssp", ssp, "--out", tmp_path / "o", "--batch-size",
                          "4", tmp=tmp_path)
    wait_until(lambda: len(rows_in(tmp_path / "o")) >= 8, client, "two batches' rows",
               lambda: (tmp_path / "stderr.txt").read_text())
    for pid in c.worker_pids():  # the worker process, not its nanny: the nanny starts a new one
        os.kill(pid, signal.SIGKILL)
    recorded = rows_in(tmp_path / "o")
    out, _ = client.communicate(timeout=300)
    assert client.returncode == 0, out + (tmp_path / "stderr.txt").read_text()
    assert "40 completed, 0 diverged, 0 failed" in out
    assert len(recorded) < 40, "the study ended before the worker was killed"
    assert sorted(rows_in(tmp_path / "o")) == [f"c{i:04d}" for i in range(40)]  # each once
    assert len(c.worker_pids()) == 2  # the worker was killed and another took its place
    runs = c.runs()
    for case in recorded:  # collected before the kill: never run again
        assert runs.count(case) == 1, (case, runs)
    # the others ran to their end once, or twice if their batch had ended on the killed worker
    # but was not yet collected (Dask runs a lost result again, once)
    assert all(1 <= runs.count(f"c{i:04d}") <= 2 for i in range(40)), runs


def test_the_ssp_is_sent_once_per_cluster_and_a_second_study_finds_it_there(cluster, ssp, tmp_path, capsys):
    """Two studies of the same SSP on one cluster: the worker plugin holding its bytes (named by
    their hash) is the one the first study registered; the second sent nothing (its nonce, made
    when the client builds the plugin, is still the first's on every worker)."""
    import hashlib

    from distributed import Client

    from orchestrator.studies.remote import ssp_plugin_name
    name = ssp_plugin_name(hashlib.sha256(Path(ssp).read_bytes()).hexdigest())
    study = write_study(tmp_path, '[set]\nstop_time = 0.02\n[grid]\nlaw = ["sc-dc", "apd-dc"]\n', "twice")
    nonces = []
    for out in ("a", "b"):
        code = main(["study", study, "--scheduler", cluster.address, "--ssp", ssp, "--out", tmp_path / out,
                     "--no-progress"])
        assert code == 0, capsys.readouterr().err
        with Client(cluster.address) as c:
            nonces.append(c.run(lambda dask_worker: dask_worker.plugins[name].nonce))
    assert len(nonces[0]) == 2 and len(set(nonces[0].values())) == 1  # both worker processes, one plugin
    assert nonces[1] == nonces[0]
    assert table(tmp_path / "a") == table(tmp_path / "b")


def test_with_every_worker_gone_the_study_waits_with_one_line_and_ends_on_sigterm(cluster_factory, ssp, tmp_path):
    c = cluster_factory()
    worker = c.worker(1)
    study = write_study(tmp_path, '[set]\nstop_time = 0.2\n[grid]\n"gain_overrides.D" = '
                        '[400.0, 500.0, 600.0, 700.0, 800.0, 900.0]\n', "gone")
    client = start_client(study, "--scheduler", c.address, "--ssp", ssp, "--out", tmp_path / "o", tmp=tmp_path)
    wait_until(lambda: rows_in(tmp_path / "o"), client, "a row", lambda: (tmp_path / "stderr.txt").read_text())
    os.killpg(worker.pid, signal.SIGKILL)  # the worker, its nanny and all
    stderr = tmp_path / "stderr.txt"
    wait_until(lambda: "no Dask worker is connected" in stderr.read_text(), client, "the no-worker line",
               stderr.read_text)
    client.send_signal(signal.SIGTERM)
    client.communicate(timeout=30)  # the client no longer waits for cases no worker runs
    lines = stderr.read_text().splitlines()
    assert client.returncode == 143, lines
    assert sum("no Dask worker is connected" in line for line in lines) == 1
    assert lines[-1] == "interrupted by SIGTERM: the results so far are in the output folder", lines
    assert 1 <= len(rows_in(tmp_path / "o")) < 6


def test_a_worker_with_another_tapmp_version_is_refused_naming_it_and_both_versions(
        cluster_factory, ssp, tmp_path, capsys):
    """The worker's tapmp-cosim reports version 9.9.9: a dist-info folder of that version earlier on
    its sys.path (PYTHONPATH) is what importlib.metadata finds first, as when another version is
    installed there."""
    c = cluster_factory()
    fake = c.folder / "site"
    (fake / "tapmp_cosim-9.9.9.dist-info").mkdir(parents=True)
    (fake / "tapmp_cosim-9.9.9.dist-info" / "METADATA").write_text(
        "Metadata-Version: 2.1\nName: tapmp-cosim\nVersion: 9.9.9\n")
    c.worker(1, env={"PYTHONPATH": str(fake)})
    study = write_study(tmp_path, '[set]\nstop_time = 0.02\n[grid]\nlaw = ["sc-dc"]\n', "v")
    code = main(["study", study, "--scheduler", c.address, "--ssp", ssp, "--out", tmp_path / "o", "--no-progress"])
    err = capsys.readouterr().err.splitlines()
    assert code == 2
    from importlib.metadata import version
    assert err[-1].startswith("error: Dask worker tcp://127.0.0.1:") and " runs tapmp-cosim 9.9.9, " in err[-1]
    assert f"this client tapmp-cosim {version('tapmp-cosim')}, " in err[-1]
    assert not c.runs() and not (tmp_path / "o" / "study.csv").exists()


def changed_copy(venv: Path, folder: Path) -> Path:
    """``folder`` holding a copy of the wheel's installed orchestrator package with one byte of a
    source file changed (a comment sign added): first on a worker's PYTHONPATH, it is what the
    worker imports, with the same tapmp-cosim version (another commit numbered the same)."""
    site = Path(sysconfig.get_paths()["purelib"].replace(sys.prefix, str(venv)))
    shutil.copytree(site / "orchestrator", folder / "orchestrator", ignore=shutil.ignore_patterns("__pycache__"))
    init = folder / "orchestrator" / "__init__.py"
    init.write_bytes(init.read_bytes() + b"#")
    return folder


def test_a_worker_of_other_content_joining_mid_study_is_retired_and_every_case_completes_on_the_good_one(
        cluster_factory, wheel_venv, ssp, tmp_path):
    """The good worker is paused (SIGSTOP) from the first row until the bad one has been retired, so
    the bad one joins while cases are left, whatever the machine's speed."""
    c = cluster_factory()
    c.worker(1)
    values = ", ".join(f"{400.0 + 20 * i}" for i in range(20))
    study = write_study(tmp_path, f'[set]\nstop_time = 0.2\n[grid]\n"gain_overrides.D" = [{values}]\n', "join")
    client = start_client(study, "--scheduler", c.address, "--ssp", ssp, "--out", tmp_path / "o", tmp=tmp_path)
    stderr = tmp_path / "stderr.txt"
    wait_until(lambda: rows_in(tmp_path / "o"), client, "a row", stderr.read_text)
    (good,) = c.worker_pids()
    os.kill(good, signal.SIGSTOP)
    try:
        bad = c.worker(1, env={"PYTHONPATH": str(changed_copy(wheel_venv, c.folder / "changed"))})
        wait_until(lambda: "warning: " in stderr.read_text(), client, "the bad worker's warning", stderr.read_text)
        assert len(rows_in(tmp_path / "o")) < 20
    finally:
        os.kill(good, signal.SIGCONT)
    out, _ = client.communicate(timeout=600)
    assert client.returncode == 0, out + stderr.read_text()
    assert "20 cases (20 run now, " in out and "20 completed, 0 diverged, 0 failed" in out
    assert bad.wait(timeout=WAIT_S) is not None  # retired: the worker and its nanny closed
    (warning,) = [line for line in stderr.read_text().splitlines() if line.startswith("warning: ")]
    theirs, ours = re.fullmatch(r"warning: Dask worker tcp://127\.0\.0\.1:\d+ \(\S+\) runs (.*), this client (.*): "
                                r"install the same tapmp-cosim on every worker \(pip install the wheel the client "
                                r"uses\); this worker is retired from the study, its cases run on the others",
                                warning).groups()
    version, package, model = re.fullmatch(r"tapmp-cosim (\S+), package sources (\w+), model sources (\w+)",
                                           theirs).groups()
    assert ours.startswith(f"tapmp-cosim {version}, package sources ") and ours.endswith(f", model sources {model}")
    assert f"package sources {package}," not in ours  # the same version and model: the package's content differs
    with open(tmp_path / "o" / "study.csv", newline="") as f:
        assert {r["worker"].split(":")[1] for r in csv.DictReader(f)} == {str(good)}
    assert sorted(c.runs()) == [f"c{i:04d}" for i in range(20)]  # each once


def test_without_workers_the_study_ends_with_one_line_after_the_timeout(cluster_factory, ssp, tmp_path, capsys):
    c = cluster_factory()
    study = write_study(tmp_path, '[set]\nstop_time = 0.02\n[grid]\nlaw = ["sc-dc"]\n', "none")
    code = main(["study", study, "--scheduler", c.address, "--ssp", ssp, "--out", tmp_path / "o", "--no-progress",
                 "--worker-timeout", "2"])
    err = capsys.readouterr().err.splitlines()
    assert code == 2 and err[-1] == (f"error: no Dask worker joined the scheduler at {c.address} within 2 s: start "
                                     f"workers with `dask worker {c.address} --nthreads 1` (one per core), or wait "
                                     "longer with --worker-timeout")


def test_a_wrong_scheduler_address_is_one_line_and_starts_no_workers(ssp, tmp_path, capsys):
    study = write_study(tmp_path, '[set]\nstop_time = 0.02\n[grid]\nlaw = ["sc-dc"]\n', "nowhere")
    with socket_nobody_listens() as address:
        code = main(["study", study, "--scheduler", address, "--ssp", ssp, "--out", tmp_path / "o",
                     "--worker-timeout", "1"])
    err = capsys.readouterr().err
    assert code == 2 and "starting the Dask workers" not in err
    assert err.splitlines()[-1].startswith(f"error: --scheduler {address}: cannot reach a Dask scheduler there "
                                           "within 1 s")


class socket_nobody_listens:
    """A loopback address whose port was just free (bound, then closed)."""

    def __enter__(self) -> str:
        import socket
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            return f"tcp://127.0.0.1:{s.getsockname()[1]}"

    def __exit__(self, *exc):
        return False
