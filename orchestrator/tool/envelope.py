"""TAPMP's platform envelope: the master's per-step output check built from a scenario.

The master (orchestrator.engine.master) checks that every output stays finite and that
the bounds of its :class:`~orchestrator.engine.master.OutputCheck` hold after every step,
in Python or in the compiled core. For the TAPMP system those bounds are the scenario's
``[limits]`` (scenario.LIMITS: |q_i| of every motor, |B| of the platform, 0 = off), and a
breach or a non-finite output points at the gains with the ``tapmp check`` hint.
"""

from ..engine.master import OutputCheck
from .scenario import LIMITS

HINT = ("hint: gains unstable at this step size? `tapmp check` tells before a run; "
        "use stable gains or a smaller step")
# Recorded columns per limit name (columns of an element with a TAPMP role carry the role's name).
SIGNALS = {"motor_travel": [f"plant.q{i}_true" for i in (1, 2, 3)], "platform_angle": ["plant.B"]}


class Envelope(OutputCheck):
    """The bounds |column| <= limit of ``limits`` ({limit name: value in its LIMITS unit},
    0 = off), in the order of ``limits`` and SIGNALS (the first breach found is reported)."""

    def __init__(self, limits: dict):
        unknown = set(limits) - set(SIGNALS)
        if unknown:
            raise ValueError(f"limits {', '.join(sorted(unknown))} unknown: allowed are {', '.join(SIGNALS)}")
        self.bounds = tuple((column, float(limit)) for key, limit in limits.items() if limit > 0.0
                            for column in SIGNALS[key])
        self._limit_of = {column: key for key in limits for column in SIGNALS[key]}

    def breach(self, column: str, value: float, limit: float, t: float) -> str:
        key = self._limit_of[column]
        unit = LIMITS[key][1]
        return (f"{column} = {value:.6g} {unit} at t = {t:.6g} s is outside the envelope |{column}| <= "
                f"{limit:g} {unit} (limits.{key}): the closed loop is diverging; {HINT}")

    def not_finite(self, column: str, value: float, t: float) -> str:
        return f"{super().not_finite(column, value, t)}; {HINT}"


def envelope(scenario) -> Envelope:
    """The platform envelope of ``scenario`` (its limit_values)."""
    return Envelope(scenario.limit_values())
