"""Errors that the command line reports as bad input (exit status 2)."""


class DrapeInputError(ValueError):
    """Bad input from the user: a file, a line, a parameter or an option.

    The message names where the problem is (file and line, or parameter) and what it is.
    The command line prints it without a traceback and exits with status 2.
    """


class ParameterError(DrapeInputError):
    """A material or model parameter is missing, unknown, not finite or out of range."""


class SolverError(RuntimeError):
    """A solve could not be completed (e.g. a load step was cut back to its floor)."""
