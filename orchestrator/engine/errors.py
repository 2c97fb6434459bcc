"""The errors of a co-simulation: where and when it failed, and the FMUs' log up to then."""

from ..errors import UserError


class CoSimulationError(RuntimeError, UserError):
    """A failure of the co-simulation, with where and when it happened."""

    def __init__(self, message: str, element: str | None = None, time: float | None = None,
                 log: list[str] | None = None):
        self.element = element
        self.time = time
        self.log = log or []
        super().__init__(message)


class DivergenceError(CoSimulationError):
    """An output left a bound of the output check (e.g. the platform envelope) or stopped being
    finite: the run is diverging."""

    def __init__(self, message: str, element: str, time: float, signal: str, value: float,
                 log: list[str] | None = None):
        self.signal = signal
        self.value = value
        super().__init__(message, element, time, log)
