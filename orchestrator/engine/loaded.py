"""An SSP's FMUs extracted and loaded once, and kept loaded between co-simulations.

:class:`LoadedSystem` is what a co-simulation opens before it instantiates anything: the SSP read
(``ssd.read_ssp``), its elements checked, their FMUs extracted into a temporary folder of this
process (``tempdirs.make_folder``) and loaded by fmpy, one :class:`~orchestrator.engine.instance.Unit`
per element. A co-simulation on its own loads a system, runs, and closes it (every instance freed,
the folder removed).

:class:`LoadedFMUs` keeps systems for the next co-simulation of the same SSP content (a study
worker runs one SSP case after case): when a co-simulation ends, every instance is reset
(``fmi2Reset`` / ``fmi3Reset``), which returns it to the state right after instantiation, so
the next co-simulation applies its parameters to it exactly as to a new instance. An instance
whose reset fails (an exception, a status above Warning, or an error it logs) is freed (after
Fatal it is left alone: FMI allows no further call) and its FMU loaded again from the extracted
folder, and the next co-simulation instantiates it anew. The reset runs when a co-simulation has
ended, so no co-simulation runs on an instance whose reset failed.
Systems are keyed by the SHA-256 of the SSP file and the event mode they were instantiated in.
"""

import hashlib
import os
import shutil
import threading
import weakref
from ctypes import byref
from pathlib import Path

from fmpy import calloc, free
from fmpy.fmi2 import (fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE, fmi2CallbackFunctions,
                       fmi2CallbackLoggerTYPE)

from .archive import ExtractBudget, ExtractLimitError
from .errors import CoSimulationError
from .ssd import check_elements, extract_fmus, read_ssp
from .tempdirs import make_folder
from .instance import Unit


# fmpy's logger proxy (it formats the FMI 2.0 logger's variadic arguments, which ctypes cannot
# take) keeps one Python logger for the whole process: the last one given to addLoggerProxy. So
# every system gives it the same logger, which is never freed, and tells it apart by the
# componentEnvironment its instances pass back (a key of _SYSTEMS).
_SYSTEMS: dict = {}  # componentEnvironment -> weak reference to its LoadedSystem
_SYSTEMS_LOCK = threading.Lock()
_NEXT_ID = 0


def _dispatch(env, instance, status, category, message):
    """The FMI 2.0 logger of every system: to the system whose componentEnvironment ``env`` is; an
    FMU that passes back another pointer than it was given logs to every system that is running."""
    ref = _SYSTEMS.get(env)
    system = ref() if ref is not None else None
    if system is not None:
        system._log(env, instance, status, category, message)
        return
    for ref in list(_SYSTEMS.values()):
        system = ref()
        if system is not None and system.target is not None:
            system._log(env, instance, status, category, message)


_LOGGER = fmi2CallbackLoggerTYPE(_dispatch)
_ALLOCATE = fmi2CallbackAllocateMemoryTYPE(calloc)
_FREE = fmi2CallbackFreeMemoryTYPE(free)


class LoadedSystem:
    """The FMUs of the SSP file ``ssp_path`` extracted into a new temporary folder (:attr:`tmp`)
    and loaded, one :class:`Unit` per element (:attr:`units`, in the SSD's order; none
    instantiated yet), their sizes counted against ``budget`` (archive.ExtractBudget).

    Every FMU's log messages go to :attr:`target` (the running co-simulation's logger, called as
    ``target(env, instance, status, category, message)``; None drops them). CoSimulationError
    names the SSP and the element for an SSP or FMU that cannot be read, extracted or loaded;
    nothing is left behind then.
    """

    def __init__(self, ssp_path: Path, budget: ExtractBudget, event_mode: bool = False):
        self.ssp_path = Path(ssp_path)
        self.event_mode = event_mode
        self.target = None
        self.units: dict[str, Unit] = {}
        self.abandoned: list[Unit] = []  # instances whose reset returned Fatal (never called again)
        self.tmp = None
        try:
            self._load(budget)
        except BaseException:
            self.close()
            raise

    def _load(self, budget: ExtractBudget) -> None:
        global _NEXT_ID
        self.ssd, members = read_ssp(self.ssp_path, budget)
        self.elements = check_elements(self.ssp_path, self.ssd.system.elements, members)  # before extracting
        self.tmp = make_folder()
        weakref.finalize(self, shutil.rmtree, str(self.tmp), True)  # also if close() is never reached
        self.fmus = extract_fmus(self.ssp_path, members, self.elements, self.tmp / "ssp", budget)
        # one callback table per system: an FMI 2.0 instance may keep its pointer until it is freed
        self.callbacks = fmi2CallbackFunctions()
        self.callbacks.logger = _LOGGER
        self.callbacks.allocateMemory = _ALLOCATE
        self.callbacks.freeMemory = _FREE
        with _SYSTEMS_LOCK:
            _NEXT_ID += 1
            self._id = _NEXT_ID
            _SYSTEMS[self._id] = weakref.ref(self)
        self.callbacks.componentEnvironment = self._id  # the logger finds this system by it
        from fmpy.logging import addLoggerProxy
        addLoggerProxy(byref(self.callbacks))
        for name in self.elements:
            self.units[name] = self._unit(name, budget)

    def _unit(self, name: str, budget: ExtractBudget | None) -> Unit:
        """The Unit of element ``name``: its FMU extracted (``budget`` given) or already extracted
        (None), then loaded."""
        source = self.elements[name][0]
        try:
            return Unit(name, self.fmus[name], self.tmp / "fmu" / name, [], budget,
                        f"SSP file {self.ssp_path}: the FMU {source} of element {name}", extract=budget is not None)
        except ExtractLimitError as err:
            raise CoSimulationError(str(err), name) from None
        except Exception as err:
            raise CoSimulationError(f"SSP file {self.ssp_path}: cannot load the FMU {source} of "
                                    f"element {name} (truncated or not an FMU): {err}", name) from err

    def _log(self, env, instance, status, category, message):
        target = self.target
        if target is not None:
            target(env, instance, status, category, message)

    def log_message(self, env, instance, status, category, message):
        """The FMI 3.0 instances' logger (the same dispatch as the FMI 2.0 callback table's)."""
        self._log(env, instance, status, category, message)

    def reset(self) -> int:
        """Reset every instantiated instance (fmi2Reset / fmi3Reset) for the next co-simulation.
        An instance whose reset fails (a status above Warning or an error logged) is freed, or after
        Fatal left alone (FMI: no call is allowed after Fatal, not even freeInstance), and its FMU
        loaded again, not instantiated. Returns how many instances had to be replaced."""
        replaced = 0
        for name, unit in list(self.units.items()):
            if not unit.instantiated:  # never instantiated (its co-simulation stopped before)
                unit.prepare_reuse()
                continue
            errors = []
            self.target = lambda env, instance, status, category, message: errors.append(status >= 3)
            try:
                status = unit.reset()
            except Exception:
                status = 4  # nothing says what state the instance is in: never call it again
            self.target = None
            if status <= 1 and not any(errors):
                unit.prepare_reuse()
                continue
            replaced += 1
            if status >= 4:  # fmi2Fatal: no further call on the instance is allowed, not even freeing it
                self.abandoned.append(unit)
            else:
                try:
                    unit.slave.freeInstance()
                except Exception:
                    pass
            unit.instantiated = False
            self.units[name] = self._unit(name, None)
        return replaced

    def close(self) -> None:
        """Terminate and free every instance and delete the extracted files; idempotent."""
        self.target = None
        for unit in self.units.values():
            _free(unit)
        self.units = {}
        with _SYSTEMS_LOCK:
            _SYSTEMS.pop(getattr(self, "_id", None), None)
        if self.tmp is not None:
            shutil.rmtree(self.tmp, ignore_errors=True)
            self.tmp = None


def _free(unit: Unit) -> None:
    """Terminate and free ``unit``'s instance if it has one (an instance in error state may refuse
    to terminate; it is freed regardless)."""
    if unit.instantiated:
        try:
            unit.slave.terminate()
        except Exception:
            pass
        try:
            unit.slave.freeInstance()
        except Exception:
            pass
        unit.instantiated = False


class LoadedFMUs:
    """Loaded systems kept for the next co-simulation of the same SSP content (module docstring);
    thread-safe. ``per_key`` systems at most are kept idle per SSP content and event mode, and
    ``keys`` contents at most (the least recently used are closed first).

    :attr:`counts` says what happened: "loaded" (systems loaded), "reused" (systems taken from
    the cache), "reset" (instances reset), "replaced" (instances whose reset failed).
    """

    def __init__(self, per_key: int = 4, keys: int = 4):
        self.per_key, self.keys = per_key, keys
        self._idle: dict[tuple, list[LoadedSystem]] = {}
        self._lock = threading.Lock()
        self._hashes: dict[tuple, str] = {}
        self.closed = False
        self.counts = {"loaded": 0, "reused": 0, "reset": 0, "replaced": 0}

    def key(self, ssp_path: Path, event_mode: bool) -> tuple:
        """(SHA-256 of the SSP file's bytes, event mode); the hash is computed again whenever the
        file's size, modification time or inode changed."""
        st = os.stat(ssp_path)
        stamp = (os.path.realpath(ssp_path), st.st_size, st.st_mtime_ns, st.st_ino)
        sha = self._hashes.get(stamp)
        if sha is None:
            sha = hashlib.sha256(Path(ssp_path).read_bytes()).hexdigest()
            if len(self._hashes) >= 64:
                self._hashes.clear()
            self._hashes[stamp] = sha
        return sha, bool(event_mode)

    def take(self, ssp_path: Path, budget: ExtractBudget, event_mode: bool = False) -> LoadedSystem:
        """A loaded system of ``ssp_path``: an idle one of the same content and event mode whose
        instances were reset, else a new LoadedSystem."""
        try:
            key = self.key(ssp_path, event_mode)
        except OSError as err:
            raise CoSimulationError(f"cannot read SSP file {ssp_path}: {err.strerror or err}") from None
        with self._lock:
            idle = self._idle.get(key)
            system = idle.pop() if idle else None
            if system is not None:
                self._idle[key] = self._idle.pop(key)  # most recently used last
                self.counts["reused"] += 1
        if system is None:
            system = LoadedSystem(ssp_path, budget, event_mode)
            with self._lock:
                self.counts["loaded"] += 1
        system.ssp_path = Path(ssp_path)  # messages name the path this co-simulation was given
        system.key = key
        return system

    def give(self, system: LoadedSystem) -> None:
        """Take back ``system`` after its co-simulation: its instances reset (those that fail
        replaced) and kept for the next co-simulation of its SSP, or closed if the cache is full
        or closed. Never raises for the next co-simulation's sake (the one that ended keeps its
        outcome): a system whose FMU cannot be loaded again is closed."""
        n_reset = sum(u.instantiated for u in system.units.values())
        try:
            replaced = system.reset()
        except Exception:  # an FMU that cannot be loaded again: the next co-simulation loads them all
            system.close()
            with self._lock:
                self.counts["replaced"] += n_reset
            return
        except BaseException:
            system.close()
            raise
        surplus = []
        with self._lock:
            self.counts["reset"] += n_reset - replaced
            self.counts["replaced"] += replaced
            idle = self._idle.get(system.key, [])
            if self.closed or len(idle) >= self.per_key:
                surplus.append(system)
            else:
                self._idle.pop(system.key, None)
                self._idle[system.key] = idle + [system]  # most recently used last
            while len(self._idle) > self.keys:
                surplus += self._idle.pop(next(iter(self._idle)))
        for s in surplus:
            s.close()

    def close(self) -> None:
        """Close every idle system; a system given back later is closed too."""
        with self._lock:
            self.closed = True
            systems = [s for idle in self._idle.values() for s in idle]
            self._idle = {}
        for s in systems:
            s.close()


_PROCESS = None
_PROCESS_LOCK = threading.Lock()


def process_fmus() -> LoadedFMUs:
    """This process's LoadedFMUs (a study worker's), made on first use and closed when the
    process exits: atexit (a Dask worker process, started by spawn, exits through it), and
    multiprocessing's exit finalizers for a process it forked (which ends with os._exit,
    skipping atexit). A worker killed outright leaves its folder to tempdirs.remove_stale_folders."""
    global _PROCESS
    with _PROCESS_LOCK:
        if _PROCESS is None or _PROCESS.closed:
            import atexit
            from multiprocessing import util
            _PROCESS = LoadedFMUs()
            atexit.register(_PROCESS.close)
            util.Finalize(_PROCESS, _PROCESS.close, exitpriority=10)
        return _PROCESS


def forget_process_fmus() -> None:
    """In a process forked from one that had a LoadedFMUs: leave it to the parent, whose instances
    and folder it is (a call here would act on the parent's), and make this process's own on
    first use."""
    global _PROCESS, _PROCESS_LOCK
    _PROCESS, _PROCESS_LOCK = None, threading.Lock()  # the parent's lock may have been held at the fork


def close_process_fmus() -> None:
    """Close this process's LoadedFMUs if it has one (a study's end on a worker)."""
    with _PROCESS_LOCK:
        cache = _PROCESS
    if cache is not None:
        cache.close()
