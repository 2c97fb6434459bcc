"""Error types shared by the model core, the FMU adapters and the orchestrator."""

import difflib
import math

# the base lives in ctoolchain, the lowest package (it imports no other), so that every layer's errors share it
from ctoolchain.errors import UserError


class ModelInputError(ValueError, UserError):
    """A value given to the model is outside what the model allows.

    The message always names the variable, the value and what is allowed.
    """

    def __init__(self, name: str, value, allowed: str, time: float | None = None):
        self.name = name
        self.value = value
        self.allowed = allowed
        self.time = time
        at = "" if time is None else f" at t = {time:.6g} s"
        super().__init__(f"{name} = {value!r}{at} is invalid: allowed is {allowed}")


class KinematicDomainError(ModelInputError):
    """A pose or a set of motor positions lies outside the kinematic domain (Eq. 1)."""


def require_finite(name: str, value: float, time: float | None = None) -> float:
    """Return ``value`` if it is a finite float, else raise :class:`ModelInputError`."""
    if not math.isfinite(value):
        raise ModelInputError(name, value, "a finite number", time)
    return value


def require_positive(name: str, value: float) -> float:
    """Return ``value`` if finite and > 0, else raise :class:`ModelInputError`."""
    if not (math.isfinite(value) and value > 0.0):
        raise ModelInputError(name, value, "a finite number > 0")
    return value


def suggestion(value, allowed) -> str:
    """``"; did you mean B?"`` naming the allowed names closest to ``value`` (difflib's ratio
    >= 0.6, at most three, best first), or ``""`` when none is close."""
    names = list(dict.fromkeys(str(a) for a in allowed))  # a name listed twice is offered once
    close = difflib.get_close_matches(str(value), names, n=3, cutoff=0.6)
    return f"; did you mean {' or '.join(close)}?" if close else ""


def allowed_are(value, allowed, sep: str = ", ") -> str:
    """``"allowed are A, B, C; did you mean B?"``: the allowed names joined by ``sep`` and the
    closest ones to the refused ``value`` (:func:`suggestion`)."""
    return f"allowed are {sep.join(str(a) for a in allowed)}{suggestion(value, allowed)}"
