"""Legacy VTK ``.vtk`` files, ``DATASET POLYDATA`` only.

ASCII and BINARY (big-endian) are read, with the classic cell layout
(``POLYGONS n size`` followed by ``count i0 i1 ...`` records) and the
VTK >= 9 layout (``OFFSETS`` + ``CONNECTIVITY``).  Polygons are fanned and
triangle strips split into triangles; vertices and lines are ignored; point
and cell data are skipped.  The writer uses file version 4.2 (classic layout,
readable by every VTK) with double-precision points and ``units: mm`` and
3D Slicer's ``SPACE=RAS`` tag in the title line (Slicer reads the tag there).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from workbench.io.mesh_formats._common import (
    UNITS_NOTE,
    WRITER_NAME,
    ParsedMesh,
    Reader,
    fan_triangulate,
    format_rows,
    space_in,
    space_tag,
)

_TYPES = {
    "float": "f4",
    "double": "f8",
    "char": "i1",
    "unsigned_char": "u1",
    "short": "i2",
    "unsigned_short": "u2",
    "int": "i4",
    "unsigned_int": "u4",
    "long": "i8",
    "unsigned_long": "u8",
    "vtkidtype": "i8",
    "vtktypeint8": "i1",
    "vtktypeuint8": "u1",
    "vtktypeint16": "i2",
    "vtktypeuint16": "u2",
    "vtktypeint32": "i4",
    "vtktypeuint32": "u4",
    "vtktypeint64": "i8",
    "vtktypeuint64": "u8",
    "vtktypefloat32": "f4",
    "vtktypefloat64": "f8",
}
_CELLS = ("VERTICES", "LINES", "POLYGONS", "TRIANGLE_STRIPS")
_SECTIONS = (*_CELLS, "POINTS", "POINT_DATA", "CELL_DATA", "FIELD", "METADATA")


def _dtype(r: Reader, name: bytes | str) -> str:
    key = name.decode("ascii", "replace") if isinstance(name, bytes) else name
    try:
        return _TYPES[key.lower()]
    except KeyError:
        raise r.fail(f"unknown data type {key!r}") from None


def _int(r: Reader, token: bytes, what: str) -> int:
    try:
        value = int(token)
    except ValueError:
        raise r.fail(f"expected a whole number for {what}, found {token[:30]!r}") from None
    if value < 0:
        raise r.fail(f"negative {what}")
    return value


def classic_cells(r: Reader, n: int, flat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Split ``count i0 i1 ...`` records into (counts, corner indices)."""
    flat = flat.astype(np.int64)
    if n == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    c = int(flat[0])
    if c >= 0 and len(flat) == n * (c + 1):
        table = flat.reshape(n, c + 1)
        if np.all(table[:, 0] == c):
            return table[:, 0].copy(), table[:, 1:].ravel()
    if n > len(flat):
        raise r.fail("cell list is shorter than its declared number of cells (damaged file)")
    counts = np.empty(n, np.int64)
    keep = np.ones(len(flat), bool)
    pos, values = 0, flat.tolist()
    for k in range(n):
        if pos >= len(values) or values[pos] < 0 or pos + 1 + values[pos] > len(values):
            raise r.fail("cell list is inconsistent with its declared size (damaged file)")
        counts[k] = values[pos]
        keep[pos] = False
        pos += 1 + values[pos]
    return counts, flat[keep]


def strips_to_triangles(counts: np.ndarray, flat: np.ndarray) -> np.ndarray:
    """Triangle strips to triangles, alternating winding like VTK."""
    n_tri = np.maximum(counts - 2, 0)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
    strip = np.repeat(np.arange(len(counts)), n_tri)
    j = np.arange(int(n_tri.sum())) - (np.cumsum(n_tri) - n_tri)[strip]
    s = starts[strip] + j
    a, b, c = flat[s], flat[s + 1], flat[s + 2]
    odd = (j % 2) == 1
    return np.stack([np.where(odd, b, a), np.where(odd, a, b), c], axis=1)


class _Tokens:
    """ASCII body: a flat token stream."""

    def __init__(self, r: Reader, start: int):
        self.r, self.tokens, self.i = r, r.data[start:].split(), 0

    def more(self) -> bool:
        return self.i < len(self.tokens)

    def words(self, k: int) -> list[bytes]:
        if self.i + k > len(self.tokens):
            raise self.r.truncated("a section header")
        out = self.tokens[self.i : self.i + k]
        self.i += k
        return out

    def peek(self) -> bytes:
        return self.tokens[self.i] if self.more() else b""

    def array(self, count: int, dtype: str, what: str) -> np.ndarray:
        if self.i + count > len(self.tokens):
            raise self.r.truncated(what)
        chunk = np.array(self.tokens[self.i : self.i + count])
        self.i += count
        if dtype.startswith("f"):
            return self.r.to_float(chunk, what)
        return self.r.to_int(chunk, what)

    def skip_metadata(self) -> None:
        while self.more() and self.peek().upper().decode("ascii", "replace") not in _SECTIONS:
            self.i += 1


class _Bytes:
    """BINARY body: keyword lines followed by raw big-endian arrays."""

    def __init__(self, r: Reader, start: int):
        self.r, self.pos = r, start

    def _skip_space(self) -> None:
        data = self.r.data
        while self.pos < len(data) and data[self.pos] in b" \t\r\n":
            self.pos += 1

    def more(self) -> bool:
        self._skip_space()
        return self.pos < len(self.r.data)

    def line(self) -> list[bytes]:
        self._skip_space()
        end = self.r.data.find(b"\n", self.pos)
        end = len(self.r.data) if end < 0 else end
        words = self.r.data[self.pos : end].split()
        self.pos = end + 1
        return words

    def words(self, k: int) -> list[bytes]:
        words = self.line()
        if len(words) < k:
            raise self.r.fail(f"malformed section line {b' '.join(words)[:60]!r}")
        return words

    def peek(self) -> bytes:
        self._skip_space()
        end = self.r.data.find(b"\n", self.pos)
        words = self.r.data[self.pos : end if end >= 0 else None].split()
        return words[0] if words else b""

    def array(self, count: int, dtype: str, what: str) -> np.ndarray:
        out = self.r.frombuffer(">" + dtype, count, self.pos, what)
        self.pos += count * out.itemsize
        return out

    def skip_metadata(self) -> None:
        while self.pos < len(self.r.data):  # metadata block ends with an empty line
            end = self.r.data.find(b"\n", self.pos)
            if end < 0:
                self.pos = len(self.r.data)
                return
            line = self.r.data[self.pos : end].strip()
            self.pos = end + 1
            if not line:
                return


def _section_loop(
    r: Reader, s: _Tokens | _Bytes
) -> tuple[np.ndarray | None, dict[str, tuple[np.ndarray, np.ndarray]]]:
    points = None
    cells: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    while s.more():
        key = s.peek().upper().decode("ascii", "replace")
        if key in ("POINT_DATA", "CELL_DATA", "FIELD"):
            break
        if key == "METADATA":
            s.words(1)
            s.skip_metadata()
        elif key == "POINTS":
            _, n_word, typ = s.words(3)[:3]
            n = _int(r, n_word, "number of points")
            points = s.array(3 * n, _dtype(r, typ), "the points").reshape(n, 3)
        elif key in _CELLS:
            _, a_word, b_word = s.words(3)[:3]
            a, b = _int(r, a_word, f"{key} count"), _int(r, b_word, f"{key} size")
            if s.peek().upper() == b"OFFSETS":
                typ = s.words(2)[1]
                offsets = s.array(a, _dtype(r, typ), f"the {key} offsets").astype(np.int64)
                typ = s.words(2)[1]
                conn = s.array(b, _dtype(r, typ), f"the {key} connectivity").astype(np.int64)
                steps = np.diff(offsets)
                if len(offsets) and (offsets[0] != 0 or offsets[-1] != b or np.any(steps < 0)):
                    raise r.fail(f"{key} offsets are inconsistent (damaged file)")
                cells[key] = (steps, conn)
            else:
                flat = s.array(b, "i4", f"the {key} cell list")
                cells[key] = classic_cells(r, a, flat)
        else:
            raise r.fail(f"unexpected section {key[:40]!r}")
    return points, cells


def read(path: Path, data: bytes) -> ParsedMesh:
    """Parse legacy VTK bytes; vertices in file units."""
    r = Reader(path, data, "VTK")
    lines: list[bytes] = []
    pos = 0
    while len(lines) < 4:
        end = data.find(b"\n", pos)
        if end < 0:
            raise r.truncated("the header")
        if len(lines) == 1 or data[pos:end].strip():  # the title line may be empty
            lines.append(data[pos:end].strip())
        pos = end + 1
    if not lines[0].lower().startswith(b"# vtk datafile"):
        raise r.fail("not a legacy VTK file (first line must be '# vtk DataFile Version ...')")
    mode = lines[2].upper()
    if mode not in (b"ASCII", b"BINARY"):
        raise r.fail(f"third line must be ASCII or BINARY, found {lines[2][:30]!r}")
    dataset = lines[3].split()
    if len(dataset) < 2 or dataset[0].upper() != b"DATASET" or dataset[1].upper() != b"POLYDATA":
        kind = dataset[1].decode("ascii", "replace") if len(dataset) > 1 else "?"
        raise r.fail(
            f"dataset type {kind} is not supported, only POLYDATA surface meshes",
            "extract the surface (e.g. in ParaView) and save it as polydata",
        )
    binary = mode == b"BINARY"
    stream = _Bytes(r, pos) if binary else _Tokens(r, pos)
    points, cells = _section_loop(r, stream)
    if points is None:
        raise r.fail("the file has no POINTS section")
    tris = []
    if "POLYGONS" in cells:
        tris.append(fan_triangulate(*cells["POLYGONS"], r))
    if "TRIANGLE_STRIPS" in cells:
        tris.append(strips_to_triangles(*cells["TRIANGLE_STRIPS"]))
    ignored = [k.lower() for k in ("VERTICES", "LINES") if k in cells and len(cells[k][0])]
    if ignored:
        r.note(f"VTK {' and '.join(ignored)} cells were ignored")
    faces = np.concatenate(tris) if tris else np.zeros((0, 3), np.int64)
    parsed = r.finish(points, faces)
    parsed.space = space_in(lines[1])  # the title line, where Slicer writes and reads the tag
    return parsed


def encode(
    vertices: np.ndarray, faces: np.ndarray, binary: bool = True, *, space: str = "RAS"
) -> bytes:
    """Legacy VTK 4.2 polydata: BINARY (default, big-endian) or ASCII."""
    n, m = len(vertices), len(faces)
    head = (
        f"# vtk DataFile Version 4.2\nmesh written by {WRITER_NAME}, {UNITS_NOTE}, {space_tag(space)}\n"
        f"{'BINARY' if binary else 'ASCII'}\nDATASET POLYDATA\nPOINTS {n} double\n"
    ).encode("ascii")
    cells = np.empty((m, 4), np.int64)
    cells[:, 0] = 3
    cells[:, 1:] = faces
    poly_head = f"POLYGONS {m} {4 * m}\n".encode("ascii")
    if binary:
        pts = np.ascontiguousarray(vertices, ">f8").tobytes()
        return head + pts + b"\n" + poly_head + cells.astype(">i4").tobytes() + b"\n"
    pts = format_rows("%r %r %r\n", vertices).encode("ascii")
    return head + pts + poly_head + format_rows("%d %d %d %d\n", cells).encode("ascii")
