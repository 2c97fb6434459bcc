"""The Python model side of the pythonfmu TAPMP FMUs.

A model adapter subclasses :class:`TapmpSlave`, names its variable table (from
``tapmp.interface``) and implements the hooks ``setup_model`` (build the model from
the parameters), ``step``, ``hidden_state`` and ``restore_hidden_state``.

pythonfmu's ``Fmi2Slave`` is the base class so that ``pythonfmu build`` writes the
modelDescription. At run time the FMU's binary is the native FMUs' runtime
(``fmu_common/c``: the FMI state machine, statuses, messages and FMU states) with model
operations that call the ``fmi2_*`` methods below (``fmu_common/pyfront/python_model.c``).
Every variable's value lives in the runtime's instance; before each call it is copied
into one of two arrays indexed by value reference, ``reals`` (float64) and ``ints``
(int32), and the outputs are copied back from ``reals``. The adapters see the same values
as attributes (``self.F1``), generated per variable.

Bad input (a ModelInputError) becomes one logged error naming the variable, the value,
the time and what is allowed, and an error status; any other exception is a bug, which
the runtime logs and answers with an error status too.
"""

import json
import math
from array import array

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real
from pythonfmu.default_experiment import DefaultExperiment

from tapmp import cmodel
from tapmp.errors import ModelInputError
from tapmp.interface import DEFAULT_EXPERIMENT

OK, WARNING, DISCARD, ERROR = 0, 1, 2, 3  # FMI status codes of log records


def _real(vr):
    return property(lambda self: self.reals[vr], lambda self, x: self.reals.__setitem__(vr, x))


def _integer(vr):
    return property(lambda self: self.ints[vr], lambda self, x: self.ints.__setitem__(vr, x))


def is_number(v) -> bool:
    """A JSON number (an int or a float, not a bool)."""
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def as_float(v) -> float:
    """A JSON number as a float; an integer too large for one becomes an infinity."""
    try:
        return float(v)
    except OverflowError:
        return math.inf if v > 0 else -math.inf


def require_state(check: str, *args) -> None:
    """Run one of the C model's checks of an FMU state's hidden values (tapmp_plant_state_check,
    tapmp_controller_state_check) on ``args``; ModelInputError naming the first offender with
    the value the check saw, as the native FMUs report it."""
    ffi, lib = cmodel.load()
    name, value, allowed = ffi.new("const char **"), ffi.new("double *"), ffi.new("const char **")
    if getattr(lib, check)(*args, name, value, allowed):
        raise ModelInputError(ffi.string(name[0]).decode(), value[0], ffi.string(allowed[0]).decode())


def _text(err: ModelInputError, t: float) -> str:
    """The message of a bad value, with the time if it does not name one."""
    return str(err) if err.time is not None else f"{err} (at t = {t:.6g} s)"


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
        self.default_experiment = DefaultExperiment(start_time=DEFAULT_EXPERIMENT["startTime"],
                                                    stop_time=DEFAULT_EXPERIMENT["stopTime"],
                                                    step_size=DEFAULT_EXPERIMENT["stepSize"])
        self.reals = array("d", [float(v.start) if v.type == "Real" else 0.0 for v in table])
        self.ints = array("i", [int(v.start) if v.type == "Integer" else 0 for v in table])
        self._records = []      # (status, category, message) for the FMI logger; the runtime empties it
        self.time = 0.0         # the current communication point [s], set by the runtime before each call
        self.retune = False     # a tunable parameter changed since the last step
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
        """Write ``values`` (a sequence of floats) to the variables of ``where``; the runtime
        publishes them only if every output is finite, else names the first that is not."""
        self.reals[where] = array("d", values)

    def check_parameters(self) -> None:
        """Raise ModelInputError if the parameters are invalid for the model (its own checks;
        the runtime checks the declared ranges). A tunable parameter set in Step Mode is
        checked at once with this. By default the model is built aside and dropped."""
        saved = self.__dict__.copy()
        try:
            self.setup_model()
        finally:
            self.__dict__.clear()
            self.__dict__.update(saved)

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

    def check_hidden_state(self, hidden) -> None:
        """Raise ModelInputError if ``hidden`` (from :meth:`hidden_state`, of an FMU state whose
        values and time are this object's now) is not valid; change nothing."""

    def log(self, msg: str, status=OK, category: str = "logAll", debug: bool = False):
        """Queue a log record for the FMI logger (errors and warnings always reach it)."""
        self._records.append((int(status), category, str(msg)))

    # --- the model operations the runtime calls (python_model.c) ------------------------
    # Each returns None, or the message of a bad value (a ModelInputError).
    def fmi2_check(self):
        try:
            self.check_parameters()
        except ModelInputError as err:
            return str(err)  # the runtime adds the time
        return None

    def fmi2_setup(self):
        try:
            self.setup_model()
        except ModelInputError as err:
            return _text(err, self.time)
        return None

    def fmi2_initial_outputs(self):
        try:
            self.initial_outputs()
        except ModelInputError as err:
            return str(err)  # the runtime adds the time
        return None

    def fmi2_do_step(self, t, h):
        """The step from t to t + h [s]: None, the message of a bad value, or a status (int) the
        model answers with (nothing is published or logged then)."""
        try:
            self.step(t, h)
        except ModelInputError as err:
            return _text(err, t)
        return None

    def fmi2_retune_step(self, t, h):
        """The step at which tunable parameters set since the last one take effect."""
        self.retune = True
        return self.fmi2_do_step(t, h)

    def fmi2_hidden(self) -> str:
        # json keeps floats exact (the shortest repr round-trips) and, unlike pickle, is safe to load.
        return json.dumps(self.hidden_state())

    def fmi2_check_state(self, text: str):
        """The hidden state of an FMU state (its JSON text), checked against the state's values
        and time (in ``reals``, ``ints`` and ``time``) without touching the model: None, or the
        message naming the bad value."""
        try:
            hidden = json.loads(text)
        except (ValueError, RecursionError):
            return f"hidden state = {text!r} is invalid: allowed is the JSON text of the model's hidden state"
        try:
            self.check_hidden_state(hidden)
        except ModelInputError as err:
            return str(err)
        return None

    def fmi2_restore(self, text: str) -> None:
        hidden = json.loads(text)
        self.check_hidden_state(hidden)
        self.restore_hidden_state(hidden)

    # --- pythonfmu's Python-level accessors (used by `pythonfmu build` for start values) -
    def get_real(self, vrs):
        return [self.reals[vr] for vr in vrs]

    def get_integer(self, vrs):
        return [self.ints[vr] for vr in vrs]

    def fmi2_reject_input(self, vr, value):
        """A non-finite value for input ``vr``: None (the runtime refuses it with an error), or
        a status (int) the model answers with, the value being ignored."""
        return None

    def do_step(self, current_time, step_size):  # Fmi2Slave's abstract method; the runtime calls fmi2_do_step
        return self.fmi2_do_step(current_time, step_size) is None
