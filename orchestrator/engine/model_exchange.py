"""A Model Exchange FMU in the co-simulation (FMI 2.0 or 3.0, loaded by fmpy): the master integrates
its continuous state itself between communication points, so that the FMU acts as a co-simulation
unit to the rest of the system (``CoSimulation(..., RunOptions(model_exchange=...))``; the TAPMP scenario key
``plant_interface = "me"``).

The integrator is SUNDIALS' CVODE (BDF with Newton iterations on a dense Jacobian, fmpy.sundials), with
the relative tolerance ``tolerance`` and the absolute tolerance ``tolerance`` x each state's nominal.
Why CVODE and not RK4 at the macro step: RK4 at the macro step is the Co-Simulation plant's own
integrator, so the closed loop would only repeat it; a variable-step, error-controlled integrator at a
tight tolerance is what Simulink, Dymola and OMSimulator do with a Model Exchange FMU, and it checks
the RK4 plant independently.

The inputs are held over a macro step (zero-order hold, as a co-simulation FMU sees them), so the
right-hand side jumps at every communication point: CVODE is re-initialized there (CVodeReInit) and
never steps past the end of the macro step (CVodeSetStopTime). A time event of the FMU
(nextEventTime, e.g. the plant's external force step at disturbance_time) inside a macro step ends an
integration there: Event Mode, the event update, Continuous-Time Mode, and CVODE starts again. State
events (event indicators) are located by CVODE's root finding and handled the same way.
"""

import math
from ctypes import c_double, c_int, c_void_p

from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Model
from fmpy.fmi3 import FMU3Model

from .errors import CoSimulationError
from .instance import Unit

# CVODE's relative tolerance: tight, so that the run checks the RK4 plant (in the paper's closed loop
# its error is ~1e-7 of a state's range over 0.05 s); 1e-10 costs as much
DEFAULT_TOLERANCE = 1e-12


def _cvode_set_stop_time():
    """CVodeSetStopTime of fmpy's SUNDIALS library (fmpy binds the library, not this function)."""
    from fmpy.sundials.libraries import sundials_cvode
    f = sundials_cvode.CVodeSetStopTime
    f.argtypes, f.restype = [c_void_p, c_double], c_int
    return f


class ModelExchangeUnit(Unit):
    """``unit`` (a :class:`Unit` of an FMU that offers Model Exchange) instantiated for Model Exchange
    and integrated by CVODE at the relative tolerance ``tolerance`` over each :meth:`do_step`.

    It replaces ``unit`` before the connections are made and keeps its variables, outputs and
    arrays, so the master exchanges values with it as with any unit."""

    def __init__(self, unit: Unit, tolerance: float = DEFAULT_TOLERANCE):
        self.__dict__.update(unit.__dict__)
        me = self.md.modelExchange
        if me is None:
            raise CoSimulationError(f"{self.name}: {self.md.modelName} offers no Model Exchange interface: allowed "
                                    "are FMUs whose modelDescription.xml has <ModelExchange> (the native plant, "
                                    "build/native/fmi2 or fmi3)", self.name)
        model_type = FMU3Model if self.fmi3 else FMU2Model
        self.slave = model_type(guid=self.md.guid, unzipDirectory=unit.slave.unzipDirectory,
                                modelIdentifier=me.modelIdentifier, instanceName=self.name)
        dll = self.slave.dll
        prefix = "fmi3" if self.fmi3 else "fmi2"
        self._get_real = dll.fmi3GetFloat64 if self.fmi3 else dll.fmi2GetReal
        self._set_real = dll.fmi3SetFloat64 if self.fmi3 else dll.fmi2SetReal
        self._set_time = getattr(dll, f"{prefix}SetTime")
        self._set_states = getattr(dll, f"{prefix}SetContinuousStates")
        self._get_states = getattr(dll, f"{prefix}GetContinuousStates")
        self._get_derivatives = dll.fmi3GetContinuousStateDerivatives if self.fmi3 else dll.fmi2GetDerivatives
        self._get_indicators = getattr(dll, f"{prefix}GetEventIndicators")
        self._get_nominals = getattr(dll, f"{prefix}GetNominalsOfContinuousStates")
        self.has_event_mode = self.event_mode = False  # Co-Simulation's Event Mode: not this interface's
        self.nx = self.md.numberOfContinuousStates
        self.nz = self.md.numberOfEventIndicators
        self.needs_completed_step = not getattr(me, "completedIntegratorStepNotNeeded", False) if not self.fmi3 \
            else bool(getattr(me, "needsCompletedIntegratorStep", False))
        self.tolerance = float(tolerance)
        self.solver = None
        self.n_reinit = 0          # CVODE restarts: one per macro step and per event
        self._status = 0           # the worst status of the FMU calls made inside CVODE's callbacks

    # --- life cycle ---------------------------------------------------------------------------
    def instantiate(self, callbacks, log_message, event_mode: bool = False) -> None:
        """fmi2Instantiate(fmi2ModelExchange) with the master's ``callbacks``, or
        fmi3InstantiateModelExchange logging through ``log_message``; ``event_mode`` does not apply."""
        if self.fmi3:
            name = self.name.encode()
            self.slave.instantiate(loggingOn=True, logMessage=lambda env, status, category, message:
                                   log_message(None, name, status, category, message))
        else:
            self.slave.instantiate(callbacks=callbacks, loggingOn=True)

    def enter_initialization(self, start_time: float) -> None:
        """Initialization Mode at ``start_time`` [s], the tolerance announced to the FMU."""
        if self.fmi3:
            self.slave.enterInitializationMode(tolerance=self.tolerance, startTime=start_time)
        else:
            self.slave.setupExperiment(tolerance=self.tolerance, startTime=start_time)
            self.slave.enterInitializationMode()

    def start_continuous(self, t0: float) -> None:
        """After ExitInitializationMode (the FMU is in Event Mode): the event iteration at ``t0`` [s],
        Continuous-Time Mode, and CVODE set up on the FMU's initial state."""
        from fmpy.sundials import CVodeSolver
        self._update_discrete_states(t0)
        self.slave.enterContinuousTimeMode()
        self.solver = CVodeSolver(
            nx=self.nx, nz=self.nz, get_x=self._cb_get_x, set_x=self._cb_set_x, get_dx=self._cb_get_dx,
            get_z=self._cb_get_z, get_nominals=self._cb_get_nominals, set_time=self._cb_set_time,
            input=_NoInput(), startTime=t0, relativeTolerance=self.tolerance, maxNumSteps=100000)
        self._stop_time = _cvode_set_stop_time()

    def _update_discrete_states(self, t: float) -> None:
        """Event Mode at ``t`` [s]: the discrete updates until the FMU needs none (at most 100), its next
        time event kept in :attr:`next_event` (inf if none)."""
        for _ in range(100):
            info = self.slave.updateDiscreteStates() if self.fmi3 else self.slave.newDiscreteStates()
            again, terminate, _nominals, _values, defined, next_time = info
            if terminate:
                raise CoSimulationError(f"{self.name}: the FMU asked to terminate the simulation at t = {t:.6g} s "
                                        "(terminateSimulation)", self.name, t)
            self.next_event = next_time if defined else math.inf
            if not again:
                self.n_events += 1
                return
        raise CoSimulationError(f"{self.name}: the event update at t = {t:.6g} s still needs another update after "
                                "100 rounds: allowed is an FMU whose discrete states settle", self.name, t)

    def _event(self, t: float) -> None:
        """An event at ``t`` [s]: Event Mode, the update, Continuous-Time Mode; CVODE restarts there."""
        self.slave.enterEventMode()
        self._update_discrete_states(t)
        self.slave.enterContinuousTimeMode()
        self._restart(t)

    def _restart(self, t: float) -> None:
        self.solver.reset(t)
        self.n_reinit += 1

    # --- CVODE's callbacks: direct FMI calls, their worst status kept (an exception in a ctypes
    # callback would be lost) ---------------------------------------------------------------------
    def _keep(self, status: int) -> None:
        if status > self._status:
            self._status = status

    def _cb_set_time(self, t):
        self._keep(self._set_time(self.slave.component, t))

    def _cb_get_x(self, x, nx):
        self._keep(self._get_states(self.slave.component, x, nx))

    def _cb_set_x(self, x, nx):
        self._keep(self._set_states(self.slave.component, x, nx))

    def _cb_get_dx(self, dx, nx):
        self._keep(self._get_derivatives(self.slave.component, dx, nx))

    def _cb_get_z(self, z, nz):
        self._keep(self._get_indicators(self.slave.component, z, nz))

    def _cb_get_nominals(self, x, nx):
        self._keep(self._get_nominals(self.slave.component, x, nx))

    # --- the macro step -----------------------------------------------------------------------
    def do_step(self, t: float, h: float) -> int:
        """Integrate from ``t`` to ``t + h`` [s] with the inputs set now held; the FMU is left at
        t + h with the state CVODE reached, so its outputs are those at t + h. Returns the worst
        status of the FMU's calls (an error: the FMU logged why)."""
        self._status = 0
        end = t + h
        tol = 1e-12 * max(1.0, abs(end))
        try:
            self._cb_set_time(t)
            self._restart(t)  # the inputs jumped at t (zero-order hold)
            now = t
            while now < end - tol and self._status <= 1:
                event_inside = self.next_event < end - tol
                target = self.next_event if event_inside else end
                self._stop_time(self.solver.cvode_mem, target)
                _, roots, reached = self.solver.step(now, target)
                if self._status > 1:
                    break
                state_event = self.nz > 0 and any(roots)  # fmpy's flag is also set at the stop time
                now = reached if state_event else target
                self._cb_set_time(now)
                if self.needs_completed_step:
                    enter_event, terminate = self.slave.completedIntegratorStep()
                    if terminate:
                        raise CoSimulationError(f"{self.name}: the FMU asked to terminate the simulation at t = "
                                                f"{now:.6g} s (terminateSimulation)", self.name, now)
                    state_event = state_event or enter_event
                if state_event or self.next_event <= now + tol:
                    self._event(now)
        except FMICallException as err:
            return max(self._status, int(err.status))
        except RuntimeError as err:  # CVODE's failure (fmpy.sundials raises RuntimeError)
            raise CoSimulationError(f"{self.name}: CVODE failed between t = {t:.6g} s and {end:.6g} s: {err}",
                                    self.name, t) from None
        return self._status


class _NoInput:
    """fmpy's CVodeSolver applies an input before each root function call; the master sets the inputs."""

    def apply(self, time):
        pass


def model_exchange_units(units: dict, entries, roles: dict, tolerance: float, where: str) -> list[str]:
    """Replace in ``units`` ({element: Unit}) the elements that ``entries`` name (element names, or role
    names of ``roles`` {role: modelName}) by :class:`ModelExchangeUnit` at ``tolerance``; returns the
    element names. CoSimulationError (one line) names an entry that is neither, or an FMU without
    Model Exchange. ``where`` names the system in messages."""
    if isinstance(entries, str) or not all(isinstance(e, str) for e in entries):
        raise CoSimulationError(f"model_exchange = {entries!r} is invalid: allowed is a list of element or role "
                                "names")
    if not (isinstance(tolerance, (int, float)) and 0.0 < tolerance < 1.0):
        raise CoSimulationError(f"me_tolerance = {tolerance!r} is invalid: allowed is a number in (0, 1)")
    names = []
    for entry in entries:
        if entry in units:
            name = entry
        else:
            model = roles.get(entry)
            matches = [n for n, u in units.items() if model is not None and u.md.modelName == model]
            if len(matches) != 1:
                allowed = sorted({*units, *(r for r, m in roles.items()
                                            if sum(u.md.modelName == m for u in units.values()) == 1)})
                raise CoSimulationError(f"model_exchange: {entry!r} is not an element of {where}: allowed are "
                                        f"{', '.join(allowed)}")
            name = matches[0]
        units[name] = ModelExchangeUnit(units[name], tolerance)
        names.append(name)
    return names

