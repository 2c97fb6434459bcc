"""Shared FMI 2.0 co-simulation plumbing for the TAPMP FMUs, on top of pythonfmu.

A model adapter subclasses :class:`TapmpSlave`, names its variable table (from
``tapmp.interface``) and implements four hooks: ``setup_model`` (build the model
from the parameters), ``step``, ``hidden_state`` and ``restore_hidden_state``.

Bad input never reaches the model and never crashes the host: a non-finite value
is refused by the setter, an invalid parameter or pose raises ModelInputError in
the model; either way the instance logs one message at fmi2Error level (category
logStatusError) naming the variable, the value, the time and what is allowed,
and every later doStep is refused, so no NaN or stale value travels on.

What status code the host sees is decided by pythonfmu 0.7's binary, not here: a
refused doStep (do_step returns False) is reported as fmi2Discard. Nothing is ever
raised out of this class on purpose: pythonfmu 0.7 turns a Python exception into
fmi2Fatal and its exception path corrupts the interpreter (the host segfaults at
garbage collection, reproduced here), so a refused setReal or initialization
returns with the error logged and the next doStep fails.
"""

import math

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real
from pythonfmu.default_experiment import DefaultExperiment
from pythonfmu.enums import Fmi2Status

from tapmp.errors import ModelInputError

_HIDDEN = "__hidden__"
_META = "__meta__"


class TapmpSlave(Fmi2Slave):
    """Maps a ``tapmp.interface`` variable table onto attributes and the model hooks."""

    VARIABLES = ()
    author = "TAPMP co-simulation project"
    license = "MIT"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.default_experiment = DefaultExperiment(start_time=0.0, stop_time=2.5, step_size=1e-4)
        self.time = 0.0
        self.error = None       # first error message; the instance refuses to step after it
        self.retune = False     # a tunable parameter changed since the last step
        self._names = []
        for v in self.VARIABLES:
            setattr(self, v.name, v.start)
            kind = Real if v.type == "Real" else Integer
            kw = {"causality": Fmi2Causality[v.causality], "description": v.description}
            if v.causality == "parameter":
                kw["variability"] = Fmi2Variability[v.variability]
            elif v.type == "Real":
                kw["variability"] = Fmi2Variability.continuous
            else:
                kw["variability"] = Fmi2Variability.discrete
            self.register_variable(kind(v.name, **kw))
            self._names.append(v.name)
        self._tunable = {i for i, v in enumerate(self.VARIABLES) if v.variability == "tunable"}

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

    # --- error reporting -----------------------------------------------------------
    def fail(self, err: Exception, t: float) -> None:
        """Log ``err`` at fmi2Error level, with the time, and refuse further steps."""
        msg = str(err)
        if isinstance(err, ModelInputError) and err.time is None:
            msg = f"{msg} (at t = {t:.6g} s)"
        self.log(msg, Fmi2Status.error, "logStatusError")
        if self.error is None:
            self.error = msg

    def _guard(self, action, t: float) -> bool:
        try:
            action()
        except ModelInputError as err:
            self.fail(err, t)
            return False
        return True

    # --- FMI entry points ----------------------------------------------------------
    def setup_experiment(self, start_time, stop_time=None, tolerance=None):
        self.time = float(start_time)

    def enter_initialization_mode(self):
        self._guard(self.setup_model, self.time)

    def exit_initialization_mode(self):
        if self.error is None and self._guard(self.setup_model, self.time):
            self._guard(self.initial_outputs, self.time)
        self.retune = False

    def do_step(self, current_time, step_size):
        if self.error is not None:
            self.log(f"doStep at t = {current_time:.6g} s refused after "
                     f"an earlier error: {self.error}", Fmi2Status.error, "logStatusError")
            return False
        if not (math.isfinite(step_size) and step_size > 0.0):
            self.fail(ModelInputError("communicationStepSize", step_size, "a finite number > 0"),
                      current_time)
            return False
        if not self._guard(lambda: self.step(current_time, step_size), current_time):
            return False
        self.time = current_time + step_size
        return True

    def set_real(self, vrs, values):
        for vr, value in zip(vrs, values):
            if not math.isfinite(value):  # refused: the previous value stays
                self.fail(ModelInputError(self._names[vr], value, "a finite number", self.time), self.time)
                continue
            setattr(self, self._names[vr], value)
            if vr in self._tunable:
                self.retune = True

    def set_integer(self, vrs, values):
        for vr, value in zip(vrs, values):
            setattr(self, self._names[vr], int(value))
            if vr in self._tunable:
                self.retune = True

    def get_real(self, vrs):
        names = self._names
        return [float(getattr(self, names[vr])) for vr in vrs]

    def get_integer(self, vrs):
        names = self._names
        return [int(getattr(self, names[vr])) for vr in vrs]

    # --- FMU state: registered variables plus the model's hidden state -------------
    def _get_fmu_state(self):
        state = {name: getattr(self, name) for name in self._names}
        state[_META] = [self.time, self.error, self.retune]
        state[_HIDDEN] = self.hidden_state()
        return state

    def _set_fmu_state(self, state):
        for name in self._names:
            setattr(self, name, state[name])
        self.time, self.error, self.retune = state[_META]
        self.restore_hidden_state(state[_HIDDEN])
