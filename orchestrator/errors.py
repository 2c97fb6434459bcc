"""The error type of bad input the user gave: an option, a value in a file they named.

``tapmp`` prints a user error (a subclass of ``UserError``) as one line (``error: ...``, exit
code 2) and lets every other exception, a programming error, show its traceback. The project's
own error types (ScenarioError, StudyError, CoSimulationError, the result-folder errors, ...)
derive from ``UserError`` too, each also from the built-in type its callers catch.
"""

# from ctoolchain, not tapmp.errors: the engine derives its errors from it and loads no tapmp module
from ctoolchain.errors import UserError


class UsageError(ValueError, UserError):
    """A value the user gave is not allowed; the message is one line naming the option or
    variable, the value and what is allowed (a ValueError, so callers that catch bad values
    as ValueError keep working)."""
