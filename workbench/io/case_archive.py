"""Reading side of the ``.fcase`` zip (:mod:`workbench.io.case_file`): member names and limits.

The members a case file holds (``case.json``, ``audit.jsonl``, ``arrays/``,
``evidence/``), the largest decompressed size accepted for each kind
(bytes), the archive opened through :mod:`workbench.io.zip_limits` (its
directory checked before any member is read) and :class:`CaseFileError`,
which every problem with a case file is reported as.  Split out of
:mod:`workbench.io.case_file`, which re-exports the public names.
"""

from __future__ import annotations

import contextlib
import math
import struct
import zipfile
import zlib
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import IO, Any

import numpy as np

from workbench.core.errors import InputError
from workbench.core.json_limits import MAX_JSON_BYTES, loads_limited
from workbench.io.zip_limits import (
    ZipLimitError,
    check_members,
    open_archive,
    open_member,
    read_member,
)

CASE_JSON = "case.json"
AUDIT = "audit.jsonl"
_ZIP_ERRORS = (zipfile.BadZipFile, zlib.error, EOFError, NotImplementedError)
#: what opening a zip's directory can raise for a damaged file, besides _ZIP_ERRORS
_DIRECTORY_ERRORS = (*_ZIP_ERRORS, RuntimeError, struct.error, UnicodeDecodeError, ValueError)

#: largest ``case.json`` read: 200 landmarks, guides and settings are well under 1 MiB
MAX_CASE_JSON_BYTES = 16 * 1024 * 1024
#: largest ``audit.jsonl`` read: ~150,000 records of ~400 bytes
MAX_AUDIT_BYTES = MAX_JSON_BYTES
#: largest ``arrays/*.npy`` member: a 45-million-vertex mesh; each array is also held
#: to the size its reference in case.json gives (dtype x shape + header)
MAX_ARRAY_BYTES = 2 * 1024**3
#: largest ``evidence/*`` member (a CT volume in one file); evidence is hashed as it
#: streams, never held in memory, and each member is also held to its recorded size
MAX_EVIDENCE_BYTES = 8 * 1024**3
#: anything else in the archive (never read; a case file writes nothing else)
MAX_OTHER_BYTES = 64 * 1024 * 1024
#: room for the ``.npy`` header in front of an array's data
_NPY_HEADER_BYTES = 64 * 1024


class CaseFileError(InputError):
    """A case file that cannot be read or written; names the file and the problem."""


def member_limit(name: str) -> int:
    """The largest decompressed size accepted for the case-file member ``name`` (bytes)."""
    if name == CASE_JSON:
        return MAX_CASE_JSON_BYTES
    if name == AUDIT:
        return MAX_AUDIT_BYTES
    if name.startswith("arrays/"):
        return MAX_ARRAY_BYTES
    if name.startswith("evidence/"):
        return MAX_EVIDENCE_BYTES
    return MAX_OTHER_BYTES


def sized_in_case(name: str) -> bool:
    """Members whose exact size ``case.json`` gives and every read is capped at (arrays by
    their shape, evidence by its recorded size): judged by that, not by how well they
    deflate (a mostly empty mask or label volume deflates beyond the bomb ratio)."""
    return name.startswith(("arrays/", "evidence/"))


@dataclass(frozen=True)
class CaseArchive:
    """An open case file whose directory passed :func:`check_members`."""

    zip: zipfile.ZipFile
    members: Mapping[str, zipfile.ZipInfo]
    path: Path

    def has(self, name: str) -> bool:
        return name in self.members

    def info(self, name: str) -> zipfile.ZipInfo:
        try:
            return self.members[name]
        except KeyError:
            raise CaseFileError(self.path, f"{name} is missing from the case file") from None

    def read(self, name: str, limit: int | None = None) -> bytes:
        """A member's bytes, never decompressing more than its limit plus one byte."""
        cap = member_limit(name) if limit is None else min(limit, member_limit(name))
        ratio = not (sized_in_case(name) and limit is not None)
        return read_member(self.zip, self.info(name), self.path, cap, ratio=ratio)

    def open(self, name: str, limit: int) -> IO[bytes]:
        """A stream over a member that stops past ``limit`` bytes (see :func:`open_member`)."""
        cap = min(limit, member_limit(name))
        return open_member(self.zip, self.info(name), self.path, cap, ratio=not sized_in_case(name))


def as_case_error(error: InputError) -> CaseFileError:
    """``error`` (e.g. a zip or JSON limit) as a :class:`CaseFileError` with the same text."""
    return CaseFileError(error.source, error.problem, error.hint)


@contextlib.contextmanager
def _reading(path: Path, damaged: tuple[type[BaseException], ...]) -> Iterator[None]:
    """Errors of reading the case file ``path`` as :class:`CaseFileError` (``damaged``: the
    library errors that mean a damaged or truncated file)."""
    try:
        yield
    except ZipLimitError as error:
        raise as_case_error(error) from None
    except damaged as error:
        raise CaseFileError(
            path, f"the file is damaged or truncated ({error})", "restore it from a backup"
        ) from None
    except OSError as error:
        raise CaseFileError(path, f"cannot read the file ({error})") from None


@contextlib.contextmanager
def open_case_zip(path: Path) -> Iterator[CaseArchive]:
    """The case file ``path`` opened for reading, its directory checked against the limits;
    reading errors inside the block are reported as :class:`CaseFileError`."""
    if not path.is_file():
        raise CaseFileError(path, "no such case file")
    with contextlib.ExitStack() as stack:
        with _reading(path, _DIRECTORY_ERRORS):
            archive = stack.enter_context(open_archive(path))
            members = check_members(archive, path, member_limit, ratio_exempt=sized_in_case)
        with _reading(path, _ZIP_ERRORS):
            yield CaseArchive(archive, MappingProxyType(members), path)


def read_stored_json(archive: CaseArchive) -> dict[str, Any]:
    """``case.json`` as stored (decoded within the JSON limits, not migrated)."""
    raw = archive.read(CASE_JSON)
    try:
        doc = loads_limited(
            raw, archive.path, max_bytes=MAX_CASE_JSON_BYTES, what="case.json member"
        )
    except InputError as error:
        raise as_case_error(error) from None
    if not isinstance(doc, dict):
        raise CaseFileError(archive.path, "case.json is not a JSON object")
    return doc


def array_limit(ref: Mapping[str, Any]) -> int:
    """The size of the ``.npy`` member ``ref`` describes, plus room for its header."""
    try:
        itemsize = np.dtype(str(ref["dtype"])).itemsize
        count = math.prod(int(n) for n in ref["shape"])
    except (TypeError, ValueError, KeyError):
        return MAX_ARRAY_BYTES
    return min(MAX_ARRAY_BYTES, itemsize * max(count, 0) + _NPY_HEADER_BYTES)


def open_previous(candidate: Path, stack: contextlib.ExitStack) -> CaseArchive | None:
    """A previous case file, opened with the reading limits; None if it cannot be used."""
    with contextlib.suppress(OSError, ZipLimitError, *_DIRECTORY_ERRORS):
        archive = stack.enter_context(open_archive(candidate))
        members = check_members(archive, candidate, member_limit, ratio_exempt=sized_in_case)
        return CaseArchive(archive, members, candidate)
    return None
