"""Stanford PLY: ascii, binary little- and big-endian.

Reads the ``vertex`` element's x/y/z (any numeric type) and the ``face``
element's ``vertex_indices`` / ``vertex_index`` list (any count and index
type); other elements and properties are skipped, except per-vertex colours
(``red``/``green``/``blue``, or ``r``/``g``/``b``, or ``diffuse_red``... ;
uchar, ushort or float 0..1; alpha ignored), which are kept as
:attr:`ParsedMesh.vertex_rgb` (uint8, aligned with the vertices).  Polygons
are split into triangle fans.  Writes double-precision vertices (optionally
``uchar`` red/green/blue) and ``uchar int`` faces with a ``comment units: mm``
line and a ``comment SPACE=RAS`` line (3D Slicer's coordinate-system tag: the
workbench's mesh frame is the frame its landmark files call RAS); a file's own
``SPACE=`` comment is returned in :attr:`ParsedMesh.space`.

Header comments: :func:`encode` and :func:`write` take extra ``comments``
(one header line each, e.g. ``credit: Courtesy of ...`` for data that must
carry a credit); :func:`read` returns them in :attr:`PlyMesh.comments`, and
:func:`header_comments` reads only the header of a file.  Vertex units are
those of the file (mm for files this module writes).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path

import numpy as np

from workbench.core.errors import InputError
from workbench.core.mesh import Mesh
from workbench.io.atomic import write_bytes_atomic
from workbench.io.mesh_formats._common import (
    UNITS_NOTE,
    WRITER_NAME,
    ParsedMesh,
    Reader,
    colour_bytes,
    fan_triangulate,
    format_rows,
    space_in,
    space_tag,
)

_TYPES = {
    "char": "i1",
    "int8": "i1",
    "uchar": "u1",
    "uint8": "u1",
    "short": "i2",
    "int16": "i2",
    "ushort": "u2",
    "uint16": "u2",
    "int": "i4",
    "int32": "i4",
    "uint": "u4",
    "uint32": "u4",
    "float": "f4",
    "float32": "f4",
    "double": "f8",
    "float64": "f8",
}
_FORMATS = {"ascii": "", "binary_little_endian": "<", "binary_big_endian": ">"}
_FACE_LISTS = ("vertex_indices", "vertex_index")
_COLOUR_NAMES = (
    ("red", "green", "blue"),
    ("r", "g", "b"),
    ("diffuse_red", "diffuse_green", "diffuse_blue"),
)
_RGB_PROPERTIES = "property uchar red\nproperty uchar green\nproperty uchar blue\n"
_HEADER_LIMIT = 1 << 20  # header_comments reads at most this many bytes looking for end_header


@dataclass
class PlyMesh(ParsedMesh):
    """:class:`ParsedMesh` plus the header's ``comment`` lines (text after ``comment``)."""

    comments: list[str] = field(default_factory=list)


@dataclass
class _Property:
    name: str
    dtype: str  # numpy kind+size, e.g. "f4"
    count_dtype: str | None = None  # set for list properties


@dataclass
class _Element:
    name: str
    count: int
    properties: list[_Property]


def _parse_header(r: Reader) -> tuple[str, list[_Element], int]:
    end = r.data.find(b"end_header")
    if not r.data.startswith(b"ply") or end < 0:
        raise r.fail("not a PLY file (missing 'ply' magic line or 'end_header')")
    body = r.data.find(b"\n", end)
    if body < 0:
        raise r.truncated("the header")
    text = r.data[:end].decode("ascii", errors="replace")
    fmt = None
    elements: list[_Element] = []
    for number, line in enumerate(text.splitlines(), start=1):
        words = line.split()
        if not words or words[0] in ("ply", "comment", "obj_info"):
            continue
        try:
            if words[0] == "format":
                fmt = words[1]
                if fmt not in _FORMATS:
                    raise r.fail(f"unknown PLY format '{fmt}'", "expected ascii or binary")
            elif words[0] == "element":
                elements.append(_Element(words[1], int(words[2]), []))
            elif words[0] == "property":
                if not elements:
                    raise r.fail(f"header line {number}: property before any element")
                if words[1] == "list":
                    prop = _Property(words[4], _TYPES[words[3]], _TYPES[words[2]])
                else:
                    prop = _Property(words[2], _TYPES[words[1]])
                elements[-1].properties.append(prop)
            else:
                raise r.fail(f"header line {number} not understood: {line.strip()!r}")
        except (IndexError, ValueError):
            raise r.fail(f"header line {number} is malformed: {line.strip()!r}") from None
        except KeyError as exc:
            raise r.fail(f"header line {number}: unknown property type {exc.args[0]!r}") from None
    if fmt is None:
        raise r.fail("the header has no 'format' line")
    if any(e.count < 0 for e in elements):
        raise r.fail("negative element count in the header")
    return fmt, elements, body + 1


def _xyz_columns(r: Reader, element: _Element) -> list[int]:
    names = [p.name for p in element.properties]
    try:
        cols = [names.index(axis) for axis in "xyz"]
    except ValueError:
        raise r.fail("the vertex element has no x, y and z properties") from None
    if any(element.properties[c].count_dtype for c in cols):
        raise r.fail("vertex x/y/z are lists, expected numbers")
    return cols


def _colour_columns(element: _Element) -> list[int] | None:
    """Columns of the vertex colour channels, or None when there are none."""
    names = [p.name for p in element.properties]
    for triple in _COLOUR_NAMES:
        if all(n in names for n in triple):
            cols = [names.index(n) for n in triple]
            if not any(element.properties[c].count_dtype for c in cols):
                return cols
    return None


def _colour_scale(element: _Element, cols: list[int]) -> float | None:
    """Full scale of the colour channels' type (None for floating point)."""
    kind = np.dtype(element.properties[cols[0]].dtype)
    return None if kind.kind == "f" else float(np.iinfo(kind).max)


def _face_list(r: Reader, element: _Element) -> int:
    for i, p in enumerate(element.properties):
        if p.name in _FACE_LISTS and p.count_dtype:
            return i
    raise r.fail("the face element has no 'vertex_indices' list")


# ------------------------------------------------------------------ ascii
def _read_ascii(r: Reader, elements: list[_Element], start: int) -> ParsedMesh:
    tokens = np.array(r.data[start:].split())
    values = r.to_float(tokens, "numbers") if tokens.size else np.zeros(0)
    pos = 0
    vertices = faces = rgb = None
    for el in elements:
        if vertices is not None and faces is not None:
            break
        lists = [i for i, p in enumerate(el.properties) if p.count_dtype]
        width = len(el.properties)
        if not lists:
            n = el.count * width
            if pos + n > len(values):
                raise r.truncated(f"the {el.name} element")
            table = values[pos : pos + n].reshape(el.count, width)
            pos += n
            if el.name == "vertex":
                vertices = table[:, _xyz_columns(r, el)]
                cols = _colour_columns(el)
                if cols is not None:
                    rgb = colour_bytes(table[:, cols], _colour_scale(el, cols))
            continue
        wanted = _face_list(r, el) if el.name == "face" else lists[0]
        counts, flat, pos = _ascii_rows(r, el, values, pos, wanted)
        if el.name == "face":
            faces = fan_triangulate(counts, r.to_int(flat, "face indices"), r)
    if vertices is None or faces is None:
        raise r.fail(_missing_element(vertices))
    parsed = r.finish(vertices, faces)
    parsed.vertex_rgb = rgb
    return parsed


def _ascii_rows(
    r: Reader, el: _Element, values: np.ndarray, pos: int, wanted: int
) -> tuple[np.ndarray, np.ndarray, int]:
    """Rows of an element with list properties: fast path when all lists match."""
    props = el.properties
    if el.count == 0:
        return np.zeros(0, np.int64), np.zeros(0), pos
    if el.count > len(values) - pos:  # every row has at least one number
        raise r.truncated(f"the {el.name} element")
    if len([p for p in props if p.count_dtype]) == 1 and pos + wanted < len(values):
        c = values[pos + wanted]
        width = len(props) + int(c)
        n = el.count * width
        if c >= 0 and pos + n <= len(values):
            table = values[pos : pos + n].reshape(el.count, width)
            if np.all(table[:, wanted] == c):
                flat = table[:, wanted + 1 : wanted + 1 + int(c)].ravel()
                return np.full(el.count, int(c)), flat, pos + n
    counts = np.empty(el.count, np.int64)
    chunks = []
    for row in range(el.count):
        for i, p in enumerate(props):
            if pos >= len(values):
                raise r.truncated(f"the {el.name} element")
            if p.count_dtype:
                k = int(values[pos])
                if k < 0 or pos + 1 + k > len(values):
                    raise r.truncated(f"the {el.name} element")
                if i == wanted:
                    counts[row] = k
                    chunks.append(values[pos + 1 : pos + 1 + k])
                pos += 1 + k
            else:
                pos += 1
    flat = np.concatenate(chunks) if chunks else np.zeros(0)
    return counts, flat, pos


# ------------------------------------------------------------------ binary
def _read_binary(r: Reader, elements: list[_Element], start: int, order: str) -> ParsedMesh:
    pos = start
    vertices = faces = rgb = None
    for el in elements:
        if vertices is not None and faces is not None:
            break
        if not any(p.count_dtype for p in el.properties):
            dtype = np.dtype([(f"p{i}", order + p.dtype) for i, p in enumerate(el.properties)])
            table = r.frombuffer(dtype, el.count, pos, f"the {el.name} element")
            pos += el.count * dtype.itemsize
            if el.name == "vertex":
                cols = _xyz_columns(r, el)
                vertices = np.stack([table[f"p{c}"].astype(np.float64) for c in cols], axis=1)
                colour = _colour_columns(el)
                if colour is not None:
                    channels = np.stack([table[f"p{c}"] for c in colour], axis=1)
                    rgb = colour_bytes(channels, _colour_scale(el, colour))
            continue
        wanted = _face_list(r, el) if el.name == "face" else 0
        counts, flat, pos = _binary_rows(r, el, pos, order, wanted)
        if el.name == "face":
            faces = fan_triangulate(counts, flat, r)
    if vertices is None or faces is None:
        raise r.fail(_missing_element(vertices))
    parsed = r.finish(vertices, faces)
    parsed.vertex_rgb = rgb
    return parsed


def _binary_rows(
    r: Reader, el: _Element, pos: int, order: str, wanted: int
) -> tuple[np.ndarray, np.ndarray, int]:
    props = el.properties
    if el.count == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), pos
    if el.count > len(r.data) - pos:  # every row has at least one byte
        raise r.truncated(f"the {el.name} element")
    # fast path: every row has the same list lengths as the first row
    fields, offset, first = [], pos, []
    for i, p in enumerate(props):
        if p.count_dtype:
            c = int(r.frombuffer(order + p.count_dtype, 1, offset, f"the {el.name} element")[0])
            first.append(c)
            fields += [(f"c{i}", order + p.count_dtype), (f"p{i}", order + p.dtype, (max(c, 0),))]
            offset += np.dtype(p.count_dtype).itemsize + max(c, 0) * np.dtype(p.dtype).itemsize
        else:
            fields.append((f"p{i}", order + p.dtype))
            offset += np.dtype(p.dtype).itemsize
    dtype = np.dtype(fields)
    if pos + el.count * dtype.itemsize <= len(r.data):
        table = np.frombuffer(r.data, dtype, el.count, pos)
        lists = [i for i, p in enumerate(props) if p.count_dtype]
        if all(np.all(table[f"c{i}"] == c) for i, c in zip(lists, first, strict=False)):
            flat = table[f"p{wanted}"].reshape(-1).astype(np.int64)
            counts = np.full(el.count, first[lists.index(wanted)])
            return counts, flat, pos + el.count * dtype.itemsize
    # general path: row by row
    counts = np.empty(el.count, np.int64)
    chunks = []
    for row in range(el.count):
        for i, p in enumerate(props):
            if p.count_dtype:
                k = int(r.frombuffer(order + p.count_dtype, 1, pos, f"the {el.name} element")[0])
                pos += np.dtype(p.count_dtype).itemsize
                items = r.frombuffer(order + p.dtype, k, pos, f"the {el.name} element")
                pos += k * items.itemsize
                if i == wanted:
                    counts[row] = k
                    chunks.append(items)
            else:
                pos += np.dtype(p.dtype).itemsize
    if pos > len(r.data):
        raise r.truncated(f"the {el.name} element")
    flat = np.concatenate(chunks).astype(np.int64) if chunks else np.zeros(0, np.int64)
    return counts, flat, pos


def _comments(data: bytes, end: int) -> list[str]:
    """Text of the ``comment`` lines before byte ``end`` (the ``end_header`` keyword)."""
    text = data[:end].decode("utf-8", errors="replace")
    out = []
    for line in text.splitlines():
        words = line.split(None, 1)
        if words and words[0] == "comment":
            out.append(words[1].strip() if len(words) > 1 else "")
    return out


def _missing_element(vertices: np.ndarray | None) -> str:
    if vertices is not None:
        return (
            f"holds {len(vertices)} points and no 'face' element: a point cloud, not a "
            "triangle surface (mesh it first, e.g. Poisson reconstruction in MeshLab)"
        )
    return "the file needs both a 'vertex' and a 'face' element"


def read(path: Path, data: bytes) -> PlyMesh:
    """Parse PLY bytes; vertices in file units, header comments in ``comments``."""
    r = Reader(path, data, "PLY")
    fmt, elements, start = _parse_header(r)
    names = {e.name for e in elements}
    extra = sorted(names - {"vertex", "face"})
    if extra:
        r.note(f"PLY elements ignored: {', '.join(extra)}")
    if fmt == "ascii":
        parsed = _read_ascii(r, elements, start)
    else:
        parsed = _read_binary(r, elements, start, _FORMATS[fmt])
    comments = _comments(data, data.find(b"end_header"))
    return PlyMesh(
        parsed.vertices,
        parsed.faces,
        parsed.messages,
        comments,
        vertex_rgb=parsed.vertex_rgb,
        # the first comment naming a space, as Slicer's model reader takes it
        space=next((s for s in map(space_in, comments) if s is not None), None),
    )


def header_comments(source: str | PathLike[str] | bytes) -> list[str]:
    """The ``comment`` lines of a PLY header (text after ``comment``), without reading the body.

    ``source`` is a path or the file's bytes.  Raises
    :class:`~workbench.core.errors.InputError` when it is not a PLY file
    (no ``ply`` magic line or no ``end_header`` within the first MiB).
    """
    if isinstance(source, bytes):
        path, data = Path("<bytes>"), source[:_HEADER_LIMIT]
    else:
        path = Path(source)
        with open(path, "rb") as stream:
            data = stream.read(_HEADER_LIMIT)
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise Reader(path, data, "PLY").fail(
            "not a PLY file (missing 'ply' magic line or 'end_header')"
        )
    return _comments(data, end)


def _comment_lines(comments: Iterable[str]) -> str:
    lines = []
    for comment in comments:
        text = str(comment)
        if "\n" in text or "\r" in text:
            raise ValueError(f"a PLY header comment must be one line, got {text!r}")
        if not text.isascii():
            raise ValueError(f"a PLY header comment must be ASCII text, got {text!r}")
        if "end_header" in text:
            raise ValueError("a PLY header comment cannot contain 'end_header'")
        lines.append(f"comment {text}\n")
    return "".join(lines)


def encode(
    vertices: np.ndarray,
    faces: np.ndarray,
    binary: bool = True,
    comments: Iterable[str] = (),
    units: str = "mm",
    vertex_rgb: np.ndarray | None = None,
    space: str = "RAS",
    vertex_scalars: Mapping[str, np.ndarray] | None = None,
) -> bytes:
    """PLY bytes: binary little endian (default) or ascii, double vertices.

    ``vertex_rgb`` ``(n, 3)`` uint8 adds ``uchar red/green/blue`` vertex
    properties; ``vertex_scalars`` ``{name: (n,)}`` adds ``float`` vertex
    properties after them (e.g. ``band_mm``, which ParaView, CloudCompare and
    MeshLab show as a scalar field).

    ``comments`` are extra header lines (``comment TEXT``), written after
    the units and writer comments; each must be one line of ASCII text
    (ValueError otherwise).  ``units`` is what the ``comment units:`` line
    states: "mm" unless the caller writes the numbers in other units.
    ``space`` is the frame the ``comment SPACE=`` line names for 3D Slicer:
    "RAS" (the workbench's mesh frame) unless the numbers are LPS.
    """
    fmt = "binary_little_endian" if binary else "ascii"
    scalars = {k: np.asarray(v, np.float32) for k, v in (vertex_scalars or {}).items()}
    for name, v in scalars.items():
        if not name.isidentifier() or not name.isascii():
            raise ValueError(f"vertex property name {name!r} is not a plain identifier")
        if v.shape != (len(vertices),):
            raise ValueError(f"expected ({len(vertices)},) values for {name}, got {v.shape}")
    scalar_props = "".join(f"property float {name}\n" for name in scalars)
    units_note = UNITS_NOTE if units == "mm" else f"units: {units}"
    _comment_lines([units_note])  # one line of ASCII text, like the other comments
    header = (
        f"ply\nformat {fmt} 1.0\ncomment {units_note}\ncomment {space_tag(space)}\n"
        f"comment written by {WRITER_NAME}\n"
        f"{_comment_lines(comments)}"
        f"element vertex {len(vertices)}\n"
        "property double x\nproperty double y\nproperty double z\n"
        f"{_RGB_PROPERTIES if vertex_rgb is not None else ''}"
        f"{scalar_props}"
        f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n"
    ).encode("ascii")
    if vertex_rgb is not None:
        rgb = np.asarray(vertex_rgb)
        if rgb.shape != (len(vertices), 3):
            raise ValueError(f"expected ({len(vertices)}, 3) vertex colours, got {rgb.shape}")
        rgb = np.clip(np.rint(rgb), 0, 255).astype(np.uint8)
    if scalars:
        return _encode_with_scalars(
            header, vertices, faces, rgb if vertex_rgb is not None else None, scalars, binary
        )
    if binary:
        rec = np.empty(len(faces), np.dtype([("n", "u1"), ("i", "<i4", (3,))]))
        rec["n"] = 3
        rec["i"] = faces
        if vertex_rgb is None:
            verts = np.ascontiguousarray(vertices, "<f8").tobytes()
        else:
            table = np.empty(len(vertices), np.dtype([("p", "<f8", (3,)), ("c", "u1", (3,))]))
            table["p"], table["c"] = vertices, rgb
            verts = table.tobytes()
        return header + verts + rec.tobytes()
    if vertex_rgb is None:
        body = format_rows("%r %r %r\n", vertices)
    else:
        rows = np.empty((len(vertices), 6), object)
        rows[:, :3], rows[:, 3:] = np.asarray(vertices, np.float64), rgb.astype(int)
        body = format_rows("%r %r %r %d %d %d\n", rows)
    body += format_rows("3 %d %d %d\n", faces)
    return header + body.encode("ascii")


def _encode_with_scalars(
    header: bytes,
    vertices: np.ndarray,
    faces: np.ndarray,
    rgb: np.ndarray | None,
    scalars: Mapping[str, np.ndarray],
    binary: bool,
) -> bytes:
    """The body of :func:`encode` when float vertex properties follow xyz (and the colours)."""
    fields: list[tuple[str, str, tuple[int, ...]]] = [("p", "<f8", (3,))]
    if rgb is not None:
        fields.append(("c", "u1", (3,)))
    fields += [(f"s{i}", "<f4", ()) for i in range(len(scalars))]
    table = np.empty(len(vertices), np.dtype(fields))
    table["p"] = vertices
    if rgb is not None:
        table["c"] = rgb
    for i, v in enumerate(scalars.values()):
        table[f"s{i}"] = v
    if binary:
        rec = np.empty(len(faces), np.dtype([("n", "u1"), ("i", "<i4", (3,))]))
        rec["n"] = 3
        rec["i"] = faces
        return header + table.tobytes() + rec.tobytes()
    cols = [np.asarray(vertices, np.float64).astype(object)]
    fmt = "%r %r %r"
    if rgb is not None:
        cols.append(rgb.astype(int).astype(object))
        fmt += " %d %d %d"
    for v in scalars.values():
        cols.append(v.astype(np.float64).astype(object)[:, None])
        fmt += " %r"
    body = format_rows(fmt + "\n", np.hstack(cols))
    body += format_rows("3 %d %d %d\n", faces)
    return header + body.encode("ascii")


def write(
    path: str | PathLike[str],
    mesh: Mesh,
    binary: bool = True,
    comments: Iterable[str] = (),
    units: str = "mm",
    space: str = "RAS",
    vertex_scalars: Mapping[str, np.ndarray] | None = None,
) -> Path:
    """Write a PLY mesh (vertices in mm) atomically with extra header ``comments``
    (and ``vertex_scalars``, float vertex properties: :func:`encode`).

    Same checks, errors and atomic write as
    :func:`workbench.io.meshes.write_mesh` (which writes no extra comments);
    raises ValueError for a comment that is not one line of ASCII text.
    """

    path = Path(path)
    if path.suffix.lower() != ".ply":
        raise InputError(path, "expected a .ply file name for a PLY mesh with header comments")
    if not isinstance(mesh, Mesh):
        raise InputError(path, f"expected a Mesh to write, got {type(mesh).__name__}")
    if not path.parent.is_dir():
        raise InputError(path, "the folder does not exist", "create it first")
    if path.is_dir():
        raise InputError(path, "is a folder, cannot write a mesh file there")
    payload = encode(
        mesh.vertices,
        np.asarray(mesh.faces),
        binary=binary,
        comments=comments,
        units=units,
        space=space,
        vertex_scalars=vertex_scalars,
    )
    try:
        write_bytes_atomic(path, payload)
    except OSError as exc:
        raise InputError(path, f"cannot be written ({exc.strerror or exc})") from None
    return path
