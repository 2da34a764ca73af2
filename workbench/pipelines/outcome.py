"""What a job returns to whoever ran it, and what a failed job tells its user.

A job function (a command line handler, a batch row) returns a
:class:`JobOutcome`: its exit status and its key figures as values, so a
batch study reads the figures from the job, not from what it printed.
:func:`failure_status` turns an exception a job raised into the one line the
user reads and the exit status: 2 for an error the user can act on (a
:class:`~workbench.core.errors.WorkbenchError`, a file that cannot be read or
written, named at its final place even when the job wrote into a staged
folder), 1 for anything unexpected (``--debug`` re-raises it).  The command
line and ``workbench batch`` both use it, so a row's message is the command's.
"""

from __future__ import annotations

import argparse
import errno
import os
import re
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from workbench.core.errors import WorkbenchError

#: what hears a job's progress lines and notes (print, a status bar, a list)
Say = Callable[[str], None]


def quiet(_message: str) -> None:
    """A :data:`Say` that drops what it hears."""
    return None


#: the name shown for the standard output in an error (it has no file name)
STDOUT_NAME = "the standard output"


@dataclass
class JobOutcome:
    """A finished job: its exit status (0 ok, 2 some cases failed, 3 written but to be
    checked) and its key figures (plain numbers and short strings, for a summary table)."""

    status: int = 0
    figures: dict[str, Any] = field(default_factory=dict)
    #: why the job asks for a check (the registration's self-check), worst first
    check: list[str] = field(default_factory=list)

    def __int__(self) -> int:
        return self.status


def failure_status(
    exc: BaseException,
    args: argparse.Namespace,
    *,
    flush_stdout: Callable[[], None] | None = None,
) -> int:
    """Print ``exc`` as the user should read it (stderr, one line) and return the exit status.

    ``args``: the job's options (``command`` names it; ``debug`` re-raises the
    unexpected; ``out`` is named when a write failed without a file name).
    ``flush_stdout`` is tried first in that case, to tell whether it was the
    standard output that failed.
    """
    if isinstance(exc, WorkbenchError):
        print(f"{_prog(args)}: error: {exc}", file=sys.stderr)
        return 2
    if isinstance(exc, OSError):
        return _os_error(args, exc, flush_stdout)
    if not isinstance(exc, Exception):
        raise exc
    return _unexpected(args, exc)


#: errors of a write that the device or file system refused, as told to the user
WRITE_FAILURES = {
    code: text
    for code, text in (
        (errno.ENOSPC, "no space left on the device"),
        (getattr(errno, "EDQUOT", None), "the disk quota is exceeded"),
        (errno.EROFS, "the file system is read-only"),
        (errno.EFBIG, "the file is too large for the file system"),
    )
    if code is not None
}

#: a staged output folder's temporary name (workbench.io.outputs): ``.NAME.partial-PID``
_STAGED = re.compile(r"^\.(?P<name>.+)\.partial-\d+$")


def _shown_path(name: Any) -> str | None:
    """``name`` (an OSError's filename) as the user knows it: a path inside a staged
    output folder is shown at its final place."""
    if name is None:
        return None
    text = os.fsdecode(name) if isinstance(name, bytes | os.PathLike) else str(name)
    parts = [_STAGED.sub(r"\g<name>", part) for part in Path(text).parts]
    return str(Path(*parts)) if parts else text


def _os_error(
    args: argparse.Namespace, exc: OSError, flush_stdout: Callable[[], None] | None
) -> int:
    """A file the command could not read or write (a folder where a file is expected, no
    permission, disk full): name the path and the problem."""
    where = _shown_path(exc.filename)
    failure = WRITE_FAILURES.get(exc.errno) if exc.errno is not None else None
    if failure is not None and not getattr(args, "debug", False):
        if where is None:  # no file named: the standard output, if it fails too, else --out
            try:
                if flush_stdout is not None:
                    flush_stdout()
            except OSError as again:
                where = again.filename
        target = where or _output_of(args)
        elsewhere = "the output" if target == STDOUT_NAME else "--out"
        hint = (
            f"free some space (or send {elsewhere} to another disk) and run the command again"
            if exc.errno in (errno.ENOSPC, getattr(errno, "EDQUOT", None))
            else f"send {elsewhere} to another place"
        )
        print(
            f"{_prog(args)}: error: {target}: cannot be written: {failure} ({hint})",
            file=sys.stderr,
        )
        return 2
    if where is None or getattr(args, "debug", False):
        return _unexpected(args, exc)
    if exc.filename2:
        where += f" -> {_shown_path(exc.filename2)}"
    print(
        f"{_prog(args)}: error: {where}: cannot be read or written ({exc.strerror or exc})",
        file=sys.stderr,
    )
    return 2


def _prog(args: argparse.Namespace) -> str:
    command = getattr(args, "command", None)
    return f"workbench {command}" if command else "workbench"


def _output_of(args: argparse.Namespace) -> str:
    """What the command writes, for an error that does not name the file: its ``--out``,
    else the standard output (where a command without one writes)."""
    out = getattr(args, "out", None)
    return f"--out {out}" if out is not None else STDOUT_NAME


def _unexpected(args: argparse.Namespace, exc: Exception) -> int:
    if getattr(args, "debug", False):
        raise exc
    print(
        f"{_prog(args)}: unexpected error: {type(exc).__name__}: {exc}\n"
        "(rerun with --debug for the full traceback, and please report it)",
        file=sys.stderr,
    )
    return 1
