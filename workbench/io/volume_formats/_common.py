"""Shared helpers for the raw-data volume formats (NRRD, MetaImage).

Both formats describe a block of voxels, x (column, i) fastest, stored in one
or several data files (attached to the header, detached, a numbered file
pattern or an explicit list), optionally compressed.  This module reads and
decodes such blocks into a ``(nk, nj, ni)`` array with the native dtype.
"""

from __future__ import annotations

import bz2
import gzip
import re
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from workbench.core.errors import InputError

#: Encodings understood by :func:`decode_block` (NRRD spellings; MetaImage maps onto them).
ENCODINGS = {
    "raw": "raw",
    "gzip": "gzip",
    "gz": "gzip",
    "zlib": "zlib",
    "bzip2": "bzip2",
    "bz2": "bzip2",
    "ascii": "ascii",
    "text": "ascii",
    "txt": "ascii",
    "hex": "hex",
}


@dataclass(frozen=True)
class DataSpec:
    """Where and how the voxel block is stored.

    Parameters
    ----------
    files : list of Path
        Data files, in order; their decoded contents are concatenated.
    offset : int
        For attached data: byte position where the data start in ``files[0]``.
    byte_skip : int
        Bytes to skip in each file (after decompression for compressed
        encodings); -1 means "the data are the last bytes of the file" (raw).
    line_skip : int
        Text lines to skip at the start of each file (before decompression).
    encoding : str
        One of the values of :data:`ENCODINGS`.
    dtype : numpy dtype
        Voxel type including byte order.
    """

    files: list[Path]
    offset: int
    byte_skip: int
    line_skip: int
    encoding: str
    dtype: np.dtype


def open_header(path: Path):
    """Open a header file for reading, turning OS errors into :class:`InputError`."""
    try:
        return open(path, "rb")
    except FileNotFoundError:
        raise InputError(path, "file not found") from None
    except OSError as exc:
        raise InputError(path, f"cannot open: {exc.strerror or exc}") from None


def expand_file_pattern(header: Path, pattern: str, first: int, last: int, step: int) -> list[Path]:
    """Numbered data files ``pattern % n`` for n = first, first+step, ... last (inclusive)."""
    if step == 0:
        raise InputError(header, f"data file pattern {pattern!r} has a step of 0")
    if (last - first) * step < 0:
        raise InputError(header, f"data file pattern range {first}..{last} step {step} is empty")
    try:
        numbers = range(first, last + (1 if step > 0 else -1), step)
        names = [pattern % n for n in numbers]
    except (TypeError, ValueError) as exc:
        raise InputError(header, f"cannot expand data file pattern {pattern!r}: {exc}") from None
    return [header.parent / name for name in names]


def _skip_lines(blob: bytes, n: int, source: Path) -> bytes:
    pos = 0
    for _ in range(n):
        nl = blob.find(b"\n", pos)
        if nl < 0:
            raise InputError(source, f"the file has fewer than {n} lines to skip")
        pos = nl + 1
    return blob[pos:]


def _decompress(blob: bytes, encoding: str, source: Path) -> bytes:
    try:
        if encoding == "gzip":
            return gzip.decompress(blob)
        if encoding == "zlib":
            # zlib or gzip header (wbits 47 = auto-detect)
            return zlib.decompressobj(47).decompress(blob)
        if encoding == "bzip2":
            return bz2.decompress(blob)
    except (OSError, EOFError, zlib.error, ValueError) as exc:
        raise InputError(source, f"cannot decompress the {encoding} data: {exc}") from None
    return blob


def _parse_text(blob: bytes, dtype: np.dtype, encoding: str, source: Path) -> np.ndarray:
    text = blob.decode("latin-1")
    if encoding == "hex":
        try:
            raw = bytes.fromhex(re.sub(r"\s+", "", text))
        except ValueError as exc:
            raise InputError(source, f"invalid hex data: {exc}") from None
        return np.frombuffer(raw, dtype=dtype)
    tokens = text.replace(",", " ").split()
    try:
        values = np.array([float(t) for t in tokens], dtype=np.float64)
    except ValueError as exc:
        raise InputError(source, f"invalid number in ASCII data: {exc}") from None
    return values.astype(dtype.newbyteorder("="))


def read_one_file(path: Path, spec: DataSpec, count: int, offset: int = 0) -> np.ndarray:
    """Read ``count`` voxels from one data file (see :class:`DataSpec`)."""
    try:
        with open(path, "rb") as fh:
            fh.seek(offset)
            blob = fh.read()
    except FileNotFoundError:
        raise InputError(path, "data file not found (named in the volume header)") from None
    except OSError as exc:
        raise InputError(path, f"cannot read data file: {exc.strerror or exc}") from None
    if spec.line_skip:
        blob = _skip_lines(blob, spec.line_skip, path)
    if spec.encoding in ("ascii", "hex"):
        values = _parse_text(blob[max(spec.byte_skip, 0) :], spec.dtype, spec.encoding, path)
    else:
        blob = _decompress(blob, spec.encoding, path)
        need = count * spec.dtype.itemsize
        if spec.byte_skip == -1:
            if spec.encoding != "raw":
                raise InputError(path, "byte skip -1 is only allowed with raw encoding")
            start = max(len(blob) - need, 0)
        else:
            start = spec.byte_skip
        available = max(len(blob) - start, 0) // spec.dtype.itemsize
        n = min(count, available)
        values = (
            np.frombuffer(blob, dtype=spec.dtype, count=n, offset=start)
            if n
            else np.zeros(0, spec.dtype)
        )
    if values.size < count:
        raise InputError(
            path,
            f"expected {count} voxels ({count * spec.dtype.itemsize} bytes) of "
            f"{spec.dtype.name} data, found only {values.size}",
            hint="the file is truncated or the header sizes/type are wrong",
        )
    return values[:count]


def read_block(spec: DataSpec, shape_kji: tuple[int, int, int], header: Path) -> np.ndarray:
    """Read and decode the whole voxel block as a native-endian ``(nk, nj, ni)`` array."""
    total = int(np.prod(shape_kji))
    n_files = len(spec.files)
    if n_files == 0:
        raise InputError(header, "the header names no data file")
    if total % n_files:
        raise InputError(
            header,
            f"{total} voxels cannot be split evenly over {n_files} data files",
            hint="check the sizes and the data file list/pattern",
        )
    per_file = total // n_files
    out = np.empty(total, dtype=spec.dtype.newbyteorder("="))
    for n, path in enumerate(spec.files):
        values = read_one_file(path, spec, per_file, offset=spec.offset if n == 0 else 0)
        out[n * per_file : (n + 1) * per_file] = values
    return out.reshape(shape_kji)


def check_sizes(header: Path, sizes: list[int]) -> tuple[int, int, int]:
    """Validate 3 positive sizes given x-fastest; return the (nk, nj, ni) array shape."""
    if len(sizes) != 3 or any(s < 1 for s in sizes):
        raise InputError(header, f"expected 3 positive sizes for a 3-D volume, got {sizes}")
    if sizes[2] < 2:
        raise InputError(header, "the volume has a single slice; an iso-surface needs at least 2")
    return sizes[2], sizes[1], sizes[0]


def parse_floats(text: str, header: Path, what: str, n: int | None = None) -> list[float]:
    """Whitespace/comma separated numbers (brackets ignored)."""
    tokens = re.sub(r"[(),\[\]]", " ", text).split()
    try:
        values = [float(t) for t in tokens]
    except ValueError:
        raise InputError(header, f"cannot read numbers from {what}: {text!r}") from None
    if n is not None and len(values) != n:
        raise InputError(header, f"{what} should have {n} numbers, got {len(values)}: {text!r}")
    return values
