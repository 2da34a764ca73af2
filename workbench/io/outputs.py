"""Evidence is sacred: outputs never replace inputs, and never replace old outputs silently.

Every ``workbench`` command that writes goes through this module:

- :func:`check_output_file` / :func:`output_file` for one file.  An output
  that *is* one of the command's inputs (same path after resolving symlinks,
  or the same file by :func:`os.path.samefile`) is always refused, also with
  ``force``; an existing file is refused unless ``force``, and then kept as
  a numbered backup (``face.1.ply``, ``face.2.ply`` ...).  The file itself
  is written by the io layer's atomic writers (a temporary file beside it,
  then :func:`os.replace`): a failed write leaves the old file as it was.
- :func:`check_output_folder` / :func:`staged_folder` for an output folder.
  An input inside the folder (or the folder inside an input folder) is
  always refused: the folder is replaced as a whole.  The job writes into a
  hidden sibling (``.DIR.partial-<pid>``) that is renamed into place only
  when the job succeeded, so the folder always holds exactly one complete
  run; with ``force`` the previous run is kept as ``DIR.1`` (``DIR.2`` ...).
  A failed or interrupted job removes its partial folder and leaves ``DIR``
  as it was.  A partial folder left by a killed process is removed by the
  next run into the same place.

Outputs go only into folders and regular files (or names that do not exist
yet): a device node (``/dev/null``), a FIFO, a socket, or a symbolic link to
one of them is refused by :func:`check_output_location`, with or without
``force``, and :func:`backup_existing` never renames anything but a regular
file or a folder.

Refusals are :class:`~workbench.core.errors.InputError`, so the command
line prints one clear line and exits with status 2.
"""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
import stat
from collections.abc import Callable, Iterable, Iterator
from os import PathLike
from pathlib import Path
from typing import TypeVar

from workbench.core.errors import InputError

PathArg = str | PathLike[str]
T = TypeVar("T")
Notify = Callable[[str], None]

#: suffixes kept whole when a backup number is put before the extension
COMPOUND_SUFFIXES = (".mrk.json", ".nii.gz", ".tar.gz")
PARTIAL_TAG = ".partial-"
_MAX_BACKUPS = 100_000

__all__ = [
    "backup_existing",
    "backup_name",
    "check_output_file",
    "check_output_folder",
    "check_not_special",
    "output_file",
    "relocate",
    "same_file",
    "staged_folder",
    "write_folder",
]


# ------------------------------------------------------------------ comparisons
def _resolved(path: PathArg) -> Path:
    return Path(os.path.realpath(os.fspath(path)))


def same_file(a: PathArg, b: PathArg) -> bool:
    """True when ``a`` and ``b`` name one file or folder (symlinks and hard links included)."""
    with contextlib.suppress(OSError):
        if os.path.exists(a) and os.path.exists(b):
            return os.path.samefile(a, b)
    return _resolved(a) == _resolved(b)


def _inside(path: PathArg, folder: PathArg) -> bool:
    """True when ``path`` lies somewhere below ``folder`` (both resolved; not equal)."""
    p, f = _resolved(path), _resolved(folder)
    return p != f and f in p.parents


def _real_inputs(inputs: Iterable[PathArg | None]) -> list[Path]:
    """The inputs that are paths (None and empty entries dropped)."""
    return [Path(i) for i in inputs if i is not None and os.fspath(i) != ""]


# ------------------------------------------------------------------ backups
def _split_name(name: str) -> tuple[str, str]:
    """``("skull_landmarks", ".mrk.json")``, ``("face", ".ply")``, ``("out", "")``."""
    lower = name.lower()
    for suffix in COMPOUND_SUFFIXES:
        if lower.endswith(suffix) and len(name) > len(suffix):
            return name[: -len(suffix)], name[-len(suffix) :]
    stem, dot, ext = name.rpartition(".")
    if not dot or not stem:  # no extension, or a hidden name such as ".env"
        return name, ""
    return stem, "." + ext


def _numbered(path: Path, n: int) -> Path:
    if path.is_dir():
        return path.with_name(f"{path.name}.{n}")
    stem, ext = _split_name(path.name)
    return path.with_name(f"{stem}.{n}{ext}")


def backup_name(path: PathArg) -> Path:
    """The first free numbered backup name of ``path`` (``name.N.ext``, or ``DIR.N``)."""
    path = Path(path)
    for n in range(1, _MAX_BACKUPS):
        candidate = _numbered(path, n)
        if not os.path.lexists(candidate):
            return candidate
    raise InputError(path, f"has {_MAX_BACKUPS} numbered backups already", "move some of them away")


def _copy_claimed(path: Path, candidate: Path) -> None:
    """Copy ``path`` to ``candidate``, which must not exist (claimed with O_EXCL)."""
    with open(path, "rb") as source, open(candidate, "xb") as target:
        shutil.copyfileobj(source, target)
    shutil.copystat(path, candidate)


def backup_existing(path: PathArg, *, keep: bool = False) -> Path:
    """Move ``path`` to its numbered backup and return the backup's path.

    Files become ``name.1.ext`` (``name.2.ext`` when that exists ...), folders
    ``DIR.1``; an existing backup is never overwritten.  ``keep=True`` (files
    only) leaves ``path`` in place and makes the backup a hard link to it (a
    copy where hard links are not possible): an atomic writer that then
    replaces ``path`` leaves the backup holding the old bytes.
    """
    path = Path(path)
    if not os.path.lexists(path):
        raise InputError(path, "does not exist; nothing to back up")
    check_not_special(path)
    is_dir = path.is_dir() and not path.is_symlink()
    if keep and is_dir:
        raise ValueError("keep=True is for files only")
    for n in range(1, _MAX_BACKUPS):
        candidate = _numbered(path, n)
        if os.path.lexists(candidate):
            continue
        try:
            if is_dir:
                os.rename(path, candidate)  # fails on a (non-empty) folder that appeared
            else:
                _claim_file(path, candidate, keep)
        except FileExistsError:
            continue
        except OSError as exc:
            if exc.errno in (errno.EEXIST, errno.ENOTEMPTY):
                continue
            raise InputError(
                path,
                f"cannot be kept as {candidate.name} ({exc.strerror or exc})",
                "check the folder's permissions",
            ) from None
        return candidate
    raise InputError(path, f"has {_MAX_BACKUPS} numbered backups already", "move some of them away")


def _claim_file(path: Path, candidate: Path, keep: bool) -> None:
    """Give the file ``path`` the new name ``candidate`` (also keeping ``path`` if ``keep``).

    A hard link claims the name atomically (FileExistsError if it was taken);
    without hard links the file is copied (``keep``) or renamed.
    """
    try:
        os.link(path, candidate, follow_symlinks=False)
    except FileExistsError:
        raise
    except OSError:
        if keep:
            _copy_claimed(path, candidate)
            return
        if os.path.lexists(candidate):
            raise FileExistsError(candidate) from None
        os.rename(path, candidate)
        return
    if not keep:
        os.unlink(path)


def _force_hint(path: Path) -> str:
    return f"use --force to replace it (the old one is kept as {backup_name(path).name})"


# ------------------------------------------------------------------ special files
_KINDS = (
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISFIFO, "a FIFO (named pipe)"),
    (stat.S_ISSOCK, "a socket"),
)


def _special_kind(path: PathArg) -> str | None:
    """What ``path`` is when it exists and is neither a regular file nor a folder (links followed)."""
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return None  # absent, or a dangling link: nothing is there to be harmed
    if stat.S_ISREG(mode) or stat.S_ISDIR(mode):
        return None
    kind = next((name for test, name in _KINDS if test(mode)), "not a regular file or folder")
    if os.path.islink(path):
        kind = f"a link to {kind}"
    return kind


def check_not_special(path: PathArg, option: str = "--out") -> None:
    """Refuse ``path`` when it is a device, FIFO, socket or a link to one (never with --force).

    Writing there would feed a device or block on a pipe, and replacing it
    (``--force``) would rename a system file: the workbench writes only
    regular files and folders.
    """
    kind = _special_kind(path)
    if kind is not None:
        raise InputError(
            path,
            f"is {kind}, not a regular file or folder; the workbench writes its outputs only "
            "into folders and regular files, and never replaces anything else",
            f"choose another {option}",
        )


# ------------------------------------------------------------------ single files
def check_output_location(path: PathArg, option: str = "--out") -> Path:
    """Refuse an output path that is a device or pipe, or whose nearest existing parent is a
    file or not writable.

    Called by :func:`check_output_file` and :func:`check_output_folder`, so every
    command learns this before its work, not from the first write.
    """
    path = Path(path)
    check_not_special(path, option)
    parent = path.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if parent.exists() and not parent.is_dir():
        raise InputError(
            path,
            f"cannot be created: {parent} is {_special_kind(parent) or 'a file'}, not a folder",
            f"choose another {option}",
        )
    if parent.exists() and not os.access(parent, os.W_OK | os.X_OK):
        raise InputError(
            path,
            f"cannot be written: no permission to write in {parent}",
            f"choose another {option}",
        )
    return path


def check_output_file(
    path: PathArg, inputs: Iterable[PathArg | None] = (), force: bool = False
) -> Path:
    """Refuse an output file that is an input, lies in an input folder, or exists.

    ``inputs`` are every file or folder the command reads (None entries are
    ignored).  An existing output is accepted with ``force``; the caller then
    keeps it with :func:`backup_existing` (or uses :func:`output_file`, which
    does).  Returns ``path`` as a :class:`~pathlib.Path`.
    """
    path = check_output_location(path)
    for source in _real_inputs(inputs):
        if same_file(path, source):
            raise InputError(
                path,
                "is an input of this command; an input is never replaced, not even with --force",
                "choose another output name",
            )
        if os.path.isdir(source) and _inside(path, source):
            raise InputError(
                path, f"lies inside the input folder {source}", "write the output somewhere else"
            )
    if path.is_dir():
        raise InputError(path, "is a folder", "give the name of a file to write")
    if os.path.lexists(path) and not force:
        raise InputError(path, "already exists; refusing to replace it", _force_hint(path))
    return path


@contextlib.contextmanager
def output_file(
    path: PathArg,
    inputs: Iterable[PathArg | None] = (),
    force: bool = False,
    notify: Notify | None = None,
) -> Iterator[Path]:
    """Check ``path`` (:func:`check_output_file`) and keep an existing file as its backup.

    Yields the path to write with an atomic writer (``write_mesh``,
    ``save_case``, ``write_landmarks`` ...).  If the block fails, the
    backup made for it is removed again when the old file is still in place.
    ``notify`` is told where a replaced file was kept.
    """
    path = check_output_file(path, inputs, force)
    backup = backup_existing(path, keep=True) if os.path.lexists(path) else None
    try:
        yield path
    except BaseException:
        if backup is not None and os.path.lexists(path) and same_file(path, backup):
            with contextlib.suppress(OSError):
                os.unlink(backup)
        raise
    if backup is not None and notify is not None:
        notify(f"kept the previous {path.name} as {backup}")


# ------------------------------------------------------------------ folders
def _is_empty_dir(path: Path) -> bool:
    try:
        with os.scandir(path) as entries:
            return next(entries, None) is None
    except OSError:
        return False


def check_output_folder(
    path: PathArg, inputs: Iterable[PathArg | None] = (), force: bool = False
) -> Path:
    """Refuse an output folder that holds an input, is in an input folder, or is in use.

    The folder is replaced as a whole (see :func:`staged_folder`), so an
    input inside it is refused even with ``force``.  An existing, non-empty
    folder (or a file of that name) is accepted only with ``force``.
    """
    path = check_output_location(path)
    for source in _real_inputs(inputs):
        if same_file(path, source) or _inside(source, path):
            raise InputError(
                path,
                f"holds {source}, an input of this command; the output "
                "folder is replaced as a whole, so the input would be lost",
                "pick another --out, outside the folder that holds the inputs",
            )
        if os.path.isdir(source) and _inside(path, source):
            raise InputError(
                path,
                f"lies inside the input folder {source}",
                "pick another --out, outside the input folder",
            )
    if os.path.lexists(path) and not _is_empty_dir(path) and not force:
        what = (
            "folder already exists and is not empty"
            if path.is_dir()
            else "already exists (a file, not a folder)"
        )
        raise InputError(path, f"{what}; refusing to replace it", _force_hint(path))
    return path


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True
    return True


def _remove_stale_partials(final: Path) -> None:
    """Remove partial folders of ``final`` left by processes that no longer run."""
    prefix = f".{final.name}{PARTIAL_TAG}"
    with contextlib.suppress(OSError):
        for entry in final.parent.iterdir():
            if not entry.name.startswith(prefix):
                continue
            tail = entry.name[len(prefix) :]
            if tail.isdigit() and (int(tail) == os.getpid() or not _pid_alive(int(tail))):
                shutil.rmtree(entry, ignore_errors=True)


@contextlib.contextmanager
def staged_folder(
    final_dir: PathArg,
    force: bool = False,
    inputs: Iterable[PathArg | None] = (),
    *,
    discard_existing: bool = False,
    notify: Notify | None = None,
) -> Iterator[Path]:
    """Yield a temporary sibling of ``final_dir`` to write a whole job into.

    On success an existing ``final_dir`` is kept as ``DIR.1`` (``DIR.2`` ...;
    only with ``force``; an empty folder is simply replaced) and the
    temporary folder is renamed to ``final_dir`` (atomic on one file system).
    ``discard_existing=True`` deletes the previous folder instead of keeping
    it (for outputs that are cheap to make again; the caller decides).  On
    an exception (also Ctrl-C) the temporary folder is removed and
    ``final_dir`` is left as it was.  ``notify`` is told where a replaced
    folder was kept.
    """
    final = Path(os.path.abspath(os.fspath(final_dir)))
    inputs = _real_inputs(inputs)
    check_output_folder(final, inputs, force)
    final.parent.mkdir(parents=True, exist_ok=True)
    _remove_stale_partials(final)
    temp = final.with_name(f".{final.name}{PARTIAL_TAG}{os.getpid()}")
    temp.mkdir()
    try:
        yield temp
        # the folder may have appeared (or filled) while the job ran
        check_output_folder(final, inputs, force)
        old = None
        if os.path.lexists(final):
            if _is_empty_dir(final):
                os.rmdir(final)
            elif discard_existing:
                old = final.with_name(f".{final.name}.old-{os.getpid()}")
                os.rename(final, old)
            else:
                kept = backup_existing(final)
                if notify is not None:
                    notify(f"kept the previous {final.name} as {kept}")
        os.rename(temp, final)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        shutil.rmtree(temp, ignore_errors=True)
        raise


def write_folder(
    final_dir: PathArg,
    write: Callable[[Path], T],
    *,
    force: bool = False,
    inputs: Iterable[PathArg | None] = (),
    notify: Notify | None = None,
) -> T:
    """``write(temp_folder)`` inside :func:`staged_folder`; returns what ``write`` returned.

    Paths in the result that point into the temporary folder (a Path, or a
    list / tuple / dict of them) are mapped to their final place.
    """
    final = Path(os.path.abspath(os.fspath(final_dir)))
    with staged_folder(final, force, inputs, notify=notify) as temp:
        result = write(temp)
    return relocate(result, temp, final)


def relocate(value: T, temp: Path, final: Path) -> T:
    """``value`` with paths under ``temp`` moved under ``final`` (containers walked)."""
    if isinstance(value, Path):
        try:
            return final / Path(os.path.abspath(value)).relative_to(temp)  # type: ignore[return-value]
        except ValueError:
            return value
    if isinstance(value, dict):
        return {k: relocate(v, temp, final) for k, v in value.items()}  # type: ignore[return-value]
    if isinstance(value, (list, tuple)):
        return type(value)(relocate(v, temp, final) for v in value)
    return value
