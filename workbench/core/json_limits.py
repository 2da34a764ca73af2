"""One JSON reader with a size and a nesting limit, for every JSON a user can hand in.

Python's decoder recurses once per nesting level, so a file of 100,000
opening brackets ends in ``RecursionError``; it also builds whatever the
text describes, so a gigabyte of whitespace or a million-entry list is read
in full before any check can look at it.  Case members, landmark files,
animation tracks and manifests are all user input, so they go through
:func:`loads_limited` (text or bytes already in memory, whose length the
caller bounded while reading) or :func:`read_json` (a file, whose size is
checked before a byte is read).  Both raise :class:`InputError` naming the
source and the limit, never ``RecursionError`` or ``MemoryError``.

Non-finite numbers (``NaN``, ``Infinity``) are refused as well: they are not
JSON, and a landmark at ``NaN`` mm is a broken file, not a point.

Pure Python and numpy; :func:`read_json` is the only function touching files.
"""

from __future__ import annotations

import json
import re
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np

from workbench.core.errors import InputError

#: the largest JSON document read (bytes): a case's ``case.json`` with 200 landmarks,
#: an audit trail of thousands of edits and its settings is well under 5 MB; an
#: animation track of a minute at 60 fps with 60 channels is ~3 MB
MAX_JSON_BYTES = 64 * 1024 * 1024
#: the deepest nesting of objects and lists: the workbench's own files go 6 deep;
#: 64 leaves room for any tool's metadata and stays far below Python's recursion limit
MAX_JSON_DEPTH = 64

_STRING = re.compile(rb'"(?:[^"\\]|\\.)*"', re.DOTALL)


def nesting_depth(raw: bytes) -> int:
    """The deepest nesting of ``{``/``[`` in JSON text (brackets inside strings ignored)."""
    bare = _STRING.sub(b"", raw)
    codes = np.frombuffer(bare, dtype=np.uint8)
    step = np.zeros(codes.shape, dtype=np.int64)
    step[(codes == ord("{")) | (codes == ord("["))] = 1
    step[(codes == ord("}")) | (codes == ord("]"))] = -1
    if not step.any():
        return 0
    return int(np.cumsum(step).max())


def _reject_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a number JSON allows")


def loads_limited(
    raw: str | bytes,
    source: str | PathLike[str],
    *,
    max_bytes: int = MAX_JSON_BYTES,
    max_depth: int = MAX_JSON_DEPTH,
    what: str = "JSON file",
) -> Any:
    """Decode JSON text after checking its size and nesting depth.

    Parameters
    ----------
    raw : str or bytes
        The text (bytes are decoded as UTF-8, a BOM is accepted).
    source : path or str
        The file or member named in the error message.
    max_bytes, max_depth : int
        Limits; see :data:`MAX_JSON_BYTES` and :data:`MAX_JSON_DEPTH`.
    what : str
        What the document is, for the message ("case file", "landmark file").

    Raises
    ------
    InputError
        Too large, nested too deep, not UTF-8, not JSON, or holding NaN/Infinity.
    """
    data = raw.encode("utf-8") if isinstance(raw, str) else bytes(raw)
    if len(data) > max_bytes:
        raise InputError(
            source,
            f"the {what} is {len(data) / 1e6:.1f} MB, more than the {max_bytes / 1e6:.0f} MB "
            "a file of this kind can reasonably be",
            "it is padded or not the file you meant",
        )
    depth = nesting_depth(data)
    if depth > max_depth:
        raise InputError(
            source,
            f"the {what} nests {depth} levels deep (at most {max_depth} are read)",
            "it is not a file the workbench or another tool wrote",
        )
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(source, f"the {what} is not UTF-8 text ({exc.reason})") from None
    try:
        return json.loads(text, parse_constant=_reject_constant)
    except (ValueError, RecursionError) as exc:
        raise InputError(source, f"the {what} is not valid JSON ({exc})") from None


def read_json(
    path: str | PathLike[str],
    *,
    max_bytes: int = MAX_JSON_BYTES,
    max_depth: int = MAX_JSON_DEPTH,
    what: str = "JSON file",
) -> Any:
    """Read and decode a JSON file with :func:`loads_limited`'s limits.

    The size is checked on the file system first, so an oversized file is
    refused without being read.
    """
    p = Path(path)
    try:
        size = p.stat().st_size
        if size > max_bytes:
            raise InputError(
                p,
                f"the {what} is {size / 1e6:.1f} MB, more than the {max_bytes / 1e6:.0f} MB "
                "a file of this kind can reasonably be",
                "it is padded or not the file you meant",
            )
        with p.open("rb") as fh:
            raw = fh.read(max_bytes + 1)
    except OSError as exc:
        raise InputError(p, f"cannot read the {what} ({exc.strerror or exc})") from None
    return loads_limited(raw, p, max_bytes=max_bytes, max_depth=max_depth, what=what)
