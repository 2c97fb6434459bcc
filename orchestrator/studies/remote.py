"""A study on a Dask cluster that shares no files with the client: what travels, and the checks.

Two ways to give the workers what a case needs (orchestrator.studies.study.CaseRunner):

* **data** (the default with ``--scheduler``): the client reads the SSP once and registers a
  worker plugin (StudyPlugin) that carries its bytes, keyed by their SHA-256; the scheduler hands
  the plugin to every worker, also to one that joins later. A worker writes the SSP once into its
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
and compares every worker's tapmp version and model source hash with the client's
(check_workers); a worker that joins later is checked by the plugin before each case.
"""

import dataclasses
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


def identity() -> dict:
    """What a worker must share with the client: the installed tapmp-cosim version and the hash of
    the model's C sources (tapmp.cmodel.source_hash), with the process's host and pid."""
    from tapmp.cmodel import source_hash
    try:
        version = metadata.version("tapmp-cosim")
    except metadata.PackageNotFoundError:
        version = "not installed"
    return {"tapmp": version, "model": source_hash(), "host": os.uname().nodename, "pid": os.getpid()}


def describe(ident: dict) -> str:
    """An identity as text: "tapmp-cosim VERSION, model sources HASH"."""
    return f"tapmp-cosim {ident['tapmp']}, model sources {ident['model']}"


def mismatch(worker: str, theirs: dict, ours: dict) -> str | None:
    """The one-line refusal of a worker whose identity differs from the client's, else None."""
    if (theirs["tapmp"], theirs["model"]) == (ours["tapmp"], ours["model"]):
        return None
    return (f"Dask worker {worker} ({theirs['host']}) runs {describe(theirs)}, this client {describe(ours)}: "
            "install the same tapmp-cosim on every worker (pip install the wheel the client uses)")


def wait_for_workers(client, timeout: float, address: str) -> None:
    """Return once at least one worker is connected; StudyError after ``timeout`` [s] without one."""
    try:
        client.wait_for_workers(1, timeout=timeout)
    except TimeoutError:
        raise StudyError(f"no Dask worker joined the scheduler at {address} within {timeout:g} s: start workers "
                         f"with `dask worker {address} --nthreads 1` (one per core), or wait longer with "
                         "--worker-timeout") from None


def check_workers(client) -> int:
    """Compare every connected worker's identity with the client's; StudyError naming the first
    worker that differs (and both versions). Returns the number of workers checked."""
    ours = identity()
    found = client.run(identity, on_error="return")
    for worker, theirs in sorted(found.items()):
        if isinstance(theirs, BaseException):
            raise StudyError(f"Dask worker {worker} cannot run tapmp: {type(theirs).__name__}: {theirs}")
        text = mismatch(worker, theirs, ours)
        if text:
            raise StudyError(text)
    return len(found)


class StudyPlugin(WorkerPlugin):
    """What every worker of a remote study gets: the client's identity, and in data mode the SSP's
    bytes (``data``, named ``name``, with its SHA-256 ``sha256``). Registered by the client under a
    name of its own (shipping); the scheduler gives it to workers that join later too."""

    idempotent = True  # registered again with the same name: the same study data

    def __init__(self, client_identity: dict, name: str = "", data: bytes | None = None):
        self.client_identity = client_identity
        self.name = name
        self.data = data
        self.sha256 = hashlib.sha256(data).hexdigest() if data is not None else ""
        self.worker = ""
        self._path = None

    def setup(self, worker) -> None:
        self.worker = str(worker.address)

    def teardown(self, worker) -> None:
        """The study ended (or the worker closes): free the FMUs its cases kept loaded in this worker
        and remove their folder (engine.loaded.process_fmus)."""
        from ..engine.loaded import close_process_fmus
        close_process_fmus()

    def check(self) -> None:
        """StudyError (naming this worker and both versions) if this worker differs from the client."""
        text = mismatch(self.worker, identity(), self.client_identity)
        if text:
            raise StudyError(text)

    def ssp_path(self) -> Path:
        """The SSP in this worker's cache, written there on first use (see cached_ssp)."""
        if self._path is None:
            self._path = cached_ssp(self.sha256, self.name, self.data, self.worker)
        return self._path


def cached_ssp(sha256: str, name: str, data: bytes, worker: str = "") -> Path:
    """``cache_dir()/ssp/SHA256/NAME`` holding ``data``: written once (to a temporary file in the
    same folder, then renamed, under a file lock so that the worker processes of a machine do not
    write it twice); a file already there is used only if its SHA-256 matches. StudyError naming
    the worker and the folder if the cache cannot be written."""
    from filelock import FileLock

    from tapmp.toolchain import cache_dir
    folder = cache_dir() / "ssp" / sha256
    path = folder / name
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with FileLock(str(folder / ".lock")):
            if not (path.is_file() and hashlib.sha256(path.read_bytes()).hexdigest() == sha256):
                fd, tmp = tempfile.mkstemp(dir=folder, prefix=f".{name}.", suffix=".tmp")
                try:
                    with os.fdopen(fd, "wb") as f:
                        f.write(data)
                    os.replace(tmp, path)
                finally:
                    Path(tmp).unlink(missing_ok=True)
    except OSError as err:
        raise StudyError(f"Dask worker {worker or os.uname().nodename} cannot write the study's SSP into its "
                         f"cache {folder}: {err.strerror or err} (set TAPMP_CACHE to a writable folder on "
                         "the worker)") from None
    return path


def study_plugin(ssp: Path | None) -> StudyPlugin:
    """The plugin of a remote study: the client's identity and, for data mode (``ssp`` given), the
    SSP's bytes read once here."""
    if ssp is None:
        return StudyPlugin(identity())
    return StudyPlugin(identity(), Path(ssp).name, Path(ssp).read_bytes())


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


def unpack_folder(files: dict, folder: Path, ssp: str) -> int:
    """Write a case's files (from pack_folder) into its folder ``folder`` on the client, as a local
    study leaves them: the folder locked while written, its old run files removed, each file
    written atomically, run.json naming the client's SSP path ``ssp`` (the worker ran the same
    bytes from its cache). Returns the bytes received (compressed)."""
    import json

    from ..tool.folders import atomic_file, output_lock, prepare_output
    if not files:
        return 0
    with output_lock(folder):
        prepare_output(folder, True)
        for name, blob in files.items():
            data = zlib.decompress(blob)
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


@contextmanager
def shipping(client, ssp: Path, address: str, data: bool, timeout: float):
    """For the duration of a study on the scheduler at ``address``: at least one worker (waited
    for up to ``timeout`` [s]), every worker checked against the client, and the study's plugin
    registered (with the SSP's bytes if ``data``) and removed at the end. Yields the
    Shipping the CaseRunner uses."""
    wait_for_workers(client, timeout, address)
    check_workers(client)
    plugin = study_plugin(ssp if data else None)
    name = f"{PLUGIN_PREFIX}{plugin.sha256[:12] or 'paths'}-{os.urandom(4).hex()}"  # one per study run
    client.register_plugin(plugin, name=name)
    try:
        yield Shipping(plugin=name, data=data, address=address)
    finally:
        try:
            client.unregister_worker_plugin(name)
        except Exception:
            pass  # the scheduler is gone: nothing left to remove
