"""Reading a zip a user hands in (the ``.fcase`` case file) within stated limits.

A zip says how large each member will be once decompressed, but nothing
holds it to that: one megabyte of deflated spaces unpacks to a gigabyte, a
central directory can list a member twice (``ZipFile.read`` then returns the
last copy), a member can be encrypted (``RuntimeError`` from the standard
library) or compressed with a method the workbench never writes.  This
module checks an archive's directory before any member is read and then
reads members through a counter, so a lie in a header costs at most the
limit, never the memory the lie asked for.

Checks, in order
----------------
1. The end-of-central-directory record, before :class:`zipfile.ZipFile`
   parses the directory: at most :data:`MAX_MEMBERS` entries in at most
   :data:`MAX_DIRECTORY_BYTES` bytes.
2. Every directory entry (:func:`check_members`): a relative name with no
   ``..`` part, no drive and no leading slash (zip-slip), listed once, not
   encrypted, stored or deflated, no larger than its kind's limit according
   to its header, and not expanding more than :data:`MAX_RATIO` to one once
   larger than :data:`RATIO_FLOOR_BYTES` (a zip bomb).
3. Reading (:func:`read_member`, :func:`open_member`): at most the limit
   plus one byte is ever decompressed, whatever the header said.

Every refusal is a :class:`ZipLimitError` (an :class:`InputError`) naming
the archive, the member and the limit.
"""

from __future__ import annotations

import contextlib
import struct
import zipfile
import zlib
from collections.abc import Callable, Iterator
from os import PathLike
from pathlib import Path
from typing import IO, Any, cast

from workbench.core.errors import InputError

#: members a case file can hold: case.json, audit.jsonl, a few arrays and the evidence
#: files (tens in practice); far more is not a case file
MAX_MEMBERS = 10_000
#: bytes of central directory read: 10,000 entries with 300-byte names fit in 4 MiB
MAX_DIRECTORY_BYTES = 4 * 1024 * 1024
#: largest decompressed/stored ratio accepted for a member above RATIO_FLOOR_BYTES;
#: meshes and JSON deflate 2-10 to 1, a run of one byte ~1000 to 1
MAX_RATIO = 200
#: members up to this size are never refused for their ratio (a small, very regular
#: JSON document can deflate well and costs nothing to read)
RATIO_FLOOR_BYTES = 1024 * 1024
#: the compression methods the workbench writes (and so reads)
METHODS = {zipfile.ZIP_STORED: "stored", zipfile.ZIP_DEFLATED: "deflate"}
_METHOD_NAMES = {
    zipfile.ZIP_BZIP2: "bzip2",
    zipfile.ZIP_LZMA: "lzma",
    9: "deflate64",
    93: "zstandard",
    99: "AES encryption",
}
#: flag bits: 0x1 encrypted, 0x40 strong encryption
_ENCRYPTED = 0x1 | 0x40
#: errors the standard library raises for a damaged, encrypted or odd member
MEMBER_ERRORS = (
    zipfile.BadZipFile,
    zlib.error,
    EOFError,
    NotImplementedError,
    RuntimeError,
    struct.error,
    OSError,
)

_EOCD = struct.Struct("<4s4H2LH")
_EOCD_SIGNATURE = b"PK\x05\x06"
_ZIP64_LOCATOR = struct.Struct("<4sLQL")
_ZIP64_LOCATOR_SIGNATURE = b"PK\x06\x07"
_ZIP64_EOCD = struct.Struct("<4sQ2H2L4Q")
_ZIP64_EOCD_SIGNATURE = b"PK\x06\x06"
_MAX_COMMENT = 0xFFFF

PathArg = str | PathLike[str]


class ZipLimitError(InputError):
    """An archive or member refused by a limit, or unreadable; names the archive and member."""


class MemberTooLarge(ZipLimitError):
    """A member that decompressed past its cap while it was read."""


def _mb(n: float) -> str:
    if n >= 1024**3:
        return f"{n / 1024**3:.1f} GiB"
    return f"{n / 1024**2:.1f} MiB" if n >= 1024**2 else f"{int(n)} bytes"


# ---------------------------------------------------------------- the directory
def _directory_extent(stream: IO[bytes]) -> tuple[int, int] | None:
    """``(entries, directory bytes)`` from the end record, or None if there is none.

    A zip without a readable end record is left to :mod:`zipfile`, which
    reports it as damaged.
    """
    stream.seek(0, 2)
    size = stream.tell()
    tail_start = max(0, size - _EOCD.size - _MAX_COMMENT)
    stream.seek(tail_start)
    tail = stream.read()
    at = tail.rfind(_EOCD_SIGNATURE)
    if at < 0 or len(tail) - at < _EOCD.size:
        return None
    fields = _EOCD.unpack_from(tail, at)
    entries, directory = int(fields[4]), int(fields[5])
    if entries != 0xFFFF and directory != 0xFFFFFFFF and int(fields[6]) != 0xFFFFFFFF:
        return entries, directory
    locator_at = tail_start + at - _ZIP64_LOCATOR.size
    if locator_at < 0:
        return None
    stream.seek(locator_at)
    locator = stream.read(_ZIP64_LOCATOR.size)
    if len(locator) < _ZIP64_LOCATOR.size or not locator.startswith(_ZIP64_LOCATOR_SIGNATURE):
        return None
    record_at = locator_at - _ZIP64_EOCD.size
    if record_at < 0:
        return None
    stream.seek(record_at)
    record = stream.read(_ZIP64_EOCD.size)
    if len(record) < _ZIP64_EOCD.size or not record.startswith(_ZIP64_EOCD_SIGNATURE):
        return None
    zip64 = _ZIP64_EOCD.unpack(record)
    return int(zip64[7]), int(zip64[8])


def check_directory(stream: IO[bytes], source: PathArg, *, max_members: int = MAX_MEMBERS) -> None:
    """Refuse an archive whose end record announces too many entries or too large a directory.

    Runs before :class:`zipfile.ZipFile` builds one object per entry.
    """
    extent = _directory_extent(stream)
    stream.seek(0)
    if extent is None:
        return
    entries, directory = extent
    if entries > max_members:
        raise ZipLimitError(
            source,
            f"the archive lists {entries} members; a case file has at most {max_members}",
            "it is not a case file the workbench wrote",
        )
    if directory > MAX_DIRECTORY_BYTES:
        raise ZipLimitError(
            source,
            f"the archive's directory is {_mb(directory)}, more than the "
            f"{_mb(MAX_DIRECTORY_BYTES)} a case file's can be",
            "it is not a case file the workbench wrote",
        )


def unsafe_name(name: str) -> str | None:
    """Why ``name`` could escape a folder it were extracted to, or None if it is a plain path."""
    if not name:
        return "an empty name"
    if "\x00" in name:
        return "a NUL character"
    if name[0] in "/\\" or (len(name) > 1 and name[1] == ":"):
        return "an absolute path"
    if ".." in name.replace("\\", "/").split("/"):
        return "a '..' part"
    return None


def _method_name(method: int) -> str:
    return METHODS.get(method) or _METHOD_NAMES.get(method) or f"method {method}"


def check_members(
    archive: zipfile.ZipFile,
    source: PathArg,
    limit_for: Callable[[str], int],
    *,
    max_members: int = MAX_MEMBERS,
    ratio_exempt: Callable[[str], bool] = lambda _name: False,
) -> dict[str, zipfile.ZipInfo]:
    """Every member of ``archive`` by name, after the checks listed in the module docstring.

    Parameters
    ----------
    limit_for : callable
        The largest decompressed size (bytes) accepted for a member name.
    ratio_exempt : callable
        Names whose exact size the caller knows from elsewhere and caps every read at
        (a case's arrays and evidence, sized in ``case.json``): not judged by their
        compression ratio, since a mostly empty mask or label volume deflates far beyond
        :data:`MAX_RATIO` to one and is real data.

    Raises
    ------
    ZipLimitError
        Naming the first member refused and why.
    """
    infos = archive.infolist()
    if len(infos) > max_members:
        raise ZipLimitError(
            source,
            f"the archive holds {len(infos)} members; a case file has at most {max_members}",
            "it is not a case file the workbench wrote",
        )
    members: dict[str, zipfile.ZipInfo] = {}
    for info in infos:
        name = info.filename
        why = unsafe_name(name)
        if why is not None:
            raise ZipLimitError(
                source,
                f"member {name!r} has {why} in its name",
                "a case file's members are plain relative paths; this one was made to "
                "write outside the folder it is unpacked to",
            )
        if name in members:
            raise ZipLimitError(
                source,
                f"the archive holds two members named {name!r} (a zip tool reads only one "
                "of them, so which content counts is ambiguous)",
                "a member was added to the case file outside the workbench",
            )
        members[name] = info
        if info.flag_bits & _ENCRYPTED:
            raise ZipLimitError(
                source,
                f"member {name} is encrypted; the workbench never encrypts case members "
                "and does not ask for passwords",
                "save the case again from the workbench, unencrypted",
            )
        if info.compress_type not in METHODS:
            raise ZipLimitError(
                source,
                f"member {name} is compressed with {_method_name(info.compress_type)}; "
                "case files use only stored or deflate members",
                "re-zip it with deflate, or save the case again from the workbench",
            )
        limit = limit_for(name)
        if info.file_size > limit:
            raise ZipLimitError(
                source,
                f"member {name} unpacks to {_mb(info.file_size)}, more than the "
                f"{_mb(limit)} a member of its kind may be",
                "it is padded or not a case file the workbench wrote",
            )
        if (
            info.file_size > RATIO_FLOOR_BYTES
            and info.file_size > MAX_RATIO * max(info.compress_size, 1)
            and not ratio_exempt(name)
        ):
            ratio = info.file_size / max(info.compress_size, 1)
            raise ZipLimitError(
                source,
                f"member {name} unpacks from {_mb(info.compress_size)} to "
                f"{_mb(info.file_size)} ({ratio:.0f} to 1, more than {MAX_RATIO} to 1): "
                "a zip bomb, not case data",
                "it is padded or not a case file the workbench wrote",
            )
    return members


# ---------------------------------------------------------------- reading
def member_cap(info: zipfile.ZipInfo, limit: int, *, ratio: bool = True) -> int:
    """The most bytes read from ``info``: ``limit``, and (``ratio``) the ratio limit on its
    packed size."""
    if info.compress_type == zipfile.ZIP_STORED:
        return min(limit, info.compress_size)
    if not ratio:
        return limit
    return min(limit, max(RATIO_FLOOR_BYTES, MAX_RATIO * info.compress_size))


def _too_large(source: PathArg, name: str, cap: int) -> MemberTooLarge:
    return MemberTooLarge(
        source,
        f"member {name} unpacks to more than {_mb(cap)} (its header said "
        "less, or the limit for its kind is lower)",
        "it is padded or not a case file the workbench wrote",
    )


def damaged(source: PathArg, name: str, error: BaseException) -> ZipLimitError:
    """The error for a member the standard library could not read."""
    return ZipLimitError(
        source,
        f"member {name} is damaged or unreadable ({type(error).__name__}: {error})",
        "restore the case file from a backup",
    )


class _CappedStream:
    """A read-only stream over a zip member that refuses to give more than ``cap`` bytes."""

    def __init__(self, raw: IO[bytes], source: PathArg, name: str, cap: int) -> None:
        self._raw, self._source, self._name, self._cap = raw, source, name, cap
        self.count = 0

    def read(self, n: int = -1) -> bytes:
        left = self._cap + 1 - self.count
        want = left if n is None or n < 0 else min(n, left)
        data = self._raw.read(want) if want > 0 else b""
        self.count += len(data)
        if self.count > self._cap:
            raise _too_large(self._source, self._name, self._cap)
        return data

    def readable(self) -> bool:
        return True

    def close(self) -> None:
        self._raw.close()

    def __enter__(self) -> _CappedStream:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def open_member(
    archive: zipfile.ZipFile,
    info: zipfile.ZipInfo,
    source: PathArg,
    limit: int,
    *,
    ratio: bool = True,
) -> IO[bytes]:
    """A stream over a member that raises :class:`MemberTooLarge` past the member's cap.

    Errors of the standard library while opening are reported as a damaged
    member (:class:`ZipLimitError`); errors while reading are left to the
    caller (it knows whether a damaged member is fatal or an integrity finding).
    """
    try:
        raw = archive.open(info)
    except MEMBER_ERRORS as error:
        raise damaged(source, info.filename, error) from None
    cap = member_cap(info, limit, ratio=ratio)
    return cast(IO[bytes], _CappedStream(raw, source, info.filename, cap))


def read_member(
    archive: zipfile.ZipFile,
    info: zipfile.ZipInfo,
    source: PathArg,
    limit: int,
    *,
    ratio: bool = True,
) -> bytes:
    """A member's bytes: at most its cap plus one byte is decompressed.

    Raises
    ------
    ZipLimitError
        Larger than ``limit`` (or its ratio limit: :class:`MemberTooLarge`), or damaged.
    """
    try:
        with open_member(archive, info, source, limit, ratio=ratio) as stream:
            return stream.read()
    except MEMBER_ERRORS as error:
        raise damaged(source, info.filename, error) from None


@contextlib.contextmanager
def open_archive(path: PathArg, *, max_members: int = MAX_MEMBERS) -> Iterator[zipfile.ZipFile]:
    """Open ``path`` as a zip after :func:`check_directory` (no member is read).

    :class:`zipfile.BadZipFile` and other errors of the standard library
    propagate for the caller to word.
    """
    p = Path(path)
    with open(p, "rb") as stream:
        check_directory(stream, p, max_members=max_members)
        with zipfile.ZipFile(stream, "r") as archive:
            yield archive
