"""Evidence files: the original inputs of a case, identified by sha256.

Evidence is never rewritten.  A case records each original file's name, size
and sha256; the case file stores the bytes once, verbatim, and every later
save copies them from the previous case file or the original file only after
re-hashing them.  Derived geometry (the working specimen mesh, arrays) is
stored separately.
"""

from __future__ import annotations

import hashlib
import re
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass, fields
from os import PathLike
from pathlib import Path
from typing import IO, Any

from workbench.core.errors import InputError

CHUNK_BYTES = 1 << 20

#: Something that opens a fresh binary stream (a file, a zip member).
Opener = Callable[[], IO[bytes]]

_SHA256 = re.compile(r"^[0-9a-f]{64}$")
_ROLE = re.compile(r"^[a-z][a-z0-9_]*$")
_BAD_NAME = re.compile(r"[/\\\x00-\x1f]")

#: Roles in use; any lower_snake_case role is accepted.
KNOWN_ROLES = ("skull_mesh", "ct_volume", "truth_surface", "photograph", "other")


def check_evidence_name(name: str) -> str:
    """Return ``name`` if it is a plain file name usable inside the case file.

    Raises
    ------
    ValueError
        For empty names, ``.``/``..``, path separators or control characters.
    """
    if not isinstance(name, str) or not name or name in (".", "..") or _BAD_NAME.search(name):
        raise ValueError(f"evidence name {name!r} must be a plain file name")
    return name


def hash_chunks(chunks: Iterable[bytes]) -> tuple[str, int]:
    """``(sha256 hex, total size in bytes)`` of a stream of chunks."""
    digest = hashlib.sha256()
    size = 0
    for chunk in chunks:
        digest.update(chunk)
        size += len(chunk)
    return digest.hexdigest(), size


def read_chunks(stream: IO[bytes], chunk_bytes: int = CHUNK_BYTES) -> Iterable[bytes]:
    """Yield ``stream`` in chunks until EOF."""
    while chunk := stream.read(chunk_bytes):
        yield chunk


def sha256_file(path: str | PathLike[str]) -> tuple[str, int]:
    """``(sha256 hex, size in bytes)`` of a file, read in 1 MiB chunks."""
    with open(path, "rb") as stream:
        return hash_chunks(read_chunks(stream))


def file_sha256(path: str | PathLike[str]) -> str:
    """SHA-256 (lower-case hex) of a file; an unreadable file is an InputError naming it."""
    try:
        return sha256_file(path)[0]
    except OSError as exc:
        raise InputError(path, f"cannot read the file to hash it ({exc.strerror or exc})") from None


def copy_hashed(source: IO[bytes], target: IO[bytes]) -> tuple[str, int]:
    """Copy ``source`` to ``target`` and return ``(sha256, size)`` of what was copied."""

    def tee() -> Iterable[bytes]:
        for chunk in read_chunks(source):
            target.write(chunk)
            yield chunk

    return hash_chunks(tee())


def find_verified_copy(
    item: EvidenceFile,
    openers: Iterable[Opener],
    errors: tuple[type[BaseException], ...] = (OSError,),
) -> Opener | None:
    """The first opener whose bytes hash to ``item``'s sha256 and size, else ``None``.

    Openers that fail with one of ``errors`` are skipped.
    """
    for opener in openers:
        try:
            with opener() as stream:
                if hash_chunks(read_chunks(stream)) == (item.sha256, item.size):
                    return opener
        except errors:
            continue
    return None


@dataclass(frozen=True)
class EvidenceFile:
    """Reference to one original evidence file.

    Parameters
    ----------
    name : str
        Plain file name, unique within the case (``evidence/<name>`` in the case file).
    sha256 : str
        Lower-case hex digest of the original bytes.
    size : int
        Size of the original in bytes.
    role : str
        What the file is, e.g. ``"skull_mesh"``, ``"ct_volume"``, ``"truth_surface"``.
    original_path : str
        Where the file was imported from (informative; may no longer exist).
    units_note : str
        What the examiner knows about the file's units, e.g. ``"unitless, scaled x10 to mm"``.
    """

    name: str
    sha256: str
    size: int
    role: str
    original_path: str = ""
    units_note: str = ""

    def __post_init__(self) -> None:
        check_evidence_name(self.name)
        if not isinstance(self.sha256, str) or not _SHA256.match(self.sha256):
            raise ValueError(f"evidence {self.name!r}: sha256 must be 64 lower-case hex digits")
        if isinstance(self.size, bool) or not isinstance(self.size, int) or self.size < 0:
            raise ValueError(f"evidence {self.name!r}: size must be a non-negative integer")
        if not isinstance(self.role, str) or not _ROLE.match(self.role):
            raise ValueError(f"evidence {self.name!r}: role {self.role!r} is not lower_snake_case")
        if not isinstance(self.original_path, str) or not isinstance(self.units_note, str):
            raise TypeError(f"evidence {self.name!r}: original_path and units_note are strings")

    @classmethod
    def from_path(
        cls,
        path: str | PathLike[str],
        role: str,
        name: str | None = None,
        units_note: str = "",
    ) -> EvidenceFile:
        """Hash an original file and describe it (the bytes are not kept in memory)."""
        path = Path(path)
        sha, size = sha256_file(path)
        return cls(name or path.name, sha, size, role, str(path.resolve()), units_note)

    def to_state(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> EvidenceFile:
        names = {f.name for f in fields(cls)}
        unknown = sorted(set(state) - names)
        if unknown:
            raise ValueError(f"unknown evidence fields: {', '.join(unknown)}")
        return cls(**state)


def evidence_to_state(evidence: tuple[EvidenceFile, ...]) -> list[dict[str, Any]]:
    """State of the evidence part: one dict per file, in order."""
    return [item.to_state() for item in evidence]


def evidence_from_state(state: list[dict[str, Any]]) -> tuple[EvidenceFile, ...]:
    """Inverse of :func:`evidence_to_state` (validated)."""
    return coerce_evidence([EvidenceFile.from_state(item) for item in state])


def coerce_evidence(value: Iterable[EvidenceFile]) -> tuple[EvidenceFile, ...]:
    """Validate an evidence list: :class:`EvidenceFile` items with unique names."""
    items = tuple(value)
    names: set[str] = set()
    for item in items:
        if not isinstance(item, EvidenceFile):
            raise TypeError(f"evidence items must be EvidenceFile, got {type(item).__name__}")
        if item.name in names:
            raise ValueError(f"two evidence files are named {item.name!r}")
        names.add(item.name)
    return items
