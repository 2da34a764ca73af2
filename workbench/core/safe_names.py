"""Names taken from user text (manifest ids, subjects, file names) made safe to use on disk.

A manifest id becomes a folder name inside an output folder (``DIR/<id>/``).
Without a check, an id such as ``../../escaped`` or ``a/b`` writes outside
that folder or nests folders, ``CON`` cannot be created on Windows, and
``Case1`` and ``case1`` are one folder on a case-insensitive file system.

:func:`name_problem` says what is wrong with a name (or None), with the
same rule everywhere: letters A-Z and a-z, digits, ``-``, ``_``, ``.`` and
spaces; the first character a letter or a digit; not ending in ``.`` or a
space; at most :data:`MAX_NAME` characters; not a Windows device name
(``CON``, ``NUL``, ``COM1`` ... also with an extension).  :func:`safe_id`
raises it as an :class:`~workbench.core.errors.InputError` naming the
manifest, the row and the id, and refuses ids that repeat after case
folding.  :func:`child_path` joins a checked name to an output folder and
makes sure the result (symlinks resolved) still lies inside the folder.
"""

from __future__ import annotations

import os
import string
import unicodedata
from collections.abc import Iterable, MutableMapping
from os import PathLike
from pathlib import Path

from workbench.core.errors import InputError

#: the longest name accepted (characters); file systems allow 255 bytes per name,
#: and the workbench adds suffixes (``.1`` backups, ``.partial-<pid>`` staging folders)
MAX_NAME = 100
#: characters a name may hold
ALLOWED = frozenset(string.ascii_letters + string.digits + "-_. ")
#: what the messages tell the user
RULE = (
    "use only letters A-Z a-z, digits, '-', '_', '.' and spaces, starting with a letter or "
    f"a digit, at most {MAX_NAME} characters"
)
#: device names Windows reserves in every folder (also with any extension: ``nul.txt``)
WINDOWS_RESERVED = frozenset(
    ["CON", "PRN", "AUX", "NUL"] + [f"{p}{n}" for p in ("COM", "LPT") for n in "123456789"]
)

__all__ = [
    "ALLOWED",
    "MAX_NAME",
    "RULE",
    "child_path",
    "name_key",
    "name_problem",
    "safe_id",
]


def _describe(ch: str) -> str:
    if ch in "/\\":
        return f"a path separator {ch!r}"
    if ch == "\0":
        return "a NUL character"
    if unicodedata.category(ch).startswith("C"):
        return f"a control character (U+{ord(ch):04X})"
    return f"the character {ch!r}"


def name_problem(value: str, reserved: Iterable[str] = ()) -> str | None:
    """What makes ``value`` unusable as a file or folder name, or None when it is fine.

    ``reserved``: names the caller writes itself in the same folder (compared
    without letter case).
    """
    if not value:
        return "it is empty"
    if value in (".", ".."):
        return f"{value!r} names a folder, not a new one"
    if (
        os.path.isabs(value)
        or value.startswith(("/", "\\"))
        or (len(value) > 1 and value[1] == ":")
    ):
        return "it is an absolute path"
    bad = next((ch for ch in value if ch not in ALLOWED), None)
    if bad is not None:
        return f"it holds {_describe(bad)}"
    if len(value) > MAX_NAME:
        return f"it is {len(value)} characters long (at most {MAX_NAME})"
    if not value[0].isalnum():
        return "it does not start with a letter or a digit"
    if value[-1] in ". ":
        return "it ends with a dot or a space"
    if value.split(".")[0].rstrip(" ").upper() in WINDOWS_RESERVED:
        return "it is a device name reserved by Windows"
    lowered = {r.casefold() for r in reserved}
    if value.casefold() in lowered:
        return "the workbench writes a file or folder of that name itself"
    return None


def name_key(value: str) -> str:
    """The form under which two names are one on a case-insensitive file system."""
    return unicodedata.normalize("NFKC", value).casefold()


def safe_id(
    value: str,
    source: str | PathLike[str],
    row: int | str,
    *,
    seen: MutableMapping[str, str] | None = None,
    reserved: Iterable[str] = (),
    what: str = "id",
) -> str:
    """``value`` (blanks around it removed) if it may name a folder; else an InputError.

    ``source`` is the manifest file, ``row`` its row (a number or a text such as
    ``"line 3"``).  ``seen`` maps :func:`name_key` of the ids accepted so far to
    where they were: an id that repeats, also in another letter case, is
    refused naming both rows.  The id is added to ``seen``.
    """
    where = f"row {row}" if isinstance(row, int) else str(row)
    value = value.strip()
    problem = name_problem(value, reserved)
    if problem is not None:
        raise InputError(
            source, f"{where}: {what} {value!r} is not a usable folder name: {problem}", RULE
        )
    if seen is not None:
        key = name_key(value)
        if key in seen:
            raise InputError(
                source,
                f"{where}: {what} {value!r} is used twice (first on {seen[key]}; names that "
                "differ only in letter case are one folder on Windows and macOS)",
                "give every row its own id",
            )
        seen[key] = where
    return value


def child_path(folder: str | PathLike[str], name: str, source: str | PathLike[str] = "") -> Path:
    """``folder / name`` after checking that it lies inside ``folder`` (symlinks resolved).

    ``name`` is one path component (see :func:`name_problem`; a name the
    workbench composes itself, such as ``label_method.png``, passes too).
    An escape (``..``, a separator, an absolute name, a symlink inside
    ``folder`` pointing elsewhere) is an InputError naming ``source``.
    """
    base = Path(folder)
    where = source or base
    if not name or name in (".", "..") or any(sep in name for sep in ("/", "\\", "\0")):
        raise InputError(where, f"{name!r} is not a single file or folder name", RULE)
    path = base / name
    real_base = os.path.realpath(base)
    real = os.path.realpath(path)
    if os.path.commonpath([real_base, real]) != real_base or real == real_base:
        raise InputError(
            where,
            f"{name!r} would be written at {real}, outside the output folder {base}",
            "move that link or file away, or choose another --out",
        )
    return path
