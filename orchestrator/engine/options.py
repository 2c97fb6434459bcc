"""The options of a co-simulation: how the master (master.CoSimulation) steps an SSP system.

One frozen record with a default for each, so that a caller names only what it changes; the master
checks the values when the co-simulation is made (CoSimulationError naming the option, the value
and what is allowed).
"""

from collections.abc import Mapping
from dataclasses import dataclass, field

from .model_exchange import DEFAULT_TOLERANCE as DEFAULT_ME_TOLERANCE


class OutputCheck:
    """The per-step check of the recorded outputs that the caller supplies (``check`` of
    :class:`RunOptions`; TAPMP's platform envelope: orchestrator.tool.envelope).

    :attr:`bounds` is data, so that the compiled core checks it too: (column, limit) pairs,
    |value| <= limit in the column's unit after every step. :meth:`breach` and
    :meth:`not_finite` word the DivergenceError. This base class bounds nothing."""

    bounds: tuple = ()

    def breach(self, column: str, value: float, limit: float, t: float) -> str:
        """The message of ``column`` = ``value`` outside |column| <= ``limit`` at ``t`` [s]."""
        return f"{column} = {value:.6g} at t = {t:.6g} s is outside |{column}| <= {limit:g}"

    def not_finite(self, column: str, value: float, t: float) -> str:
        """The message of a non-finite output ``column`` = ``value`` at ``t`` [s]."""
        return f"{column} = {value!r} at t = {t:.6g} s is not finite: the co-simulation diverged"


@dataclass(frozen=True)
class RunOptions:
    """How a co-simulation steps (the conventions are those of master.py's module docstring)."""

    start_time: float = 0.0
    """t0 [s]: the time of step 0."""
    step_size: float = 1e-4
    """h [s]: the communication step, > 0; step k is at t0 + k h (see ``clock``)."""
    ordering: str = "gauss-seidel"
    """``gauss-seidel`` (one element after the other) or ``jacobi`` (all at once from the outputs at t)."""
    order: tuple[str, ...] | None = None
    """Gauss-Seidel only: every element once, in the order they step; None: the order from the graph
    (orchestrator.engine.schedule)."""
    clock: str = "exact"
    """How t_k and h_k are computed (orchestrator.engine.clocks): ``exact`` (t0 + k h), ``accumulated``
    (FMPy, Ecos) or ``nanoseconds`` (libcosim)."""
    connection_start: str = "propagated"
    """``propagated`` (outputs propagated in Initialization Mode) or ``zero`` (every connection at 0
    until the first step, as FMPy's simulate_ssp)."""
    stepper: str | None = None
    """``auto``, ``compiled`` or ``python``: the stepping loop; None: $TAPMP_STEPPER, else ``auto``."""
    event_mode: bool = False
    """FMI 3.0: FMUs with hasEventMode run with Event Mode, the macro step cut at every event."""
    check: OutputCheck | None = None
    """The per-step check of the recorded outputs (e.g. TAPMP's platform envelope); None: every
    output finite, no bound."""
    roles: Mapping[str, str] = field(default_factory=dict)
    """{role: modelName}: a role addresses the one element whose FMU is that model (in the parameters)
    and names its columns (ssd.column_prefixes)."""
    open_inputs: tuple[str, ...] = ()
    """FMU inputs ("element.variable") that no connection drives: they keep their start values."""
    other_tables: tuple[str, ...] = ()
    """Further names offered when a parameter table addresses nothing."""
    model_exchange: tuple[str, ...] = ()
    """Elements (or roles) whose FMU runs as Model Exchange, integrated by the master with CVODE
    between communication points (orchestrator.engine.model_exchange)."""
    me_tolerance: float = DEFAULT_ME_TOLERANCE
    """CVODE's relative tolerance [1] for the Model Exchange elements."""
    perturb: Mapping[str, object] = field(default_factory=dict)
    """{"element.variable": values}: added to what the connection delivers to that input at every macro step, a
    sequence (one value per step) or a callable of t [s] (orchestrator.engine.perturbation); runs in the Python loop."""
