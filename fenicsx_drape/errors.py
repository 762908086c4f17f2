"""Errors that the command line reports as bad input (exit status 2)."""

from __future__ import annotations

import difflib
import warnings
from collections.abc import Iterable

__all__ = ["DrapeInputError", "InputFileError", "ParameterError", "SolverError",
           "did_you_mean", "likely_typo", "old_name"]


class DrapeInputError(ValueError):
    """Bad input from the user: a file, a line, a parameter or an option.

    The message names where the problem is (file and line, or parameter) and what it is.
    The command line prints it without a traceback and exits with status 2.
    """


class InputFileError(DrapeInputError):
    """An input file (a case, a bundle and its tables) that cannot be used, with every problem.

    ``problems`` lists each problem as a sentence that starts with its file (and line or key):
    ``case.toml: [[tool]] 2 'geometry': no such file 'punch.stp'``, ``grid.csv:11: ...``. A
    file is read whole and all its problems are reported at once.
    """

    def __init__(self, problems: Iterable[str]):
        self.problems = list(problems)
        if len(self.problems) == 1:
            message = self.problems[0]
        else:
            message = f"{len(self.problems)} problems:\n  " + "\n  ".join(self.problems)
        super().__init__(message)


class ParameterError(DrapeInputError):
    """A material or model parameter is missing, unknown, not finite or out of range."""


class SolverError(RuntimeError):
    """A solve could not be completed (e.g. a load step was cut back to its floor)."""


def likely_typo(name: str, known: Iterable[str]) -> str | None:
    """The known name that ``name`` is most likely a misspelling of, or None.

    Close in spelling (:func:`difflib.get_close_matches`, ratio ≥ 0.75), or the same words in
    the same unit with one word changed (``shear_noise_deg`` for ``shear_sd_deg``): names are
    words joined by ``_`` whose last word is the unit.
    """
    known = [k for k in known if k != name]
    close = difflib.get_close_matches(name, known, n=1, cutoff=0.75)
    if close:
        return close[0]
    words = name.split("_")
    if len(words) < 3:
        return None
    for k in known:
        other = k.split("_")
        # The unit and the first word kept, one middle word changed (shear_noise_deg).
        if (len(other) == len(words) and other[0] == words[0] and other[-1] == words[-1]
                and sum(a != b for a, b in zip(words, other)) == 1):
            return k
    return None


def did_you_mean(name: str, known: Iterable[str]) -> str:
    """`` (did you mean `x`?)`` when ``name`` is a likely typo of a known name, else ``""``."""
    guess = likely_typo(name, known)
    return f" (did you mean `{guess}`?)" if guess else ""


def old_name(at: str, old: str, new: str, stacklevel: int = 3) -> str:
    """``new``, after a note that ``old``, an earlier name of the same value, was read as it.

    One name per quantity in case files, bundles and reports; the earlier name is read for one
    release with this note (a :class:`FutureWarning`, which Python shows to a command's user),
    ``at`` naming the file and table or key: ``case.toml: [holder] 'force_N' is now called
    'holder_force_N' (read as it; the old name goes in the next release)``.
    """
    warnings.warn(f"{at} '{old}' is now called '{new}' (read as it; the old name goes in the "
                  "next release)", FutureWarning, stacklevel=stacklevel)
    return new
