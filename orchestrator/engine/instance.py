"""One FMU instance of a co-simulation (FMI 2.0 or 3.0 co-simulation, loaded by fmpy): its
outputs cached in a ctypes array, its input connections, and the FMI calls of one step made
directly through ctypes with arrays built once (fmpy's getReal/setReal wrappers build new
arrays and lists on every call). The compiled stepping core reads the same arrays.
"""

import math
from ctypes import byref, c_bool, c_double, c_int, c_uint
from pathlib import Path

from fmpy import read_model_description
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave

from .archive import ExtractBudget, extract_archive
from .errors import CoSimulationError

_DESCRIPTIONS = {}  # sha-1 of an FMU archive -> its parsed modelDescription (read-only)


def _model_description(fmu_path: Path):
    """fmpy's read_model_description, parsed once per process for each FMU content: a study
    worker runs the same FMUs case after case (parsing costs ~15 ms per FMU)."""
    import hashlib
    key = hashlib.sha1(Path(fmu_path).read_bytes()).hexdigest()
    md = _DESCRIPTIONS.get(key)
    if md is None:
        md = read_model_description(str(fmu_path))
        if len(_DESCRIPTIONS) >= 64:
            _DESCRIPTIONS.clear()
        _DESCRIPTIONS[key] = md
    return md


class Unit:
    """One FMU instance in the system, its cached outputs and its input connections.

    The hot path calls the FMU's C functions directly with ctypes arrays built once
    (fmpy's getReal/setReal wrappers build new arrays and lists on every call).
    """

    def __init__(self, name: str, fmu_path: Path, unzip_dir: Path, log: list, budget=None, where: str = "",
                 extract: bool = True):
        self.name = name
        # extracted first, counted against ``budget`` (archive.ExtractBudget): a member's size is
        # checked before modelDescription.xml is read into memory; extract=False: ``unzip_dir``
        # holds the FMU extracted already (an FMU loaded again after its instance was freed)
        if extract:
            extract_archive(fmu_path, unzip_dir, budget or ExtractBudget(), where or f"FMU {fmu_path}")
        self.md = _model_description(fmu_path)
        self.fmi3 = self.md.fmiVersion.startswith("3")
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.log = log
        slave_type = FMU3Slave if self.fmi3 else FMU2Slave
        self.slave = slave_type(guid=self.md.guid, unzipDirectory=str(unzip_dir),
                                modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=name)
        self.outputs = [v.name for v in self.md.modelVariables if v.causality == "output"]
        inputs = [v.name for v in self.md.modelVariables if v.causality == "input"]
        # {output: inputs it depends on directly}; an output without declared dependencies
        # depends on every input (FMI 2.0 and 3.0 ModelStructure rules).
        self.feedthrough = {o: frozenset(inputs) for o in self.outputs}
        for u in self.md.outputs:
            if u.dependencies is not None:
                self.feedthrough[u.variable.name] = frozenset(d.name for d in u.dependencies
                                                              if d.causality == "input")
        self.n_out = len(self.outputs)
        self.out_vrs = (c_uint * self.n_out)(*(self.vars[n].valueReference for n in self.outputs))
        self.out = (c_double * self.n_out)()   # outputs at the last communication point
        self.sources = []                      # (source unit, index in source.out) per input
        self.in_vrs = self.inp = None
        self.n_in = 0
        self.offsets = None                    # perturbation.Offsets of its perturbed inputs, if any
        self.instantiated = False
        # FMI 3.0 Event Mode (hasEventMode): the master may instantiate with eventModeUsed
        self.has_event_mode = self.fmi3 and bool(getattr(self.md.coSimulation, "hasEventMode", False))
        self.event_mode = False       # instantiated with eventModeUsed (and earlyReturnAllowed)
        self.next_event = math.inf    # its next time event [s] (nextEventTime), inf if none
        self.n_events = 0             # events handled (fmi3UpdateDiscreteStates rounds that settled)
        # FMI 3.0 input clocks, periodic with a constant or fixed interval: the master ticks them
        # (start_clocks, tick_due, tick); any other clock is refused by the master (clock_kinds_refused)
        self.clocks = [v for v in self.md.modelVariables if v.type == "Clock" and v.causality == "input"]
        self.clock_vrs = [v.valueReference for v in self.clocks]
        self.clock_t0 = self.clock_interval = math.nan
        self.clock_k = 0              # the index of the next tick, at clock_t0 + clock_k * clock_interval
        dll = self.slave.dll
        if self.fmi3:
            self._get_real, self._set_real, self._do_step3 = dll.fmi3GetFloat64, dll.fmi3SetFloat64, dll.fmi3DoStep
            self._flags = [c_bool(), c_bool(), c_bool()]  # eventHandlingNeeded, terminate, earlyReturn
            self._last_time = c_double()
            self._step_out = (*(byref(f) for f in self._flags), byref(self._last_time))
        else:
            self._get_real, self._set_real, self._do_step = dll.fmi2GetReal, dll.fmi2SetReal, dll.fmi2DoStep

    def instantiate(self, callbacks, log_message, event_mode: bool = False) -> None:
        """fmi2Instantiate with the master's ``callbacks``, or fmi3InstantiateCoSimulation with
        ``log_message(instance, status, category, message)`` (FMI 3 logs carry no instance name);
        ``event_mode``: eventModeUsed and earlyReturnAllowed (an FMU with hasEventMode only)."""
        if self.fmi3:
            name = self.name.encode()
            self.event_mode = event_mode and self.has_event_mode
            self.slave.instantiate(loggingOn=True, eventModeUsed=self.event_mode,
                                   earlyReturnAllowed=self.event_mode,
                                   logMessage=lambda env, status, category, message:
                                   log_message(None, name, status, category, message))
        else:
            self.slave.instantiate(callbacks=callbacks, loggingOn=True)

    def reset(self) -> int:
        """fmi2Reset (fmi3Reset) of the instance: back to the state right after instantiation,
        every variable at its start value; returns the status."""
        if self.fmi3:
            return self.slave.dll.fmi3Reset(self.slave.component)
        return self.slave.dll.fmi2Reset(self.slave.component)

    def prepare_reuse(self) -> None:
        """Forget the connections and events of the last co-simulation (after :meth:`reset`), so
        that the next one connects and steps this instance as a new one."""
        self.sources = []
        self.in_vrs = self.inp = None
        self.n_in = 0
        self._copies = ()
        self.offsets = None
        self.next_event = math.inf
        self.n_events = 0
        self.clock_t0 = self.clock_interval = math.nan
        self.clock_k = 0
        if self.fmi3:
            for flag in self._flags:
                flag.value = False
            self._last_time.value = 0.0

    def enter_initialization(self, start_time: float) -> None:
        """fmi2SetupExperiment + fmi2EnterInitializationMode, or fmi3EnterInitializationMode."""
        if self.fmi3:
            self.slave.enterInitializationMode(startTime=start_time)
        else:
            self.slave.setupExperiment(startTime=start_time)
            self.slave.enterInitializationMode()

    def connect(self, source: "Unit", output: str, input_vr: int) -> None:
        """Feed this unit's input ``input_vr`` from ``source``'s output ``output``."""
        self.sources.append((source, source.outputs.index(output), input_vr))
        self.n_in = len(self.sources)
        self.in_vrs = (c_uint * self.n_in)(*(vr for _, _, vr in self.sources))
        self.inp = (c_double * self.n_in)()

    def finish_connections(self) -> None:
        """Bind the connection table for the hot path (after all units are instantiated)."""
        self._copies = tuple((j, src.out, i) for j, (src, i, _) in enumerate(self.sources))

    def read_outputs(self) -> int:
        """fmi2GetReal (fmi3GetFloat64) of every output into :attr:`out`; returns the status."""
        if self.fmi3:
            return self._get_real(self.slave.component, self.out_vrs, self.n_out, self.out, self.n_out)
        return self._get_real(self.slave.component, self.out_vrs, self.n_out, self.out)

    def apply_inputs(self) -> int:
        """Copy the sources' outputs into the inputs and fmi2SetReal them; the fmi2Status."""
        if not self.n_in:
            return 0
        inp = self.inp
        for j, src, i in self._copies:
            inp[j] = src[i]
        if self.offsets is not None:  # an input perturbation (perturbation.py)
            self.offsets.add(inp)
        if self.fmi3:
            return self._set_real(self.slave.component, self.in_vrs, self.n_in, inp, self.n_in)
        return self._set_real(self.slave.component, self.in_vrs, self.n_in, inp)

    def do_step(self, t: float, h: float) -> int:
        """fmi2DoStep(t, h) (fmi3DoStep); returns the status."""
        if self.fmi3:
            return self._do_step3(self.slave.component, t, h, True, *self._step_out)
        return self._do_step(self.slave.component, t, h, 1)

    def event_needed(self) -> bool:
        """The last fmi3DoStep said eventHandlingNeeded."""
        return self.event_mode and self._flags[0].value

    def returned_early(self) -> float | None:
        """The time [s] the last fmi3DoStep stopped at if it returned early (earlyReturn), else None."""
        return self._last_time.value if self.event_mode and self._flags[2].value else None

    def update_discrete_states(self) -> None:
        """In Event Mode: fmi3UpdateDiscreteStates until the FMU needs no further update (at most
        100 rounds), keeping its nextEventTime in :attr:`next_event` (inf if it defines none)."""
        for _ in range(100):
            again, _terminate, _, _, defined, next_time = self.slave.updateDiscreteStates()
            self.next_event = next_time if defined else math.inf
            if self.clocks:  # the next tick of the clocks, as the FMU's grid t0 + k T_s computes it
                self.next_event = min(self.next_event, self.clock_t0 + self.clock_k * self.clock_interval)
            if not again:
                self.n_events += 1
                return
        raise self.not_settled_error()

    def not_settled_error(self) -> CoSimulationError:
        """The error of discrete states that still need an update after 100 rounds (the compiled core's too)."""
        return CoSimulationError(f"{self.name}: fmi3UpdateDiscreteStates still needs another update after 100 "
                                 "rounds: allowed is an FMU whose discrete states settle", self.name)

    def clock_kinds_refused(self) -> list[str]:
        """The names of the input clocks the master cannot tick: every one that is not periodic with a
        constant or fixed interval (those tick at t0 + shift + k interval)."""
        return [v.name for v in self.clocks if v.intervalVariability not in ("constant", "fixed")]

    def start_clocks(self, t0: float) -> None:
        """After initialization: the clocks' interval and shift [s] (fmi3GetIntervalDecimal, fmi3GetShiftDecimal;
        one interval for all: the master ticks them together), the first tick at t0 + shift."""
        n = len(self.clock_vrs)
        vrs = (c_uint * n)(*self.clock_vrs)
        intervals, qualifiers, shifts = (c_double * n)(), (c_int * n)(), (c_double * n)()
        self.slave.getIntervalDecimal(vrs, intervals, qualifiers)
        self.slave.getShiftDecimal(vrs, shifts)
        if len(set(intervals)) != 1 or len(set(shifts)) != 1 or not (intervals[0] > 0.0):
            raise CoSimulationError(f"{self.name}: input clocks {', '.join(v.name for v in self.clocks)} with "
                                    f"intervals {list(intervals)} s and shifts {list(shifts)} s: allowed are clocks "
                                    "that tick together (one interval > 0, one shift)", self.name)
        self.clock_t0 = t0 + shifts[0] if shifts[0] else t0  # t0 itself, as the FMU's own grid t0 + k T_s
        self.clock_interval = intervals[0]
        self.clock_k = 0
        self.next_event = self.clock_t0

    def tick_due(self, t: float, tol: float) -> bool:
        """Whether the clocks tick at t [s] (within tol [s]): t is the next tick."""
        return bool(self.clocks) and abs(t - self.next_event) <= tol

    def tick(self) -> None:
        """In Event Mode at a tick: activate every clock (fmi3SetClock); the next tick becomes :attr:`next_event`
        once the update is done (:meth:`update_discrete_states`)."""
        self.slave.setClock(self.clock_vrs, [True] * len(self.clock_vrs))
        self.clock_k += 1

    def set_parameter(self, name: str, value) -> None:
        var = self.vars.get(name)
        if var is None or var.causality != "parameter":
            allowed = sorted(v.name for v in self.vars.values() if v.causality == "parameter")
            raise CoSimulationError(f"{self.name}.{name} is not a parameter of {self.md.modelName}: "
                                    f"allowed are {', '.join(allowed)}", self.name)
        if var.type == "Boolean":
            if not isinstance(value, bool) and value not in (0, 1):
                raise CoSimulationError(f"{self.name}.{name} = {value!r} is invalid: allowed is a boolean",
                                        self.name)
            self.slave.setBoolean([var.valueReference], [bool(value)])  # FMI 2.0 and 3.0 alike in fmpy
        elif var.type in ("Integer", "Int32"):
            if int(value) != value:
                raise CoSimulationError(f"{self.name}.{name} = {value!r} is invalid: allowed is an integer",
                                        self.name)
            if self.fmi3:
                self.slave.setInt32([var.valueReference], [int(value)])
            else:
                self.slave.setInteger([var.valueReference], [int(value)])
        elif self.fmi3:
            self.slave.setFloat64([var.valueReference], [float(value)])
        else:
            self.slave.setReal([var.valueReference], [float(value)])
