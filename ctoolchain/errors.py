"""The base of every error ``tapmp`` prints as one line, ``error: ...`` with exit code 2.

It lives in ctoolchain, the lowest package of the project (it imports no other), so that every
layer above can derive its own errors from it: the toolchain, the model (tapmp), the FMU
builder, the engine, the tool, the paper study and the studies.
"""


class UserError(Exception):
    """An error the user can act on: bad input (an option, a value in a file they named) or a
    run, build or file that failed for a reason the message names in one line. Each subclass
    also derives from the built-in type its callers catch (ValueError, RuntimeError)."""
