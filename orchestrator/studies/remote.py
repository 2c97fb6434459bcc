"""A study on a Dask cluster that shares no files with the client: what travels, and the checks.

Two ways to give the workers what a case needs (orchestrator.studies.study.CaseRunner):

* **data** (the default with ``--scheduler``): the client reads the SSP and, unless the cluster
  has it already, registers a worker plugin (SspPlugin) that carries its bytes, named by their
  SHA-256 and left registered: a later study of the same SSP on the same cluster sends nothing
  (ship_ssp). The scheduler hands the plugin to every worker, also to one that joins later. Each
  study registers a small plugin of its own (StudyPlugin: the client's identity, the checks,
  the name of the SSP's plugin), removed when it ends. A worker writes the SSP once into its
  own cache (``cache_dir()/ssp/SHA256/NAME``, atomically, under a file lock, so the worker
  processes of one machine write it once) and opens it from there. A case runs in a
  worker-local temporary folder and returns its files (run.json, metrics.json, the result file
  with keep_results) compressed with zlib; the client writes them into ``OUTPUT/cases/CASE``.
* **shared** (``--shared-fs``, and the local cluster): every worker sees the client's files at the
  same paths; the SSP travels as its path and each case writes its own folder. Worth it only for
  studies that keep large result files on a cluster with a shared file system.

In both, a scenario's gain preset file (gains_file) is read by the client and sent as values
(gain_values_of), so a worker never opens a path the client gave it (except the SSP in shared mode).

Before the first case a remote study waits for a worker (wait_for_workers, one line if none comes)
and checks every worker (worker_problem: its tapmp version, the content of its installed package
and C model, that it can load or build the C model in a cache it may trust, and in data mode
write the SSP into that cache). A worker that fails is retired from the study (Dask's
retire_workers: it closes, with its nanny, so no case is ever sent to it) with one warning naming
it and the reason; its cases run on the other workers. A worker that joins later is checked by
the study's plugin when it joins, before it takes a case (StudyPlugin.setup: Dask sets up a
joining worker's plugins before it reads the scheduler's tasks); if it fails, it asks the
scheduler to retire it and any case that reached it meanwhile goes back to the scheduler (Dask's
Reschedule). A worker plugin cannot refuse to start a worker (Dask logs its setup's error and
runs the worker anyway), hence retiring.
"""

import asyncio
import dataclasses
import functools
import hashlib
import os
import shutil
import tempfile
import zlib
from contextlib import contextmanager
from importlib import metadata
from pathlib import Path

from distributed.diagnostics.plugin import WorkerPlugin

from .study_file import StudyError

PLUGIN_PREFIX = "tapmp-study-"
ZLIB_LEVEL = 6  # zlib's default: a 0.5 s case's run.json + metrics.json shrink about 4x


PACKAGES = ("ctoolchain", "tapmp", "orchestrator", "fmu_common", "fmu_plant", "fmu_controller")  # tapmp-cosim's code
SOURCE_SUFFIXES = (".py", ".c", ".h", ".toml")  # the files of PACKAGES that make what a worker runs


@functools.cache
def package_hash() -> str:
    """16 hex digits of a SHA-256 over the source files (SOURCE_SUFFIXES) of the installed
    PACKAGES, each by its path in its package and its content: two installations that differ in
    one byte of them differ here, whatever their version says."""
    # PACKAGES sit beside this package (site-packages or the checkout), found from this file, not by
    # import: a pythonfmu FMU run in the process puts its resources, a partial copy of fmu_common, on
    # sys.path
    top = Path(__file__).resolve().parents[2]
    digest = hashlib.sha256()
    for package in PACKAGES:
        root = top / package
        files = sorted(p for p in root.rglob("*") if p.suffix in SOURCE_SUFFIXES
                       and "__pycache__" not in p.parts and p.is_file())
        for path in files:
            digest.update(f"{package}/{path.relative_to(root).as_posix()}\0".encode())
            digest.update(hashlib.sha256(path.read_bytes()).digest())
    return digest.hexdigest()[:16]


def identity() -> dict:
    """What a worker must share with the client: the installed tapmp-cosim version, the hash of
    its package's source files (package_hash) and of the model's C sources
    (tapmp.cmodel.source_hash), with the process's host and pid."""
    from tapmp.cmodel import source_hash
    try:
        version = metadata.version("tapmp-cosim")
    except metadata.PackageNotFoundError:
        version = "not installed"
    return {"tapmp": version, "package": package_hash(), "model": source_hash(), "host": os.uname().nodename,
            "pid": os.getpid()}


IDENTITY_KEYS = ("tapmp", "package", "model")  # what must be equal


def describe(ident: dict) -> str:
    """An identity as text: "tapmp-cosim VERSION, package sources HASH, model sources HASH"."""
    return f"tapmp-cosim {ident['tapmp']}, package sources {ident['package']}, model sources {ident['model']}"


def mismatch(worker: str, theirs: dict, ours: dict) -> str | None:
    """The one-line refusal of a worker whose identity differs from the client's, else None."""
    if all(theirs.get(k) == ours.get(k) for k in IDENTITY_KEYS):
        return None
    return (f"Dask worker {worker} ({theirs['host']}) runs {describe(theirs)}, this client {describe(ours)}: "
            "install the same tapmp-cosim on every worker (pip install the wheel the client uses)")


def worker_problem(worker: str, client_identity: dict, ssp=None) -> str | None:
    """Why this process (the Dask worker ``worker``) cannot run the study's cases, in one line, or
    None: its identity differs from the client's (mismatch); it cannot load the C model, which
    is compiled on first use into the cache (tapmp.cmodel.library_path: no toolchain such as the
    ziglang package, or a cache another user could write); or ``ssp()``, writing the study's
    SSP into its cache (data mode), fails."""
    from tapmp.cmodel import CModelError, load
    from ctoolchain import CacheTrustError
    text = mismatch(worker, identity(), client_identity)
    if text:
        return text
    try:
        load()
        if ssp is not None:
            ssp()
    except StudyError as err:
        return str(err)
    except (CModelError, CacheTrustError, OSError) as err:
        return f"Dask worker {worker} ({os.uname().nodename}) cannot run the cases: {' '.join(str(err).split())}"
    return None


def wait_for_workers(client, timeout: float, address: str) -> None:
    """Return once at least one worker is connected; StudyError after ``timeout`` [s] without one."""
    try:
        client.wait_for_workers(1, timeout=timeout)
    except TimeoutError:
        raise StudyError(f"no Dask worker joined the scheduler at {address} within {timeout:g} s: start workers "
                         f"with `dask worker {address} --nthreads 1` (one per core), or wait longer with "
                         "--worker-timeout") from None


def reaches_workers(client, timeout: float = 5.0) -> bool:
    """Whether this client can open a connection to a connected worker's address within
    ``timeout`` [s] (else results travel through the scheduler)."""
    from distributed.comm import connect
    workers = list(client.scheduler_info().get("workers", {}))
    if not workers:
        return False

    async def probe():
        comm = await connect(workers[0], timeout=timeout)
        await comm.close()
    try:
        client.sync(probe)
    except Exception:  # refused, unreachable, timed out: through the scheduler then
        return False
    return True


async def _problem_here(plugin: "StudyPlugin", dask_worker=None) -> str | None:
    """StudyPlugin.problem on this worker, in a thread (it may compile the C model, and the
    worker's event loop must keep answering the scheduler meanwhile)."""
    plugin.worker = str(dask_worker.address)
    plugin.plugins = dask_worker.plugins  # the check runs in a thread, where get_worker finds none
    return await asyncio.get_running_loop().run_in_executor(None, plugin.problem)


def check_workers(client, plugin: "StudyPlugin") -> int:
    """Check every connected worker (StudyPlugin.problem). Those that fail are retired from the
    study (retire_workers: closed) with one warning each naming the worker and its reason;
    StudyError with the first reason if every worker fails. Returns the number of good workers."""
    found = client.run(_problem_here, plugin, on_error="return")
    problems = {}
    for worker, text in sorted(found.items()):
        if isinstance(text, BaseException):
            text = f"Dask worker {worker} cannot run tapmp: {type(text).__name__}: {' '.join(str(text).split())}"
        if text:
            problems[worker] = text
    if problems and len(problems) == len(found):
        raise StudyError(next(iter(problems.values())))
    for text in problems.values():
        retired_warning(text)
    if problems:
        client.retire_workers(list(problems), close_workers=True)
    return len(found) - len(problems)


def retired_warning(text: str) -> None:
    """The one warning line of a worker retired from the study, with the reason ``text``."""
    import sys
    print(f"warning: {text}; this worker is retired from the study, its cases run on the others", file=sys.stderr)


class SspPlugin(WorkerPlugin):
    """An SSP's bytes (``data``, named ``name``, with its SHA-256 ``sha256``) on every worker of a
    cluster: registered once per cluster under ssp_plugin_name (its hash), so that every later
    study of the same SSP finds it there and sends nothing again; the scheduler gives it to
    workers that join later too. A worker writes the bytes into its SSP cache on first use
    (ssp_path). ``nonce``: made when the client built it (a test sees whether it was sent again)."""

    idempotent = True  # registered again with the same name: the same bytes

    def __init__(self, name: str, data: bytes):
        self.name = name
        self.data = data
        self.sha256 = hashlib.sha256(data).hexdigest()
        self.nonce = os.urandom(8).hex()
        self._path = None

    def ssp_path(self, worker: str = "") -> Path:
        """The SSP in this worker's cache, written there on first use (see cached_ssp)."""
        if self._path is None:
            self._path = cached_ssp(self.sha256, self.name, self.data, worker)
        return self._path


def ssp_plugin_name(sha256: str) -> str:
    """The name of the SspPlugin of the SSP whose SHA-256 is ``sha256`` (the same on every study)."""
    return f"{PLUGIN_PREFIX}ssp-{sha256}"


class StudyPlugin(WorkerPlugin):
    """What every worker of one remote study gets: the client's identity, and in data mode the
    name of the SspPlugin holding its SSP (``ssp_name``). Registered by the client under a name
    of its own for the study (shipping); the scheduler gives it to workers that join later too."""

    idempotent = True  # registered again with the same name: the same study

    def __init__(self, client_identity: dict, ssp_name: str = ""):
        self.client_identity = client_identity
        self.ssp_name = ssp_name
        self.worker = ""
        self.topic = ""  # the plugin's name, under which a worker that fails the check says so (log_event)
        self.failed = None  # on a worker: why it failed the check (setup), else None
        self.plugins = None  # on a worker: its plugins by name (set by the check)

    async def setup(self, worker) -> None:
        """Check this worker (problem); if it fails, say so under ``topic`` (the client prints it)
        and ask the scheduler to retire it, without waiting (a joining worker is being set up)."""
        self.failed = await _problem_here(self, worker)
        if self.failed:
            worker.log_event(self.topic, {"worker": self.worker, "problem": self.failed})
            self._retiring = asyncio.ensure_future(_retire(worker))  # kept: the loop holds tasks weakly

    def problem(self) -> str | None:
        """worker_problem of this worker against the client's identity (and its SSP cache, in data mode)."""
        return worker_problem(self.worker, self.client_identity, self.ssp_path if self.ssp_name else None)

    def teardown(self, worker) -> None:
        """The study ended (or the worker closes): free the FMUs its cases kept loaded in this worker
        and remove their folder (engine.loaded.process_fmus)."""
        from ..engine.loaded import close_process_fmus
        close_process_fmus()

    def ssp_path(self) -> Path:
        """The study's SSP in this worker's cache (its SspPlugin's ssp_path); StudyError if this
        worker has not received it."""
        shipped = self.plugins.get(self.ssp_name) if self.plugins is not None else this_plugin(self.ssp_name)
        if shipped is None:
            raise StudyError(f"Dask worker {self.worker or os.uname().nodename} has not received the study's SSP "
                             f"(plugin {self.ssp_name}): it is not a worker of this study's scheduler")
        return shipped.ssp_path(self.worker)


async def _retire(worker) -> None:
    """Ask the scheduler to retire ``worker`` (it closes, with its nanny)."""
    try:
        await worker.scheduler.retire_workers(workers=[worker.address], close_workers=True,
                                              stimulus_id=f"tapmp-study-check-{os.urandom(4).hex()}")
    except Exception:  # the scheduler is gone: the worker goes with it
        pass


def retired_since(client, topic: str, seen: int) -> int:
    """Print the warning of each worker retired by its own check (StudyPlugin.setup) under ``topic``
    since the first ``seen`` ones; returns how many there are now."""
    events = client.get_events(topic)
    for _, msg in events[seen:]:
        retired_warning(msg["problem"])
    return len(events)


def cached_ssp(sha256: str, name: str, data: bytes, worker: str = "") -> Path:
    """``cache_dir()/ssp/SHA256/NAME`` holding ``data``: written once (to a temporary file in the
    same folder, then renamed, under a file lock so that the worker processes of a machine do not
    write it twice); a file already there is used only if its SHA-256 matches. The folder and the
    file are under the compiled-code cache's rule (ctoolchain.private_folder and
    check_private_file: this user's, writable by no one else, no symbolic link), as the FMUs'
    binaries are loaded from the SSP. StudyError naming the worker and the folder if the cache
    cannot be written or is not trusted."""
    from filelock import FileLock

    from ctoolchain import CacheTrustError, cache_dir, check_private_file, private_folder
    folder = cache_dir() / "ssp" / sha256
    try:
        folder = private_folder(folder)
        path = folder / name
        with FileLock(str(folder / ".lock")):
            if os.path.lexists(path):
                check_private_file(path)
            if not (path.is_file() and hashlib.sha256(path.read_bytes()).hexdigest() == sha256):
                fd, tmp = tempfile.mkstemp(dir=folder, prefix=f".{name}.", suffix=".tmp")
                try:
                    with os.fdopen(fd, "wb") as f:
                        f.write(data)
                    os.replace(tmp, path)
                finally:
                    Path(tmp).unlink(missing_ok=True)
    except CacheTrustError as err:
        raise StudyError(f"Dask worker {worker or os.uname().nodename} does not trust its SSP cache: {err}") from None
    except OSError as err:
        raise StudyError(f"Dask worker {worker or os.uname().nodename} cannot write the study's SSP into its "
                         f"cache {folder}: {err.strerror or err} (set TAPMP_CACHE to a writable folder on "
                         "the worker)") from None
    return path


def ship_ssp(client, ssp: Path) -> tuple[str, bool]:
    """Make sure the cluster of ``client`` holds the SSP ``ssp``: its SspPlugin is registered
    unless the scheduler has one of that name (the same bytes) already. Returns the plugin's
    name and whether its bytes were sent now."""
    data = Path(ssp).read_bytes()
    name = ssp_plugin_name(hashlib.sha256(data).hexdigest())
    if client.run_on_scheduler(_has_worker_plugin, name):
        return name, False
    client.register_plugin(SspPlugin(Path(ssp).name, data), name=name)
    return name, True


def _has_worker_plugin(name: str, dask_scheduler=None) -> bool:
    """On the scheduler: whether a worker plugin ``name`` is registered."""
    return name in dask_scheduler.worker_plugins


def this_plugin(name: str) -> StudyPlugin | None:
    """The study plugin ``name`` on the worker running this task (None outside a worker)."""
    from distributed import get_worker
    try:
        worker = get_worker()
    except ValueError:
        return None
    return worker.plugins.get(name)


def gain_values_of(paths) -> dict:
    """{path: the preset of load_gain_file, or the error text} for each gain preset file path,
    read here (on the client) so that workers get values, not paths."""
    from ..tool.scenario import ScenarioError, load_gain_file
    out = {}
    for path in paths:
        if path and path not in out:
            try:
                out[path] = load_gain_file(path)
            except ScenarioError as err:
                out[path] = str(err)
    return out


def pack_folder(folder: Path) -> dict:
    """{file name: zlib-compressed bytes} of every file a case wrote into ``folder`` (its lock file
    aside), to send to the client."""
    from ..tool.folders import LOCK_FILE
    folder = Path(folder)
    if not folder.is_dir():
        return {}
    return {p.name: zlib.compress(p.read_bytes(), ZLIB_LEVEL) for p in sorted(folder.iterdir())
            if p.is_file() and p.name != LOCK_FILE}


def inflate(files: dict, limit: int) -> dict:
    """{name: bytes} of pack_folder's {name: zlib bytes}; StudyError if they hold more than
    ``limit`` bytes together, found without inflating more than ``limit`` + 1 of them (a small
    message from a worker may expand a thousandfold)."""
    out, total = {}, 0
    for name, blob in files.items():
        inflater = zlib.decompressobj()
        try:
            data = inflater.decompress(blob, limit - total + 1)
        except zlib.error as err:
            raise StudyError(f"the case's file {name} from the worker is not zlib data ({err})") from None
        total += len(data)
        if total > limit or inflater.unconsumed_tail:
            raise StudyError(f"the case's files from the worker hold more than {limit} bytes uncompressed "
                             f"(at {name}), more than the run can write: refused, nothing written")
        if not inflater.eof:
            raise StudyError(f"the case's file {name} from the worker is cut (its zlib data ends early)")
        out[name] = data
    return out


def unpack_folder(files: dict, folder: Path, ssp: str, limit: int) -> int:
    """Write a case's files (from pack_folder) into its folder ``folder`` on the client, as a local
    study leaves them: the folder locked while written, its old run files removed, each file
    written atomically, run.json naming the client's SSP path ``ssp`` (the worker ran the same
    bytes from its cache). StudyError, with nothing written, if they hold more than ``limit``
    bytes uncompressed (inflate). Returns the bytes received (compressed)."""
    import json

    from ..tool.folders import atomic_file, output_lock, prepare_output
    if not files:
        return 0
    inflated = inflate(files, limit)
    with output_lock(folder):
        prepare_output(folder, True)
        for name, data in inflated.items():
            if name == "run.json":
                info = json.loads(data)
                info["ssp"] = ssp
                data = (json.dumps(info, indent=2, default=str) + "\n").encode()
            with atomic_file(folder / Path(name).name, "wb") as f:
                f.write(data)
    return sum(len(b) for b in files.values())


def case_folder() -> Path:
    """A new worker-local temporary folder for one case (removed by remove_case_folder)."""
    return Path(tempfile.mkdtemp(prefix="tapmp_case_"))


def remove_case_folder(folder: Path) -> None:
    shutil.rmtree(folder, ignore_errors=True)


@dataclasses.dataclass
class Shipping:
    """How a study's cases reach its workers: ``plugin``, the name of the study's worker plugin
    ("" on the local cluster: no check, no data); ``data``: the SSP and the case files travel as
    data (else as paths on a shared file system); ``address``: the scheduler's, for messages."""

    plugin: str = ""
    data: bool = False
    address: str = ""
    ssp_sent: bool = False  # data mode: the SSP's bytes were sent to the cluster for this study (else it had them)


@contextmanager
def shipping(client, ssp: Path, address: str, data: bool, timeout: float):
    """For the duration of a study on the scheduler at ``address``: at least one worker (waited
    for up to ``timeout`` [s]), every worker checked against the client, and the study's plugin
    registered (with the SSP's bytes if ``data``) and removed at the end. Yields the
    Shipping the CaseRunner uses."""
    wait_for_workers(client, timeout, address)
    # rows straight from the worker that holds them, if this client reaches the workers (not behind a port forward)
    client.direct_to_workers = reaches_workers(client)
    ssp_name, sent = ship_ssp(client, ssp) if data else ("", False)  # once per cluster (its name is its hash)
    plugin = StudyPlugin(identity(), ssp_name)
    name = f"{PLUGIN_PREFIX}study-{os.urandom(6).hex()}"  # one per study run
    plugin.topic = name
    check_workers(client, plugin)  # the bad ones retired before the plugin (and cases) reach any worker
    client.register_plugin(plugin, name=name)
    try:
        yield Shipping(plugin=name, data=data, address=address, ssp_sent=sent)
    finally:
        try:
            client.unregister_worker_plugin(name)
        except Exception:
            pass  # the scheduler is gone: nothing left to remove
