"""Shared FMI 2.0 co-simulation plumbing for the TAPMP FMUs.

A model adapter subclasses :class:`TapmpSlave`, names its variable table (from
``tapmp.interface``) and implements the hooks ``setup_model`` (build the model from
the parameters), ``step``, ``hidden_state`` and ``restore_hidden_state``.

pythonfmu's ``Fmi2Slave`` is the base class so that ``pythonfmu build`` writes the
modelDescription; at run time the FMU's own binary (``fmu_common/native``) drives the
``fmi2_*`` methods below. Every variable's value lives in one of two arrays indexed by
value reference, ``reals`` (float64) and ``ints`` (int32), which the binary reads and
writes directly: getReal, getInteger and setReal of an input never enter Python. The
adapters see the same values as attributes (``self.F1``), generated per variable.

Bad input never reaches the model and never crashes the host: the call that receives it
returns fmi2Error after logging one message (category logStatusError) naming the
variable, the value, the time and what is allowed, and every later doStep is refused
with fmi2Error too, so no NaN or stale value travels on. Nothing is raised to the binary
on purpose; should a bug raise anyway, the binary logs it and returns fmi2Error.
"""

import json
import math
from array import array

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real
from pythonfmu.default_experiment import DefaultExperiment

from tapmp.errors import ModelInputError
from tapmp.interface import range_text

OK, WARNING, DISCARD, ERROR = 0, 1, 2, 3
LOGS_PENDING = 8  # or-ed into a returned status when log records wait in the queue
# Variable kinds, one byte per value reference, for the binary.
KIND = {("Real", "input"): "i", ("Real", "parameter"): "p", ("Real", "output"): "o",
        ("Integer", "parameter"): "I"}
# Modes of the FMI 2.0 co-simulation state machine that matter for setting values.
INSTANTIATED, INITIALIZATION, STEPPING, TERMINATED = "instantiated", "initialization", "step", "terminated"
MODE_NAMES = {INSTANTIATED: "Instantiated", INITIALIZATION: "Initialization Mode", STEPPING: "Step Mode",
              TERMINATED: "Terminated"}
# doStep(t, h) must continue the previous step: |t - end of previous step| <= this x max(1 s, |t_end|).
TIME_TOLERANCE = 1e-9
OVERFLOW = "a finite number (the output overflowed; check the inputs and parameters)"


def _real(vr):
    return property(lambda self: self.reals[vr], lambda self, x: self.reals.__setitem__(vr, x))


def _integer(vr):
    return property(lambda self: self.ints[vr], lambda self, x: self.ints.__setitem__(vr, x))


class TapmpSlave(Fmi2Slave):
    """Maps a ``tapmp.interface`` variable table onto value arrays and the model hooks."""

    VARIABLES = ()
    author = "TAPMP co-simulation project"
    license = "MIT"

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        for vr, v in enumerate(cls.VARIABLES):  # value reference = index in the table
            setattr(cls, v.name, _real(vr) if v.type == "Real" else _integer(vr))

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        table = self.VARIABLES
        self.default_experiment = DefaultExperiment(start_time=0.0, stop_time=2.5, step_size=1e-4)
        self.reals = array("d", [float(v.start) if v.type == "Real" else 0.0 for v in table])
        self.ints = array("i", [int(v.start) if v.type == "Integer" else 0 for v in table])
        self.kinds = "".join(KIND[v.type, v.causality] for v in table).encode()
        self._names = [v.name for v in table]
        self._tunable = frozenset(i for i, v in enumerate(table) if v.variability == "tunable")
        self._ranged = [(i, v) for i, v in enumerate(table) if v.causality == "parameter" and v.min is not None]
        self._records = []
        self.logging_on = False
        self._clear()
        for v in table:
            kind = Real if v.type == "Real" else Integer
            kw = {"causality": Fmi2Causality[v.causality], "description": v.description}
            if v.causality == "parameter":
                kw["variability"] = Fmi2Variability[v.variability]
            elif v.type == "Real":
                kw["variability"] = Fmi2Variability.continuous
            else:
                kw["variability"] = Fmi2Variability.discrete
            self.register_variable(kind(v.name, **kw))

    def _clear(self):
        self.time = 0.0
        self._t_end = 0.0       # the time outputs being published belong to
        self.mode = INSTANTIATED
        self.error = None       # first error message; the instance refuses to step after it
        self.retune = False     # a tunable parameter changed since the last step

    @classmethod
    def block(cls, first: str, count: int) -> slice:
        """Slice of ``reals`` for ``count`` variables stored contiguously from ``first``.

        The adapters read inputs and publish outputs as blocks (one C-level copy
        instead of a property call per variable); this checks the layout once.
        """
        names = [v.name for v in cls.VARIABLES]
        start = names.index(first)
        if any(v.type != "Real" for v in cls.VARIABLES[start:start + count]) or start + count > len(names):
            raise ValueError(f"{count} Real variables from {first} are not contiguous in {cls.__name__}")
        return slice(start, start + count)

    def publish_block(self, where: slice, values) -> None:
        """Write ``values`` (a sequence of floats) to the variables of ``where``; a value that
        is not finite is never published: ModelInputError names the first such output."""
        if not math.isfinite(sum(values)):  # one sum on the fast path
            for name, value in zip(self._names[where], values):
                if not math.isfinite(value):
                    raise ModelInputError(name, value, OVERFLOW, self._t_end)
        self.reals[where] = array("d", values)

    def check_ranges(self) -> None:
        """Raise ModelInputError for a parameter outside its declared range (tapmp.interface.RANGES)."""
        for vr, v in self._ranged:
            value = self.reals[vr] if v.type == "Real" else self.ints[vr]
            if not v.min <= value <= v.max:
                raise ModelInputError(v.name, value, range_text(v))

    def check_parameters(self) -> None:
        """The model's own checks of the tunable parameters, then the ranges (a tunable
        parameter set in Step Mode is checked at once with this)."""
        self.check_ranges()

    # --- hooks for the model adapters -------------------------------------------
    def setup_model(self) -> None:
        """Build the model from the current parameter values and publish outputs."""
        raise NotImplementedError

    def step(self, t: float, h: float) -> None:
        """Advance from t to t + h [s] and publish outputs."""
        raise NotImplementedError

    def initial_outputs(self) -> None:
        """Compute outputs that depend on inputs, at the end of initialization."""

    def hidden_state(self):
        """JSON-serializable state that is not a registered variable."""
        return None

    def restore_hidden_state(self, hidden) -> None:
        """Inverse of :meth:`hidden_state`; called after the variables are restored."""

    # --- logging and errors ----------------------------------------------------------
    def log(self, msg: str, status=OK, category: str = "logAll", debug: bool = False):
        """Queue a log record for the FMI logger (errors always reach it)."""
        self._records.append((int(status), category, str(msg)))

    def _status(self, status: int) -> int:
        return status | LOGS_PENDING if self._records else status

    def fmi2_take_logs(self):
        records, self._records = self._records, []
        return records

    def fail_text(self, msg: str) -> int:
        """Log ``msg`` at fmi2Error level, refuse further steps; fmi2Error."""
        self.log(msg, ERROR, "logStatusError")
        if self.error is None:
            self.error = msg
        return self._status(ERROR)

    def mode_error(self, call: str, allowed: str, hint: str = "") -> int:
        """fmi2Error for a call the co-simulation state machine does not allow now."""
        return self.fail_text(f"fmi2{call} is not allowed in {MODE_NAMES[self.mode]}: allowed in {allowed}{hint}")

    def fail(self, err: Exception, t: float) -> int:
        """Log ``err`` at fmi2Error level, with the time, refuse further steps; fmi2Error."""
        msg = str(err)
        if isinstance(err, ModelInputError) and err.time is None:
            msg = f"{msg} (at t = {t:.6g} s)"
        self.log(msg, ERROR, "logStatusError")
        if self.error is None:
            self.error = msg
        return self._status(ERROR)

    def _guard(self, action) -> int:
        try:
            action()
        except ModelInputError as err:
            return self.fail(err, self.time)
        return self._status(OK)

    # --- FMI entry points, called by the binary; each returns a status code -----------
    def fmi2_setup_experiment(self, start_time, stop_time=None, tolerance=None):
        if self.mode != INSTANTIATED:
            return self.mode_error("SetupExperiment", "Instantiated")
        if not math.isfinite(start_time):
            return self.fail(ModelInputError("startTime", start_time, "a finite number"), 0.0)
        self.time = float(start_time)
        return self._status(OK)

    def _setup(self):
        self._t_end = self.time
        outputs = self.reals.tolist()
        try:
            try:
                self.setup_model()
            except ModelInputError as err:
                if err.allowed == OVERFLOW:  # as the native FMUs: a range error explains it first
                    self.check_ranges()
                raise
            self.check_ranges()
        except ModelInputError:
            self.reals[:] = array("d", outputs)  # nothing half-built is published
            raise

    def fmi2_enter_initialization_mode(self):
        if self.mode != INSTANTIATED:
            return self.mode_error("EnterInitializationMode", "Instantiated")
        self.mode = INITIALIZATION
        return self._guard(self._setup) if self.error is None else self._status(ERROR)

    def fmi2_exit_initialization_mode(self):
        if self.mode != INITIALIZATION:
            return self.mode_error("ExitInitializationMode", "Initialization Mode")
        self.mode = STEPPING
        self.retune = False
        if self.error is not None:
            return self._status(ERROR)

        def init():
            self._setup()
            self.initial_outputs()
        return self._guard(init)

    def fmi2_update_initial_unknowns(self):
        """Recompute the outputs from the values set in Initialization Mode so far.

        The binary calls this at the first get after a set in Initialization Mode: FMI 2.0
        lets a master set parameters and inputs there and read the outputs (initial
        unknowns) before fmi2ExitInitializationMode. fmpy's container runtime copies each
        connection once that way, so the controller's F must already follow q_d and q;
        Ecos sets parameters there. A combination that is invalid may be a master's
        half-way point (one value set, the next to come): the outputs keep the last
        valid values, and fmi2ExitInitializationMode, which builds the model again,
        reports the error if it is still there.
        """
        if self.mode == INITIALIZATION and self.error is None:
            try:
                self._setup()
                self.initial_outputs()
            except ModelInputError:
                pass
        return self._status(OK)

    def fmi2_do_step(self, current_time, step_size):
        if self.mode != STEPPING:
            hint = (" (the instance is terminated; reset it first)" if self.mode == TERMINATED else
                    " (leave initialization first: EnterInitializationMode, ExitInitializationMode)")
            return self.mode_error("DoStep", "Step Mode", hint)
        if self.error is not None:
            self.log(f"doStep at t = {current_time:.6g} s refused after "
                     f"an earlier error: {self.error}", ERROR, "logStatusError")
            return self._status(ERROR)
        if not math.isfinite(current_time):
            return self.fail(ModelInputError("currentCommunicationPoint", current_time, "a finite number"),
                             self.time)
        if not (math.isfinite(step_size) and step_size > 0.0):
            return self.fail(ModelInputError("communicationStepSize", step_size, "a finite number > 0"),
                             current_time)
        tolerance = TIME_TOLERANCE * max(1.0, abs(self.time))
        if abs(current_time - self.time) > tolerance:
            return self.fail(ModelInputError("currentCommunicationPoint", current_time,
                                             f"the end of the previous step, {self.time!r} s (within {tolerance:g} s)"),
                             self.time)
        self._t_end = current_time + step_size
        try:
            self.step(current_time, step_size)
        except ModelInputError as err:
            return self.fail(err, current_time)
        self.time = current_time + step_size
        return LOGS_PENDING if self._records else OK

    def fmi2_terminate(self):
        if self.mode != STEPPING and self.error is None:
            return self.mode_error("Terminate", "Step Mode")
        self.mode = TERMINATED
        return self._status(OK)

    def fmi2_reset(self):
        for vr, v in enumerate(self.VARIABLES):
            if v.type == "Real":
                self.reals[vr] = float(v.start)
            else:
                self.ints[vr] = int(v.start)
        self._clear()
        self.restore_hidden_state(None)
        return self._status(OK)

    def _settable(self, vr, value, call="SetReal") -> int:
        """OK if variable vr may be set now, else the logged error."""
        if self.mode == TERMINATED:
            return self.mode_error(call, "Instantiated, Initialization Mode or Step Mode")
        v = self.VARIABLES[vr]
        if v.causality == "output":
            return self.fail(ModelInputError(v.name, value, "no value: it is an output"), self.time)
        if v.variability == "fixed" and self.mode not in (INSTANTIATED, INITIALIZATION):
            return self.fail(ModelInputError(v.name, value, "no change after initialization: "
                                             "it is a fixed parameter"), self.time)
        return OK

    def fmi2_reject_input(self, vr, value):
        return self.fail(ModelInputError(self._names[vr], value, "a finite number", self.time), self.time)

    def fmi2_set_real(self, vr, value):
        status = self._settable(vr, value)
        if status != OK:
            return status
        if not math.isfinite(value):  # refused: the previous value stays
            return self.fail(ModelInputError(self._names[vr], value, "a finite number", self.time), self.time)
        return self._set_checked(self.reals, vr, value)

    def fmi2_set_integer(self, vr, value):
        status = self._settable(vr, value, "SetInteger")
        if status != OK:
            return status
        return self._set_checked(self.ints, vr, value)

    def _set_checked(self, values, vr, value) -> int:
        """Set; a tunable parameter in Step Mode is checked at once and kept only if valid."""
        old = values[vr]
        values[vr] = value
        if vr in self._tunable and self.mode == STEPPING:
            try:
                self.check_parameters()
            except ModelInputError as err:
                values[vr] = old
                return self.fail(err, self.time)
            self.retune = True
        return self._status(OK)

    # --- FMU state: all values plus the model's hidden state ---------------------------
    def fmi2_get_state(self):
        return (self.reals.tolist(), self.ints.tolist(),
                [self.time, self.mode, self.error, self.retune], self.hidden_state())

    def _check_state(self, state) -> None:
        """Raise ValueError unless ``state`` is a complete, finite state of this FMU."""
        try:
            reals, ints, meta, hidden = state
            time, mode, error, retune = meta
        except (TypeError, ValueError):
            raise ValueError("FMU state: not a state of this FMU (4 parts expected)") from None
        n = len(self.VARIABLES)
        if len(reals) != n or len(ints) != n or mode not in MODE_NAMES:
            raise ValueError(f"FMU state: not a state of {type(self).__name__} ({n} variables)")
        for name, value in zip(self._names, reals):
            if not (isinstance(value, (int, float)) and math.isfinite(value)):
                raise ValueError(f"FMU state: {name} = {value!r} is invalid: allowed is a finite number")
        if not (isinstance(time, (int, float)) and math.isfinite(time)):
            raise ValueError(f"FMU state: time = {time!r} is invalid: allowed is a finite number")
        self.check_hidden_state(hidden)

    def check_hidden_state(self, hidden) -> None:
        """Raise ValueError if ``hidden`` (from :meth:`hidden_state`) is not valid."""

    def fmi2_set_state(self, state):
        try:
            self._check_state(state)
        except ValueError as err:
            return self.fail_text(f"fmi2SetFMUstate: {err}; nothing was changed")
        reals, ints, meta, hidden = state
        self.reals[:] = array("d", reals)  # in place: the binary holds these buffers
        self.ints[:] = array("i", ints)
        self.time, self.mode, self.error, self.retune = meta
        self.restore_hidden_state(hidden)
        return self._status(OK)

    def fmi2_serialize(self, state) -> bytes:
        # json keeps floats exact (shortest repr round-trips) and, unlike pickle, is safe to load.
        return json.dumps({"model": type(self).__name__, "state": state}).encode()

    def fmi2_deserialize(self, data: bytes):
        doc = json.loads(data.decode())
        if doc.get("model") != type(self).__name__:
            raise ValueError(f"serialized FMU state of {doc.get('model')!r}, "
                             f"not of {type(self).__name__!r}")
        state = tuple(doc["state"])
        self._check_state(state)
        return state

    # --- pythonfmu's Python-level accessors (used by `pythonfmu build` for start values) -
    def get_real(self, vrs):
        return [self.reals[vr] for vr in vrs]

    def get_integer(self, vrs):
        return [self.ints[vr] for vr in vrs]

    def do_step(self, current_time, step_size):  # Fmi2Slave's abstract method; the binary calls fmi2_do_step
        return self.fmi2_do_step(current_time, step_size) & 7 == OK
