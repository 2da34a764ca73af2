"""Exceptions that carry a message meant for the user.

Every error the workbench raises for bad input derives from
:class:`WorkbenchError`; the CLI and the GUI show ``str(error)`` and never a
traceback.  :class:`InputError` names the file and the problem.
"""

from __future__ import annotations

from os import PathLike


class WorkbenchError(Exception):
    """An error with a message a user can act on."""


class InputError(WorkbenchError):
    """A problem with an input file or value.

    Parameters
    ----------
    source : path or str
        The file (or argument) at fault.
    problem : str
        What is wrong, in plain words.
    hint : str, optional
        What the user can do about it.
    """

    def __init__(self, source: str | PathLike[str], problem: str, hint: str | None = None):
        self.source = str(source)
        self.problem = problem
        self.hint = hint
        message = f"{self.source}: {problem}"
        if hint:
            message += f" ({hint})"
        super().__init__(message)


class UnitsError(InputError):
    """A mesh whose size does not look like millimetres and no units were given."""


class LandmarkError(WorkbenchError):
    """Missing, duplicate, unknown or undefined landmarks."""


class Cancelled(WorkbenchError):
    """The user cancelled a running job (raised at its next progress check)."""
