"""Checks shared by the configuration files: scenarios (orchestrator.tool.scenario) and
studies (orchestrator.studies.study, orchestrator.studies.tuning).

Scenarios and studies are pydantic models: each field carries its rule (``Annotated[str,
one_of(LAWS)]``, ``Annotated[float, rule(...)]``), rules that relate fields run after them.
Every rule raises ValueError with the project's one-line message ("KEY = VALUE is invalid:
allowed is ...", "KEY is unknown: allowed are ...; did you mean ...?"); :func:`build` turns
pydantic's ValidationError into that one line (its first error) in one place. Validation
reads no file and changes no input: reading a gains_file or looking for a study's base
scenario are explicit steps after it.
"""

import math
import sys
from pathlib import Path

from pydantic import BeforeValidator, ValidationError

from tapmp.errors import allowed_are

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


def read_toml(path: Path, subject: str, error: type[Exception], allowed: str = "") -> dict:
    """Parse a TOML file; a missing or malformed file raises ``error`` as
    "<subject> does not exist<allowed>" or "<subject> is not valid TOML: ..."."""
    try:
        return tomllib.loads(Path(path).read_text())
    except FileNotFoundError:
        raise error(f"{subject} does not exist{allowed}") from None
    except tomllib.TOMLDecodeError as err:
        raise error(f"{subject} is not valid TOML: {err}") from None


def require(cond, message: str, error: type[Exception] = ValueError) -> None:
    """Raise ``error(message)`` unless ``cond`` holds."""
    if not cond:
        raise error(message)


def is_number(value) -> bool:
    """True for an int or a float (a bool is not a number here, as in TOML)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def check_type(key: str, value, kind, error: type[Exception] = ValueError):
    """``value`` as ``kind`` (an int where a float is asked becomes a float, a whole float where
    an int is asked becomes an int); anything else raises "KEY = VALUE has the wrong type"."""
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if kind is int and isinstance(value, float) and value.is_integer():
        return int(value)
    if not isinstance(value, kind) or (kind is not bool and isinstance(value, bool)):
        raise error(f"{key} = {value!r} has the wrong type: allowed is {kind.__name__}")
    return value


def finite_number(where: str, value, error: type[Exception] = ValueError) -> float:
    """``value`` as a float if it is a finite number, else "WHERE = VALUE is invalid"."""
    require(is_number(value) and math.isfinite(value), f"{where} = {value!r} is invalid: allowed is a finite number",
            error)
    return float(value)


def three_numbers(where: str, value, error: type[Exception] = ValueError) -> list:
    """A per-motor value: a number (the same for all three motors) or a list of 3 numbers,
    as a list of 3 floats (units those of the key)."""
    values = [value] * 3 if is_number(value) else value
    require(isinstance(values, list) and len(values) == 3,
            f"{where} = {value!r} is invalid: allowed is a number or a list of 3 numbers", error)
    return [check_type(where, x, float, error) for x in values]


def one_of(allowed, where: str = "") -> BeforeValidator:
    """Field rule: the value is one of ``allowed``, else "WHERE.FIELD = VALUE is invalid:
    allowed are ..." (``where`` is the table's dotted name with its dot, "" at the top)."""
    def check(value, info):
        if value not in allowed:  # the message (with its suggestions) only when it is needed
            raise ValueError(f"{where}{info.field_name} = {value!r} is invalid: {allowed_are(value, allowed)}")
        return value
    return BeforeValidator(check)


def rule(test, allowed: str, where: str = "") -> BeforeValidator:
    """Field rule: ``test(value)`` holds, else "WHERE.FIELD = VALUE is invalid: allowed is ALLOWED"."""
    def check(value, info):
        require(test(value), f"{where}{info.field_name} = {value!r} is invalid: allowed is {allowed}")
        return value
    return BeforeValidator(check)


def is_int(value, low: int) -> bool:
    """True for an int >= ``low`` (not a bool)."""
    return isinstance(value, int) and not isinstance(value, bool) and value >= low


def known(key, allowed, where: str = "", error: type[Exception] = ValueError) -> None:
    """``key`` is in ``allowed``, else "WHERE.KEY is unknown: allowed are ...; did you mean ...?"
    (``where`` is the table's dotted name with its dot)."""
    if key not in allowed:  # the message (with its suggestions) only when it is needed
        raise error(f"{where}{key} is unknown: {allowed_are(key, allowed)}")


def known_keys(where: str, allowed, data) -> None:
    """Every key of the table ``data`` is in ``allowed``, else "WHERE.KEY is unknown: allowed are ..."."""
    for key in data:
        known(key, allowed, f"{where}.")


def one_line(err: ValidationError) -> str:
    """The first error of a ValidationError as the project's one-line message: the message of
    the rule that refused the value, or for a value of the wrong kind "KEY = VALUE is invalid:
    <pydantic's reason>"."""
    first = err.errors()[0]
    cause = first.get("ctx", {}).get("error")
    if isinstance(cause, ValidationError):  # a rule that validated a nested table
        return one_line(cause)
    if isinstance(cause, ValueError):
        return str(cause)
    where = ".".join(str(p) for p in first["loc"])
    return f"{where} = {first['input']!r} is invalid: {first['msg']}"


def build(factory, error: type[Exception], /, *args, **kwargs):
    """``factory(*args, **kwargs)`` (a pydantic model or dataclass, or dataclasses.replace);
    a ValidationError is raised as ``error`` with its one-line message."""
    try:
        return factory(*args, **kwargs)
    except ValidationError as err:
        raise error(one_line(err)) from None
