"""Atomic file writes: a file holds its old content or the whole new one, never a part.

Every writer of the workbench that replaces a file goes through here: the
bytes (or a callback that writes a file) go to a uniquely named temporary
file beside the target, are flushed to disk, and the temporary file is
renamed over the target (``os.replace``, atomic on one file system).  On any
failure the temporary file is removed and the target is left as it was.
"""

from __future__ import annotations

import json
import os
import secrets
from collections.abc import Callable
from os import PathLike
from pathlib import Path
from typing import Any


def _temporary(path: Path) -> Path:
    return path.with_name(f".{path.name}.{secrets.token_hex(6)}.tmp")


def write_bytes_atomic(path: str | PathLike[str], payload: bytes) -> Path:
    """Write ``payload`` to ``path`` atomically.

    ``os.open(..., 0o666)`` lets the umask set the permissions, as for any
    new file (``tempfile.mkstemp`` would make it private); an existing
    target keeps its permissions.
    """
    path = Path(path)
    tmp = _temporary(path)
    mode = path.stat().st_mode & 0o7777 if path.exists() else 0o666
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0), mode)
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(payload)
            handle.flush()
            os.fsync(handle.fileno())
        if path.exists():
            os.chmod(tmp, mode)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def write_text_atomic(path: str | PathLike[str], text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    return write_bytes_atomic(path, text.encode("utf-8"))


def write_with_atomic(path: str | PathLike[str], write: Callable[[Path], object]) -> Path:
    """Call ``write(tmp)`` on a temporary file beside ``path`` (for writers that only take a
    file name, such as a PDF library), then move it into place."""
    path = Path(path)
    tmp = _temporary(path)
    try:
        write(tmp)
        with open(tmp, "rb") as handle:
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def json_default(value: Any) -> Any:
    """``json.dumps``'s ``default`` for the values results hold: numpy arrays and scalars
    (as lists and numbers) and paths (as text)."""
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def write_json_atomic(path: str | PathLike[str], data: Any, *, indent: int = 2) -> Path:
    """``data`` as JSON (UTF-8, a final newline; numpy values and paths converted by
    :func:`json_default`) written to ``path`` atomically."""
    return write_text_atomic(path, json.dumps(data, indent=indent, default=json_default) + "\n")
