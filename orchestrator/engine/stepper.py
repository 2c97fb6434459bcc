"""The compiled stepping core: the master's macro-step loop in C (``stepper.c``).

fmpy reads the modelDescriptions, loads the binaries, instantiates, initializes and
terminates; :class:`CompiledStepper` then steps the instances from C through the FMI
function pointers of the libraries fmpy loaded, a block of steps per call, and returns to
Python after every block (progress, stop requests, recording) and at the first failed call
or suspect output, which the master reports with the same error as its Python loop
(``CoSimulation.step``). The rows are the Python loop's to the bit
(tests/engine/test_stepper.py), in FMI 3.0 Event Mode too (the event units' state, their
nextEventTime, clock tick index and events handled, is handed over at every call:
tests/engine/master/test_stepper_events.py).

A binary wheel ships the core compiled for its platform beside stepper.c (setup.py); else the
C file is compiled on first use (or by ``tapmp build``) into a cache folder outside
the package: ``$TAPMP_CACHE``, else ``$XDG_CACHE_HOME/tapmp``, else ``~/.cache/tapmp``,
named after a hash of the source and the compiler command, under a file lock so that
concurrent processes build it once. If it cannot be built, the master says so in one line
on stderr and steps in Python. A cache folder or library another user could have written is
refused before anything is loaded (ctoolchain.CacheTrustError, not a fallback: the run
stops with one line naming the path). ``TAPMP_STEPPER=python`` selects the Python loop.

A paced (real-time) run is one call, ``tapmp_advance_paced``, on a thread of its own without the GIL:
each step kept to the wall clock, the rows into a ring of blocks that the caller reads meanwhile
(orchestrator.engine.pacing).
"""

import ctypes
import hashlib
import sys
from ctypes import POINTER, Structure, c_double, c_int32, c_int64, c_void_p
from pathlib import Path

SOURCE = Path(__file__).with_name("stepper.c")
STEPPERS = ("auto", "compiled", "python")
# No -ffast-math, no contraction: the core only copies and compares doubles, and must keep them.
CFLAGS = ["-O2", "-std=c99", "-ffp-contract=off", "-Wall"]  # exported for ctypes: no hidden visibility

DONE, FAIL_CALL, SUSPECT_OUTPUT, FAIL_EVENT, EARLY_RETURN, NOT_SETTLED, OVERRUN, STOPPED = 0, 1, 2, 3, 4, 5, 6, 7
CALLS = ("setReal", "doStep", "getReal")
# FAIL_EVENT: the call as CoSimulation._handle_events names it, and fmpy's name of the function that
# raises FMICallException above Warning (None: a direct ctypes call whose status the master words)
EVENT_CALLS = (("enterEventMode", "fmi3EnterEventMode"), ("setClock", "fmi3SetClock"), ("setFloat64", None),
               ("updateDiscreteStates", "fmi3UpdateDiscreteStates"), ("getFloat64", None),
               ("enterStepMode", "fmi3EnterStepMode"))
CLOCK_KINDS = {"exact": 0, "accumulated": 1, "nanoseconds": 2}


class StepperBuildError(RuntimeError):
    """The compiled stepping core cannot be built or loaded; the message says why."""


def compiler_command(source: Path, output: Path) -> list[str]:
    """The compiler and flags that build the core (the project's toolchain: $CC if set, else
    zig cc from the ziglang package; ctoolchain); part of the cache key."""
    from ctoolchain import compiler
    return [*compiler(), *CFLAGS, "-shared", "-fPIC", "-o", str(output), str(source), "-lm"]


def compile_core(source: Path, output: Path) -> Path:
    """Compile the stepping core ``source`` into ``output`` with the project's toolchain;
    StepperBuildError with the compiler's first error line if it fails."""
    from ctoolchain import ToolchainError, compile_c
    try:
        return compile_c([source], output, flags=CFLAGS, libs=("m",), what="the compiled stepping core")
    except ToolchainError as err:
        raise StepperBuildError(str(err)) from None


def library_path() -> Path:
    """Where the compiled core of this source and compiler command lives in the cache."""
    from ctoolchain import cache_dir  # on first use: importing the master loads no tapmp module
    key = hashlib.sha256(SOURCE.read_bytes() + "\0".join(compiler_command(SOURCE, Path("x"))).encode())
    return cache_dir() / f"tapmp_stepper_{key.hexdigest()[:16]}.so"


def build() -> Path:
    """The core shipped in a binary wheel for this platform (ctoolchain.prebuilt), else the cache's,
    built unless it is there; returns its path. A file lock makes concurrent builds (a study's
    workers) wait for the first one."""
    from ctoolchain import build_cached
    from ctoolchain.prebuilt import digest, find_prebuilt
    shipped = find_prebuilt(SOURCE.parent, "tapmp_stepper", digest([SOURCE], CFLAGS))
    if shipped:
        return shipped
    path = library_path()
    try:
        return build_cached(path, lambda tmp: compile_core(SOURCE, tmp))
    except OSError as err:
        raise StepperBuildError(f"cannot write the compiled core into {path.parent}: "
                                f"{err.strerror or err} (set TAPMP_CACHE to a writable folder)") from None


_LIB = None
_NOTE_GIVEN = False


def load():
    """The loaded core (ctypes.CDLL), built on first use; StepperBuildError if impossible."""
    global _LIB
    if _LIB is None:
        path = build()
        try:
            lib = ctypes.CDLL(str(path))
            lib.tapmp_advance
        except (OSError, AttributeError) as err:
            raise StepperBuildError(f"cannot load {path}: {' '.join(str(err).split())} (delete the file so that it "
                                    "is compiled again)") from None
        lib.tapmp_advance.restype = c_int32
        lib.tapmp_advance.argtypes = [POINTER(_Plan), POINTER(_State), c_int64, c_void_p, c_int32]
        lib.tapmp_advance_paced.restype = c_int32
        lib.tapmp_advance_paced.argtypes = [POINTER(_Plan), POINTER(_State), c_int64, c_void_p, c_int32, c_int64,
                                            c_int32, c_void_p, c_void_p]
        _LIB = lib
    return _LIB


def available(quiet: bool = False) -> bool:
    """Whether the compiled core can be used; if not, say why once on stderr (unless quiet).
    CacheTrustError (a cache another user could write) is raised, never taken as a reason to
    step in Python: the same cache holds the C model every run loads."""
    global _NOTE_GIVEN
    try:
        load()
        return True
    except (StepperBuildError, OSError) as err:
        if not quiet and not _NOTE_GIVEN:
            _NOTE_GIVEN = True
            print(f"note: compiled stepping core unavailable ({err}); stepping in Python", file=sys.stderr)
        return False


class _UnitC(Structure):
    _fields_ = [("instance", c_void_p), ("get", c_void_p), ("set", c_void_p), ("step", c_void_p),
                ("fmi3", c_int32), ("n_out", c_int32), ("n_in", c_int32),
                ("out_vrs", c_void_p), ("out", c_void_p), ("in_vrs", c_void_p), ("inp", c_void_p),
                ("src", c_void_p),
                ("event_needed", c_void_p), ("terminate", c_void_p), ("early", c_void_p), ("last_time", c_void_p),
                ("enter_event", c_void_p), ("set_clock", c_void_p), ("update", c_void_p), ("enter_step", c_void_p),
                ("next_event", c_double), ("clock_k", c_int64), ("n_events", c_int64), ("n_clocks", c_int32),
                ("clock_vrs", c_void_p), ("clock_on", c_void_p), ("clock_t0", c_double),
                ("clock_interval", c_double)]


class _Plan(Structure):
    _fields_ = [("units", c_void_p), ("n_units", c_int32), ("jacobi", c_int32), ("step_order", c_void_p),
                ("clock", c_int32), ("t0", c_double), ("h", c_double), ("t0_ns", c_int64), ("h_ns", c_int64),
                ("n_env", c_int32), ("env_unit", c_void_p), ("env_index", c_void_p), ("env_limit", c_void_p),
                ("log_count", c_void_p), ("log_errors", c_void_p),
                ("event_mode", c_int32), ("n_event", c_int32), ("event_order", c_void_p),
                ("pace", c_void_p)]  # engine.pacing.Pace, or None


class _State(Structure):
    _fields_ = [("k", c_int64), ("acc_t", c_double), ("rows", c_int64), ("outcome", c_int32),
                ("unit", c_int32), ("call", c_int32), ("status", c_int32), ("n_log", c_int64),
                ("t", c_double), ("mid", c_int32), ("early", c_double), ("target", c_double)]


def _addr(obj) -> int:
    return ctypes.addressof(obj)


class CompiledStepper:
    """The C loop bound to the units of one opened CoSimulation (``sim``): ``units`` in row
    order, ``step_order`` their indices in step order, ``envelope`` the bounds of the master's
    OutputCheck as (unit, output index, limit), the logger's counters ``log_count`` and
    ``log_errors`` (c_int64); ``event_units``: the units in Event Mode in step order (empty
    without event mode), whose macro steps are cut at their events."""

    def __init__(self, units, step_order, jacobi: bool, clock, envelope, log_count, log_errors,
                 event_units=(), event_mode: bool = False):
        self.lib = load()
        self._keep = []  # every ctypes object the C side points into
        index = {id(u): i for i, u in enumerate(units)}
        cunits = (_UnitC * len(units))()
        for i, u in enumerate(units):
            dll = u.slave.dll
            names = (("fmi3GetFloat64", "fmi3SetFloat64", "fmi3DoStep") if u.fmi3
                     else ("fmi2GetReal", "fmi2SetReal", "fmi2DoStep"))
            get, set_, step = (ctypes.cast(getattr(dll, n), c_void_p).value for n in names)
            src = (c_void_p * max(u.n_in, 1))(*(_addr(s.out) + j * 8 for s, j, _ in u.sources))
            self._keep.append(src)
            cunits[i] = _UnitC(u.slave.component, get, set_, step, int(u.fmi3), u.n_out, u.n_in,
                               _addr(u.out_vrs), _addr(u.out), _addr(u.in_vrs) if u.n_in else None,
                               _addr(u.inp) if u.n_in else None, _addr(src))
            if u.fmi3:  # doStep writes into the Unit's own flags: the Python loop reads them on
                c = cunits[i]
                c.event_needed, c.terminate, c.early = (_addr(f) for f in u._flags)
                c.last_time = _addr(u._last_time)
            if u.event_mode:
                c = cunits[i]
                c.enter_event, c.set_clock, c.update, c.enter_step = (
                    ctypes.cast(getattr(dll, n), c_void_p).value for n in
                    ("fmi3EnterEventMode", "fmi3SetClock", "fmi3UpdateDiscreteStates", "fmi3EnterStepMode"))
                n_clocks = len(u.clock_vrs)
                vrs, on = (ctypes.c_uint32 * max(n_clocks, 1))(*u.clock_vrs), (ctypes.c_bool * max(n_clocks, 1))()
                for j in range(n_clocks):
                    on[j] = True
                self._keep += [vrs, on]
                c.n_clocks, c.clock_vrs, c.clock_on = n_clocks, _addr(vrs), _addr(on)
                c.clock_t0, c.clock_interval = u.clock_t0, u.clock_interval
        order = (c_int32 * len(step_order))(*(index[id(u)] for u in step_order))
        env_unit = (c_int32 * max(len(envelope), 1))(*(index[id(u)] for u, _, _ in envelope))
        env_index = (c_int32 * max(len(envelope), 1))(*(i for _, i, _ in envelope))
        env_limit = (c_double * max(len(envelope), 1))(*(lim for _, _, lim in envelope))
        events = (c_int32 * max(len(event_units), 1))(*(index[id(u)] for u in event_units))
        self._keep += [cunits, order, env_unit, env_index, env_limit, log_count, log_errors, events]
        self.units, self.cunits = units, cunits
        self.event_units = [(index[id(u)], u) for u in event_units]
        ns = clock.kind == "nanoseconds"
        self.plan = _Plan(_addr(cunits), len(units), int(jacobi), _addr(order), CLOCK_KINDS[clock.kind],
                          clock.t0, clock.h, clock._t0_ns if ns else 0, clock._h_ns if ns else 0,
                          len(envelope), _addr(env_unit), _addr(env_index), _addr(env_limit),
                          _addr(log_count), _addr(log_errors), int(event_mode), len(event_units), _addr(events))
        self.state = _State()
        self.clock = clock

    def advance(self, k: int, rows, n: int) -> _State:
        """Step from communication point ``k`` at most ``n`` times into ``rows`` (a C-contiguous
        float64 array of at least n rows); returns the state (k reached, rows stored, outcome)."""
        return self._call(k, lambda s: self.lib.tapmp_advance(ctypes.byref(self.plan), ctypes.byref(s), n,
                                                              rows.ctypes.data, rows.shape[1]))

    def advance_paced(self, k: int, n: int, pace, ring, block: int, produced, consumed) -> _State:
        """A paced run of ``n`` steps from ``k`` (orchestrator.engine.pacing): each step kept to the
        wall-clock schedule of ``pace`` (a pacing.Pace), the rows into ``ring`` (C-contiguous float64,
        slots x block x columns) block by block, ``produced`` / ``consumed`` (c_int64) the blocks
        written and taken. Without the GIL: another thread reads the ring meanwhile."""
        self.plan.pace = ctypes.addressof(pace)
        try:
            return self._call(k, lambda s: self.lib.tapmp_advance_paced(
                ctypes.byref(self.plan), ctypes.byref(s), n, ring.ctypes.data, ring.shape[0], block,
                ring.shape[2], ctypes.addressof(produced), ctypes.addressof(consumed)))
        finally:
            self.plan.pace = None

    def _call(self, k: int, run) -> _State:
        """``run(state)`` from communication point ``k``, the event units' state handed over both ways."""
        s = self.state
        s.k = k
        if self.clock.kind == "accumulated":
            s.acc_t = self.clock.at(k)
        for i, u in self.event_units:  # the Python loop may have stepped since (CoSimulation.step)
            c = self.cunits[i]
            c.next_event, c.clock_k, c.n_events = u.next_event, u.clock_k, u.n_events
        try:
            run(s)
        finally:
            for i, u in self.event_units:
                c = self.cunits[i]
                u.next_event, u.clock_k, u.n_events = c.next_event, c.clock_k, c.n_events
        if self.clock.kind == "accumulated":  # the Python clock continues from where C stopped
            self.clock._acc_k, self.clock._acc_t = s.k, s.acc_t
        return s
