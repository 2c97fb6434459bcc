"""An additive perturbation of FMU inputs (RunOptions.perturb): what a frequency-response
measurement injects into a closed loop, for any SSP.

At every macro step k (from t_k to t_k+1) the master adds d_k to the value the connection delivers
to each named input before it sets it, so the FMU steps with u_k = y_k + d_k, y_k the source's
output. d_k is ``values[k]`` of a precomputed sequence (nothing is added beyond its end) or
``values(t_k)`` of a callable (t_k [s], in the input's unit). Nothing is added in Initialization
Mode. The values actually set (u_k) are kept per step (CoSimulation.perturbed_inputs), so a caller
reads the plant input and the controller output y_k = u_k - d_k from the co-simulation itself.

An entry names its input "element.variable", the element by its SSP name or by a role of
RunOptions.roles. The compiled stepping core has no perturbation: a perturbed run steps in the
Python loop (the same FMI calls; ``stepper = "compiled"`` is refused), and not with event_mode
(an event inside a macro step would set the input again mid-step).
"""

import math

import numpy as np

from .errors import CoSimulationError


class Offsets:
    """The perturbed inputs of one unit: (index among its inputs, name, values) and the values set."""

    def __init__(self):
        self.entries = []   # (index in Unit.inp, "element.variable", sequence or callable)
        self.k = None       # the macro step being taken; None: not stepping (initialization)
        self.t = 0.0        # its time t_k [s]
        self.applied = {}   # name -> list of the values set, one per step

    def add(self, inp) -> None:
        """Add d_k to the inputs just copied from the sources (Unit.apply_inputs) and keep u_k."""
        if self.k is None:
            return
        for j, name, values in self.entries:
            if callable(values):
                d = float(values(self.t))
            else:
                d = float(values[self.k]) if self.k < len(values) else 0.0
            inp[j] += d
            self.applied[name].append(inp[j])


def check_values(name: str, values) -> object:
    """``values`` as the master uses them: a callable, or a 1-D float array of finite numbers;
    CoSimulationError naming the entry otherwise."""
    if callable(values):
        return values
    try:
        arr = np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        arr = None
    if arr is None or arr.ndim != 1 or not all(math.isfinite(x) for x in arr):
        raise CoSimulationError(f"perturb[{name!r}] = {type(values).__name__} is invalid: allowed is a callable of "
                                "t [s] or a 1-D sequence of finite numbers, one per macro step")
    return arr


def attach(units: dict, perturb, roles: dict, event_mode: bool, stepper: str, where: str) -> list:
    """Bind each entry of ``perturb`` ({"element.variable": values}) to its unit's input (after the
    connections are made); returns the units' Offsets. CoSimulationError for an entry that names no
    input of the system, with event_mode, or with the compiled stepper."""
    if not perturb:
        return []
    if event_mode:
        raise CoSimulationError("perturb is invalid with event_mode = true: allowed only without event mode (an "
                                "event inside a macro step would set the perturbed input again)")
    if stepper == "compiled":
        raise CoSimulationError("stepper = 'compiled' is unavailable with perturb: allowed are 'python' or 'auto' "
                                "(a perturbed run steps in the Python loop)")
    models = {n: u.md.modelName for n, u in units.items()}
    inputs = [f"{n}.{v}" for n, u in units.items() for v, x in u.vars.items() if x.causality == "input"]
    found = {}
    for name, values in perturb.items():
        element, _, variable = str(name).partition(".")
        if element not in units and element in roles:
            hits = [e for e, m in models.items() if m == roles[element]]
            element = hits[0] if len(hits) == 1 else element
        unit = units.get(element)
        var = unit.vars.get(variable) if unit is not None else None
        if var is None or var.causality != "input":
            raise CoSimulationError(f"perturb: {name!r} is not an input of the system in {where}: allowed are "
                                    f"{', '.join(inputs)} (or a role's name for its element)")
        index = [j for j, (_, _, vr) in enumerate(unit.sources) if vr == var.valueReference]
        if not index:
            raise CoSimulationError(f"perturb: {name!r} is driven by no connection in {where}: allowed are inputs "
                                    "that a connection drives (the perturbation is added to what it delivers)")
        if unit.offsets is None:
            unit.offsets = Offsets()
        unit.offsets.entries.append((index[0], str(name), check_values(str(name), values)))
        unit.offsets.applied[str(name)] = []
        found[unit.name] = unit.offsets
    return list(found.values())


def applied(offsets: list) -> dict:
    """{"element.variable": array of the values set at that input, one per macro step} of ``offsets``."""
    return {name: np.array(values) for o in offsets for name, values in o.applied.items()}
