"""The error type of bad input the user gave: an option, a value in a file they named.

``tapmp`` prints such an error as one line (``error: ...``, exit code 2) and lets every other
exception, a programming error, show its traceback. The project's own error types (ScenarioError,
StudyError, CoSimulationError, the result-folder errors, ...) are user errors too; the command
line lists them in orchestrator.cli.USER_ERRORS.
"""


class UsageError(ValueError):
    """A value the user gave is not allowed; the message is one line naming the option or
    variable, the value and what is allowed (a ValueError, so callers that catch bad values
    as ValueError keep working)."""
