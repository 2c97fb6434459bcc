"""The master algorithm: co-simulates the FMUs of any SSP system of co-simulation FMUs
(FMI 2.0 and 3.0, any element names, any number of elements) on fmpy.

Life cycle: extract, instantiate, apply parameters, setupExperiment, enter
initialization, propagate outputs through the connections in dependency order
(each FMU's inputs are set from its sources, then it leaves initialization),
then step at a fixed communication step h where the time of step k is t0 + k h
(never accumulated; see ``clock`` below), then terminate and free every instance and
remove every extracted folder, also when a step fails.

Orderings of one macro step from t to t + h (the orders themselves come from the connection
graph and the FMUs' declared direct feedthrough: ``orchestrator.engine.schedule``; docs/master.md):
* ``gauss-seidel`` (default): one element after the other, each taking the latest outputs
  of its sources just before it steps. Default order from the graph; for the TAPMP system
  controller, plant, trajectory: the plant integrates with the command the controller
  computed from the measurement at t, a sampled loop whose only delay is the zero-order
  hold of the servo cycle. ``order`` gives the order explicitly.
* ``jacobi``: every FMU's inputs are set from the outputs at t, then all step.
  The plant runs with the command of the previous sample: one extra step of delay
  (0.1 ms) in the feedback path. This is what libcosim's and Ecos's fixed-step
  masters and FMPy's ``simulate_ssp`` do.
An algebraic loop (a cycle of connections through direct feedthrough only) is refused.

Reading the SSP (parse, check the elements, extract the FMUs, bind the parameter tables) is
``orchestrator.engine.ssd``. Parameters address elements by SSP name; the caller's ``roles``
({role: modelName}) also address the one element whose FMU is that model, whatever the SSP calls
it (the TAPMP roles plant, controller, trajectory: orchestrator.tool.roles). Recorded
columns are ``element.output``, with such an element written by its role, so a system records
the same columns under any element names.

Conventions of other masters, to reproduce them bit for bit (tests/interop/test_libcosim.py,
test_ecos.py, test_fmpy_ssp.py):
* ``clock``: how t_k and h_k are computed (``orchestrator.engine.clocks``): ``exact``
  (default, t0 + k h), ``accumulated`` (FMPy, Ecos) or ``nanoseconds`` (libcosim).
* ``connection_start``: ``propagated`` (default; also libcosim and Ecos, which iterate
  the transfers in Initialization Mode) or ``zero``: FMPy's ``simulate_ssp``, which
  initializes every FMU on its own and starts every connection at 0, so no output is
  read before the first step and the first step's inputs are all 0.

Event mode (``event_mode``, FMI 3.0): every FMU with ``hasEventMode`` (the TAPMP controller) is
instantiated with eventModeUsed and earlyReturnAllowed. The master keeps each one's nextEventTime
and never steps any FMU past it: a macro step is cut at every event inside it, every FMU steps to
the event, and there the event FMUs, in the step order, enter Event Mode, take their inputs from the
outputs at that time, update (fmi3UpdateDiscreteStates) and publish their outputs, which the others
take from then on. An event at the end of a macro step is handled at the start of the next one, so
the row at a communication point holds the outputs before it (the command of the previous sample).
So the controller samples at every instant t0 + k T_s whatever the macro step. An FMU with periodic
input clocks (the clocked controller, TAPMP_ControllerClocked) is handled the same way with its ticks as
the events: the master reads the interval and shift after initialization (fmi3GetIntervalDecimal,
fmi3GetShiftDecimal), cuts the macro step at every tick t0 + shift + k interval and there activates the
clocks (fmi3SetClock) in Event Mode before the inputs and the update; such an FMU requires event_mode.
The FMI 3.0 FMUs without Event Mode and the FMI 2.0 ones step as before. An early return at a time the FMU did not
announce is refused: the others have stepped past it already.
The compiled stepping core (stepper.c) runs the same event loop with the same FMI calls in the same
order, so its rows are the Python loop's to the bit.
"""

import math
import os
from ctypes import c_double, c_int64
from pathlib import Path

from fmpy.fmi1 import FMICallException

from . import perturbation
from . import stepper as stepper_core
from .archive import ExtractBudget, ExtractLimitError
from .clocks import Clock
from .errors import CoSimulationError, DivergenceError
from .model_exchange import ModelExchangeUnit, model_exchange_units
from .options import OutputCheck, RunOptions
from .schedule import (CONNECTION_STARTS, ORDERINGS, Connection, ScheduleError, check_algebraic_loops, check_order,
                       gauss_seidel_order, initialization_order)
from .loaded import LoadedFMUs, LoadedSystem
from .ssd import ParameterAddressError, column_prefixes, resolve_parameters
from .instance import Unit

STEPPERS = stepper_core.STEPPERS  # auto: the compiled core if it can be built, else Python
_STATUS = ["OK", "WARNING", "DISCARD", "ERROR", "FATAL", "PENDING"]


class CoSimulation:
    """A running co-simulation of an SSP system; use as a context manager.

    ``parameters`` maps element name -> {parameter name: value}. After entering,
    :attr:`columns` names the recorded values and :meth:`row` returns them.
    ``options`` (a :class:`RunOptions`) says how it steps: start time and step [s], ordering,
    clock, connection start, event mode, the roles, the Model Exchange elements. Every step checks
    that every output is finite and that the columns of ``options.check.bounds`` (an
    :class:`OutputCheck` from the caller, e.g. TAPMP's platform envelope) stay within their
    limits; a breach raises DivergenceError naming the time, the signal and the value. Every FMU
    input must be driven by a connection unless ``options.open_inputs`` names it
    ("element.variable"): such an input keeps its start value. ``parameters`` keys are element
    names or the role names of ``options.roles``. After entering, :attr:`step_order` and
    :attr:`init_order` hold the element names in the orders used. ``loaded`` (LoadedFMUs) keeps
    the FMUs loaded between co-simulations.
    """

    def __init__(self, ssp_path, parameters: dict, options: RunOptions = RunOptions(),
                 loaded: LoadedFMUs | None = None):
        if not isinstance(options, RunOptions):
            raise TypeError(f"options = {options!r} is invalid: allowed is a RunOptions")
        self.options = o = options
        if o.ordering not in ORDERINGS:
            raise CoSimulationError(f"ordering = {o.ordering!r} is invalid: allowed are "
                                    f"{', '.join(ORDERINGS)}")
        if o.order is not None and o.ordering != "gauss-seidel":
            raise CoSimulationError(f"order = {o.order!r} is invalid with ordering = {o.ordering!r}: allowed is an "
                                    "order only with ordering = 'gauss-seidel' (Jacobi steps all at once)")
        self.order = o.order
        stepper = o.stepper or os.environ.get("TAPMP_STEPPER") or "auto"
        if stepper not in STEPPERS:
            raise CoSimulationError(f"stepper = {stepper!r} is invalid (TAPMP_STEPPER or the stepper argument): "
                                    f"allowed are {', '.join(STEPPERS)}")
        if o.event_mode not in (True, False):
            raise CoSimulationError(f"event_mode = {o.event_mode!r} is invalid: allowed is true or false")
        self.event_mode = bool(o.event_mode)
        self.model_exchange = o.model_exchange  # elements or roles run as Model Exchange (model_exchange.py)
        self.me_tolerance = o.me_tolerance
        if o.model_exchange and stepper == "compiled":
            raise CoSimulationError("stepper = 'compiled' is unavailable with a Model Exchange FMU (model_exchange): "
                                    "allowed are 'python' or 'auto' (the master's integrator runs in Python)")
        self.stepper = stepper
        self._core = None        # the CompiledStepper once opened, if used
        self.filled = 0          # rows the last advance() stored, also when it raised
        self._log_count, self._log_errors = c_int64(), c_int64()  # read by the compiled core
        if not o.step_size > 0.0:
            raise CoSimulationError(f"step_size = {o.step_size!r} is invalid: allowed is a number > 0")
        if o.connection_start not in CONNECTION_STARTS:
            raise CoSimulationError(f"connection_start = {o.connection_start!r} is invalid: allowed are "
                                    f"{', '.join(CONNECTION_STARTS)}")
        try:
            self.clock = Clock(o.clock, o.start_time, o.step_size)
        except ValueError as err:
            raise CoSimulationError(str(err)) from None
        self.connection_start = o.connection_start
        if isinstance(o.open_inputs, str) or not all(isinstance(x, str) for x in o.open_inputs):
            raise CoSimulationError(f"open_inputs = {o.open_inputs!r} is invalid: allowed is a list of "
                                    "\"element.variable\" strings")
        self.open_inputs = tuple(o.open_inputs)
        self.ssp_path = Path(ssp_path)
        self.parameters = parameters
        self.roles = dict(o.roles or {})
        self.other_tables = tuple(o.other_tables)
        self.t0 = float(o.start_time)
        self.h = float(o.step_size)
        self.ordering = o.ordering
        self.units: dict[str, Unit] = {}
        self.log: list[str] = []
        self.tmp = None
        self.loaded = loaded     # LoadedFMUs that keeps the FMUs loaded between co-simulations, or None
        self._system = None      # the LoadedSystem while open
        self.k = 0
        self.guids = {}
        self.check = o.check or OutputCheck()
        self._offsets = []       # perturbation.Offsets of the perturbed units (options.perturb)

    # --- setup ---------------------------------------------------------------------
    def _logger(self, env, instance, status, category, message):
        self._log_count.value += 1
        if status in (3, 4):  # fmi2Error/fmi3Error, Fatal: the message starts [ERROR] or [FATAL]
            self._log_errors.value += 1
        self.log.append(f"[{_STATUS[status] if 0 <= status < 6 else status}] "
                        f"{instance.decode(errors='replace')}: {message.decode(errors='replace')}")

    def __enter__(self):
        try:
            self._open()
        except BaseException:  # never leave an instance or a folder behind
            self.close()
            raise
        return self

    def __exit__(self, *exc):
        self.close()
        return False

    def _open(self):
        if self.ssp_path.is_dir():
            raise CoSimulationError(f"SSP file {self.ssp_path} is a folder: allowed is an SSP file (a zip archive "
                                    "holding SystemStructure.ssd and the FMUs)")
        if not self.ssp_path.is_file():
            raise CoSimulationError(f"SSP file {self.ssp_path} does not exist: run `tapmp build` first")
        try:
            self._budget = ExtractBudget()  # of the SSP's members and the FMUs' together
        except ExtractLimitError as err:
            raise CoSimulationError(str(err)) from None
        # -- the loaded FMUs: this co-simulation's own, or a reset system kept by ``loaded`` --
        if self.loaded is None or self.model_exchange:  # a Model Exchange instance is no part of a kept system
            self._system = LoadedSystem(self.ssp_path, self._budget, self.event_mode)
        else:
            self._system = self.loaded.take(self.ssp_path, self._budget, self.event_mode)
        system = self._system
        system.target = self._logger
        self.tmp = system.tmp
        self.units = system.units
        for name, unit in self.units.items():
            unit.log = self.log
            self.guids[name] = unit.md.guid
        ssd = system.ssd
        model_exchange_units(self.units, self.model_exchange, self.roles, self.me_tolerance,
                             f"the system in SSP file {self.ssp_path}")
        self._connect(ssd.system.connections)
        for unit in self.units.values():
            unit.finish_connections()
        self._offsets = perturbation.attach(self.units, self.options.perturb, self.roles, self.event_mode,
                                            self.stepper, f"SSP file {self.ssp_path}")
        self._plan(ssd.system.connections)
        parameters = self._resolve_parameters()
        if self.event_mode and not any(u.has_event_mode for u in self.units.values()):
            raise CoSimulationError(f"event_mode = true is invalid for SSP file {self.ssp_path}: no FMU in it has "
                                    "Event Mode: allowed is an SSP with an FMI 3.0 FMU with hasEventMode=\"true\" "
                                    "(the native FMI 3.0 controller, build/native/fmi3/TAPMP.ssp)")
        self._check_clocks()
        for name in self.init_order:
            unit = self.units[name]
            if not unit.instantiated:  # else reset by ``loaded``: in the state right after instantiation
                self._call(unit, lambda u=unit: u.instantiate(system.callbacks, system.log_message, self.event_mode),
                           "instantiate")
                unit.instantiated = True
            for pname, value in parameters.get(name, {}).items():
                self._call(unit, lambda u=unit, p=pname, v=value: u.set_parameter(p, v),
                           f"set parameter {pname}")
            self._call(unit, lambda u=unit: u.enter_initialization(self.t0), "enterInitializationMode")
        propagate = self.connection_start == "propagated"
        if propagate:
            for name in self.init_order:
                unit = self.units[name]
                self._call(unit, unit.read_outputs, "getReal")
        for name in self.init_order:  # dependency order: sources leave initialization first
            unit = self.units[name]
            if propagate:
                self._call(unit, unit.apply_inputs, "setReal")
            self._call(unit, unit.slave.exitInitializationMode, "exitInitializationMode")
            if isinstance(unit, ModelExchangeUnit):  # in Event Mode: the event iteration, then the integrator
                self._call(unit, lambda u=unit: u.start_continuous(self.t0), "enterContinuousTimeMode", self.t0)
            if unit.event_mode:  # it left initialization into Event Mode: the event at the start time
                if unit.clocks:
                    self._start_clocks(unit)
                self._call(unit, unit.update_discrete_states, "updateDiscreteStates", self.t0)
                self._call(unit, unit.slave.enterStepMode, "enterStepMode", self.t0)
            if propagate:  # else the outputs (and so the connections) stay 0 until the first step
                self._call(unit, unit.read_outputs, "getReal")
        prefix = column_prefixes({n: u.md.modelName for n, u in self.units.items()}, self.roles)
        self.columns = ["time"] + [f"{prefix[n]}.{o}" for n, u in self.units.items() for o in u.outputs]
        self._row_units = list(self.units.values())
        self._step_units = [self.units[n] for n in self.step_order]
        where = {f"{prefix[n]}.{o}": (u, i) for n, u in self.units.items() for i, o in enumerate(u.outputs)}
        self._bounds = []     # (outputs array, index, column, limit, element)
        envelope_units = []   # (unit, output index, limit) for the compiled core
        for column, limit in self.check.bounds:
            if column in where:  # a signal the system does not record is not checked
                unit, i = where[column]
                self._bounds.append((unit.out, i, column, float(limit), unit.name))
                envelope_units.append((unit, i, float(limit)))
        self._check_outputs(self.t0)
        self._event_units = [u for u in self._step_units if u.event_mode]
        if any(isinstance(u, ModelExchangeUnit) for u in self._step_units) or self._offsets:
            pass  # the Python loop: the compiled core has no integrator and no perturbation
        elif self.stepper == "compiled" or (self.stepper == "auto" and stepper_core.available()):
            try:
                self._core = stepper_core.CompiledStepper(
                    self._row_units, self._step_units, self.ordering == "jacobi", self.clock, envelope_units,
                    self._log_count, self._log_errors, self._event_units, self.event_mode)
            except (stepper_core.StepperBuildError, OSError) as err:
                raise CoSimulationError(f"stepper = 'compiled' is unavailable: {err}") from None

    def _plan(self, connections) -> None:
        """:attr:`init_order` and :attr:`step_order` from the connection graph and the FMUs'
        declared direct feedthrough (or the explicit ``order``); refuses an algebraic loop."""
        names = list(self.units)
        conns = [Connection(c.startElement, c.startConnector, c.endElement, c.endConnector) for c in connections]

        def feedthrough(element, output):
            return self.units[element].feedthrough[output]
        try:
            check_algebraic_loops(names, conns, feedthrough)
            self.init_order = initialization_order(names, conns, feedthrough)
            if self.ordering == "jacobi":
                self.step_order = list(self.init_order)  # all step on the values at t: any order
            elif self.order is not None:
                self.step_order = check_order(self.order, names)
            else:
                self.step_order = gauss_seidel_order(names, conns, feedthrough)
        except ScheduleError as err:
            raise CoSimulationError(f"SSP file {self.ssp_path}: {err}") from None

    def _resolve_parameters(self) -> dict:
        """``parameters`` keyed by element (ssd.resolve_parameters: by name, or by role)."""
        models = {n: u.md.modelName for n, u in self.units.items()}
        try:
            return resolve_parameters(self.parameters, models, self.ssp_path, self.roles, self.other_tables)
        except ParameterAddressError as err:
            raise CoSimulationError(str(err), err.element) from None

    def _connect(self, connections) -> None:
        """Wire the SSP connections, output to input; reject, before any FMU is instantiated,
        a connection that names an element or variable that does not exist, runs the wrong
        way, or drives an input that another connection drives already, and an input that
        nothing drives (unless named in ``open_inputs``)."""
        driven = {}
        for c in connections:
            name = f"{c.startElement}.{c.startConnector} -> {c.endElement}.{c.endConnector}"
            where = f"SSP file {self.ssp_path}: connection {name}"
            for element in (c.startElement, c.endElement):
                if element not in self.units:
                    raise CoSimulationError(f"{where}: element {element!r} does not exist: allowed are "
                                            f"{', '.join(self.units)}")
            src, dst = self.units[c.startElement], self.units[c.endElement]
            for unit, var, causality in ((src, c.startConnector, "output"), (dst, c.endConnector, "input")):
                v = unit.vars.get(var)
                if v is None or v.causality != causality or v.type not in ("Real", "Float64"):
                    allowed = [n for n, x in unit.vars.items() if x.causality == causality and x.type in ("Real", "Float64")]
                    raise CoSimulationError(f"{where}: {unit.name} ({unit.md.modelName}) has no Real {causality} "
                                            f"{var!r}: allowed are {', '.join(allowed)}", unit.name)
            end = (c.endElement, c.endConnector)
            if end in driven:
                raise CoSimulationError(f"{where}: input {c.endElement}.{c.endConnector} is driven already "
                                        f"by {driven[end]}: allowed is one connection per input", dst.name)
            driven[end] = f"{c.startElement}.{c.startConnector}"
            dst.connect(src, c.startConnector, dst.vars[c.endConnector].valueReference)
        self._check_open_inputs({f"{e}.{v}": source for (e, v), source in driven.items()})

    def _check_open_inputs(self, driven: dict) -> None:
        """Refuse an FMU input that no connection drives unless ``open_inputs`` names it, and
        an ``open_inputs`` entry that is no input of the system or that a connection drives."""
        inputs = [f"{u.name}.{n}" for u in self.units.values() for n, v in u.vars.items()
                  if v.causality == "input" and v.type != "Clock"]  # the master ticks input clocks itself
        for entry in self.open_inputs:
            if entry not in inputs:
                raise CoSimulationError(f"open_inputs: {entry!r} is not an input of the system in SSP file "
                                        f"{self.ssp_path}: allowed are {', '.join(inputs)}")
            if entry in driven:
                raise CoSimulationError(f"open_inputs: {entry} is driven by {driven[entry]} in SSP file "
                                        f"{self.ssp_path}: allowed are inputs that no connection drives",
                                        entry.split(".")[0])
        undriven = [i for i in inputs if i not in driven and i not in self.open_inputs]
        if undriven:
            raise CoSimulationError(f"SSP file {self.ssp_path}: no connection drives the input(s) "
                                    f"{', '.join(undriven)}: allowed is every FMU input driven by a connection, "
                                    "or named in the scenario's open_inputs to keep its start value",
                                    undriven[0].split(".")[0])

    def _call(self, unit: Unit, action, what: str, t: float | None = None):
        """Run one FMI call; a failed call (an exception or a returned status above
        fmi2Warning) or an error it logged raises CoSimulationError."""
        n_log = len(self.log)
        try:
            result = action()
        except CoSimulationError:
            raise
        except (FMICallException, Exception) as err:
            self._fail(unit, what, t, err)
        if type(result) is int and result > 1:
            self._fail(unit, what, t, f"status {_STATUS[result] if result < 6 else result}")
        self._check_log(unit, what, t, n_log)
        return result

    def _check_log(self, unit: Unit, what: str, t: float | None, n_log: int) -> None:
        """Fail if an error was logged since ``n_log``: pythonfmu may return OK after one."""
        if any(m.startswith(("[ERROR]", "[FATAL]")) for m in self.log[n_log:]):
            self._fail(unit, what, t, None)

    def _fail(self, unit: Unit, what: str, t: float | None, err):
        when = "" if t is None else f" at t = {t:.6g} s"
        detail = [m for m in self.log if m.startswith(("[ERROR]", "[FATAL]"))]
        reason = detail[0] if detail else str(err)
        cause = err if isinstance(err, BaseException) else None  # a status or log is no exception
        raise CoSimulationError(f"{unit.name}: {what} failed{when}: {reason}", unit.name, t,
                                list(self.log)) from cause

    # --- stepping ------------------------------------------------------------------
    @property
    def time(self) -> float:
        """Current communication point t_k [s] (t0 + k h on the default clock)."""
        return self.clock.at(self.k)

    @property
    def perturbed_inputs(self) -> dict:
        """{"element.variable": array of the values set at that perturbed input (options.perturb), one per
        macro step taken: the connection's value plus the perturbation, as the FMU stepped with it}."""
        return perturbation.applied(self._offsets)

    def row(self) -> list[float]:
        """Time and every FMU's outputs at the current communication point."""
        out = [self.time]
        for unit in self._row_units:
            out += unit.out[:]
        return out

    def step(self) -> None:
        """One macro step from t_k to t_{k+1} (t0 + k h to t0 + (k + 1) h on the default clock).

        The hot path: 10,000 calls per simulated second. Each FMI call is a direct ctypes
        call that returns its fmi2Status; like the Reference FMUs' CALL pattern, the worst
        status so far is kept call by call and the step stops at the first call above
        fmi2Warning (a failed fmi2SetReal means no doStep on stale inputs); the log is only
        scanned when it grew.
        """
        t, h = self.clock.at(self.k), self.clock.step(self.k)
        if self.event_mode:
            return self._step_events(t, h)
        for offsets in self._offsets:  # the macro step the perturbed inputs add their value of
            offsets.k, offsets.t = self.k, t
        self._substep(t, h)
        self.k += 1
        self._check_outputs(self.clock.at(self.k))

    def _substep(self, t: float, h: float) -> None:
        """Exchange the values and step every FMU from t by h [s] in the planned ordering."""
        n_log = len(self.log)
        if self.ordering == "gauss-seidel":
            for unit in self._step_units:
                status = unit.apply_inputs()
                if status > 1 or len(self.log) != n_log:
                    self._step_failed(unit, t, n_log, status)
                status = max(status, unit.do_step(t, h))
                if status > 1 or len(self.log) != n_log:
                    self._step_failed(unit, t, n_log, status)
                status = max(status, unit.read_outputs())
                if status > 1 or len(self.log) != n_log:
                    self._step_failed(unit, t, n_log, status)
        else:
            units = self._step_units
            worst = [0] * len(units)  # per unit, the worst status of its calls in this step
            for i, unit in enumerate(units):
                status = worst[i] = unit.apply_inputs()
                if status > 1 or len(self.log) != n_log:
                    self._step_failed(unit, t, n_log, status)
            for i, unit in enumerate(units):
                status = worst[i] = max(worst[i], unit.do_step(t, h))
                if status > 1 or len(self.log) != n_log:
                    self._step_failed(unit, t, n_log, status)
            for i, unit in enumerate(units):
                status = max(worst[i], unit.read_outputs())
                if status > 1 or len(self.log) != n_log:
                    self._step_failed(unit, t, n_log, status)

    def _step_events(self, t: float, h: float) -> None:
        """One macro step in event mode (module docstring): the events due at t first, then sub-steps
        that end at each event inside the step, each followed by its event, up to t_{k+1}."""
        end = self.clock.at(self.k + 1)
        tol = max(1e-12, 8.0 * (math.nextafter(abs(end), math.inf) - abs(end)))  # ulps between two clocks
        self._handle_events(t)
        now = t
        while True:
            next_event = min((u.next_event for u in self._event_units), default=math.inf)
            inside = next_event < end - tol
            target = next_event if inside else end
            # from t_k the step is h as without events, so a run whose events fall on its grid is the same
            self._substep(now, h if now == t and not inside else target - now)
            for unit in self._event_units:
                early = unit.returned_early()
                if early is not None and early < target - tol:
                    self._early_return(unit, early, target)
            now = target
            if not inside:
                break
            self._check_outputs(now)
            self._handle_events(now)
        self.k += 1
        self._check_outputs(self.clock.at(self.k))

    def _early_return(self, unit: Unit, early: float, target: float) -> None:
        """Raise for ``unit``'s doStep that returned early at ``early`` [s] before ``target`` [s]."""
        raise CoSimulationError(
            f"{unit.name}: doStep returned early at t = {early:.9g} s, before t = {target:.9g} s, a "
            "time it did not announce as nextEventTime: the other FMUs have stepped past it (allowed "
            "is an FMU whose events are the time events it announces)", unit.name, early, list(self.log))

    def _handle_events(self, t: float) -> None:
        """The event FMUs whose last doStep asked for event handling, in the step order: enter Event
        Mode, inputs from the outputs at t [s], update, outputs, back to Step Mode."""
        tol = max(1e-12, 8.0 * (math.nextafter(abs(t), math.inf) - abs(t)))  # as _step_events's
        for unit in self._event_units:
            tick = unit.tick_due(t, tol)
            if not (unit.event_needed() or tick):
                continue
            unit._flags[0].value = False  # handled
            self._call(unit, unit.slave.enterEventMode, "enterEventMode", t)
            if tick:
                self._call(unit, unit.tick, "setClock", t)
            self._call(unit, unit.apply_inputs, "setFloat64", t)
            self._call(unit, unit.update_discrete_states, "updateDiscreteStates", t)
            self._call(unit, unit.read_outputs, "getFloat64", t)
            self._call(unit, unit.slave.enterStepMode, "enterStepMode", t)

    def _check_clocks(self) -> None:
        """Refuse, before anything is instantiated, an FMU with input clocks that the run cannot tick: without
        event_mode (FMI 3.0: clocks tick only in Event Mode), or clocks that are not periodic."""
        for unit in self.units.values():
            if not unit.clocks:
                continue
            names = ", ".join(v.name for v in unit.clocks)
            if not self.event_mode:
                raise CoSimulationError(
                    f"event_mode = false is invalid for SSP file {self.ssp_path}: the FMU {unit.md.modelName} of "
                    f"element {unit.name} has the input clock(s) {names}, which tick only in Event Mode: allowed "
                    "is event_mode = true", unit.name)
            refused = unit.clock_kinds_refused()
            if refused:
                raise CoSimulationError(
                    f"SSP file {self.ssp_path}: the FMU {unit.md.modelName} of element {unit.name} has the input "
                    f"clock(s) {', '.join(refused)}, which are not periodic: allowed are input clocks with "
                    "intervalVariability constant or fixed (the master ticks them at t0 + shift + k interval)",
                    unit.name)

    def _start_clocks(self, unit: Unit) -> None:
        """At the start time, in the Event Mode after initialization: the clocks' interval and shift, and the
        tick at t0 if they tick there (shift 0)."""
        self._call(unit, lambda: unit.start_clocks(self.t0), "getIntervalDecimal", self.t0)
        if unit.tick_due(self.t0, 0.0):
            self._call(unit, unit.tick, "setClock", self.t0)

    def advance(self, rows) -> int:
        """Step ``len(rows)`` times, storing :meth:`row` after each step into ``rows`` (a
        C-contiguous float64 array, one row per step, len(:attr:`columns`) wide); returns the
        rows stored. Compiled core or Python loop (:attr:`stepper`), same rows to the bit; a
        failure raises what :meth:`step` raises, after setting :attr:`filled` to the rows
        stored before it."""
        self.filled = 0
        try:  # before any step, the same in both loops: the compiled core's int64 clock must not wrap
            self.clock.require_steps(self.k + len(rows))
        except ValueError as err:
            raise CoSimulationError(str(err)) from None
        if self._core is None:  # the reference loop
            for i in range(len(rows)):
                self.step()
                rows[i] = self.row()
                self.filled = i + 1
            return self.filled
        if rows.dtype != c_double or not rows.flags.c_contiguous or rows.shape[1:] != (len(self.columns),):
            raise ValueError(f"rows must be a C-contiguous float64 array of {len(self.columns)} columns, "
                             f"not {rows.dtype} {rows.shape}")  # the C core writes into its memory
        while self.filled < len(rows):
            s = self._core.advance(self.k, rows[self.filled:], len(rows) - self.filled)
            self.filled += s.rows
            self.k = s.k
            if s.outcome == stepper_core.SUSPECT_OUTPUT and not s.mid:
                self._check_outputs(self.time)  # raises as step() does, unless only the C check was stricter
                rows[self.filled] = self.row()
                self.filled += 1
            elif s.outcome != stepper_core.DONE:
                self.raise_outcome(s)
        return self.filled

    def compiled_core(self, why: str):
        """The compiled stepping core this co-simulation steps with; CoSimulationError naming ``why``
        (what needs it) if it steps in Python."""
        if self._core is None:
            reason = ("a Model Exchange FMU steps in Python" if self.model_exchange else
                      "the inputs are perturbed" if self._offsets else
                      "TAPMP_STEPPER or stepper = 'python'" if self.stepper == "python" else
                      "it is unavailable on this machine")
            raise CoSimulationError(f"{why} needs the compiled stepping core, and this run steps in Python "
                                    f"({reason})")
        return self._core

    def raise_outcome(self, s) -> None:
        """Raise what :meth:`step` raises for the compiled core's failed outcome ``s`` (its state, after
        :attr:`k` was set to s.k); a SUSPECT_OUTPUT that the Python check accepts raises too."""
        if s.outcome == stepper_core.SUSPECT_OUTPUT and s.mid:
            # at an event inside the macro step: the C check is the Python check, value by value
            self._check_outputs(s.t)
            raise CoSimulationError(f"the compiled core stopped at t = {s.t:.9g} s on outputs that the "
                                    "Python check accepts")
        elif s.outcome == stepper_core.SUSPECT_OUTPUT:
            self._check_outputs(self.time)
            raise CoSimulationError(f"the compiled core stopped at t = {self.time:.9g} s on outputs that the "
                                    "Python check accepts")
        elif s.outcome == stepper_core.FAIL_EVENT:
            unit = self._row_units[s.unit]
            what, function = stepper_core.EVENT_CALLS[s.call]
            err = None
            if s.status > 1:  # as fmpy raises, or as _call words a returned status
                err = (FMICallException(function, s.status) if function else
                       f"status {_STATUS[s.status] if s.status < 6 else s.status}")
            self._fail(unit, what, s.t, err)
        elif s.outcome == stepper_core.EARLY_RETURN:
            self._early_return(self._row_units[s.unit], s.early, s.target)
        elif s.outcome == stepper_core.NOT_SETTLED:
            unit = self._row_units[s.unit]
            raise unit.not_settled_error()
        elif s.outcome == stepper_core.FAIL_CALL:
            unit, t = self._row_units[s.unit], s.t
            self._step_failed(unit, t, s.n_log, s.status)
            raise CoSimulationError(f"{unit.name}: {stepper_core.CALLS[s.call]} failed at t = {t:.6g} s: "
                                    f"status {_STATUS[s.status] if 0 <= s.status < 6 else s.status}",
                                    unit.name, t, list(self.log))

    def _check_outputs(self, t: float) -> None:
        """Raise DivergenceError if an output is not finite or leaves a bound of :attr:`check`."""
        for unit in self._row_units:
            if not math.isfinite(sum(unit.out)):  # one sum per unit on the fast path
                for name, value in zip(unit.outputs, unit.out):
                    if not math.isfinite(value):
                        signal = f"{unit.name}.{name}"
                        raise DivergenceError(self.check.not_finite(signal, value, t), unit.name, t, signal,
                                              value, list(self.log))
        for out, i, column, limit, element in self._bounds:
            value = out[i]
            if not -limit <= value <= limit:
                raise DivergenceError(self.check.breach(column, value, limit, t), element, t, column,
                                      value, list(self.log))

    def _step_failed(self, unit: Unit, t: float, n_log: int, status: int) -> None:
        """Raise for a failed step of ``unit``: ``status`` (the worst status of its calls so far) above
        fmi2Warning or an error logged since ``n_log``; return if it only logged non-errors."""
        errors = any(m.startswith(("[ERROR]", "[FATAL]")) for m in self.log[n_log:])
        if errors:
            self._fail(unit, "doStep", t, None)
        if status > 1:
            self._fail(unit, "doStep", t, f"a call returned {_STATUS[status] if status < 6 else status}, "
                       "above fmi2Warning")

    # --- teardown ------------------------------------------------------------------
    def close(self) -> None:
        """Terminate and free every instance and delete the extracted files, or, with ``loaded``,
        reset every instance and give the system back to it; idempotent."""
        system, self._system = self._system, None
        self.units = {}
        self.tmp = None
        if system is None:
            return
        system.target = None
        if self.loaded is None or self.model_exchange:
            system.close()
        else:
            self.loaded.give(system)
