"""Wavefront OBJ: ``v`` and ``f`` records only.

Face corners may be written ``v``, ``v/vt``, ``v//vn`` or ``v/vt/vn``; indices
are 1-based, negative indices count back from the latest vertex.  Polygons are
split into triangle fans.  Texture coordinates, normals, groups, objects,
materials, smoothing groups, lines and comments are ignored.
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np

from workbench.io.mesh_formats._common import (
    UNITS_NOTE,
    WRITER_NAME,
    ParsedMesh,
    Reader,
    fan_triangulate,
    format_rows,
)

_SLASH_SUFFIX = re.compile(r"/\S*")
_INDENTED = re.compile(r"^[ \t]", re.MULTILINE)
_V = ("v ", "v\t")
_F = ("f ", "f\t")


def _fast_table(
    lines: list[str], dtype: type, usecols: tuple[int, ...] | None
) -> np.ndarray | None:
    """``np.loadtxt`` (C speed) on uniform numeric rows; None if they are not uniform."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return np.loadtxt(lines, dtype=dtype, usecols=usecols, ndmin=2, comments="#")
    except ValueError:
        return None


def _vertex_table(r: Reader, lines: list[str]) -> np.ndarray:
    table = _fast_table(lines, np.float64, (1, 2, 3))
    if table is not None:
        return table
    rows = [line.split("#")[0].split() for line in lines]
    for i, row in enumerate(rows):
        if len(row) < 4:
            raise r.fail(f"vertex {i + 1} has fewer than 3 coordinates: {lines[i].strip()[:60]!r}")
    return r.to_float([row[1:4] for row in rows], "vertex coordinates")


def _face_corners(r: Reader, lines: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """Corner counts and 1-based (possibly negative) indices of the ``f`` lines."""
    stripped = _SLASH_SUFFIX.sub("", "\n".join(lines)).split("\n")
    table = _fast_table([line[1:] for line in stripped], np.int64, None)
    if table is not None and table.shape[0] == len(lines):
        return np.full(len(lines), table.shape[1]), table.ravel()
    rows = [line.split("#")[0].split()[1:] for line in stripped]
    counts = np.array([len(row) for row in rows], np.int64)
    flat = r.to_int([tok for row in rows for tok in row], "face vertex indices")
    return counts, flat


def read(path: Path, data: bytes) -> ParsedMesh:
    """Parse OBJ bytes; vertices in file units."""
    r = Reader(path, data, "OBJ")
    r.index_base = 1
    text = data.decode("utf-8", errors="replace")
    if "\\\n" in text:  # line continuation
        text = text.replace("\\\r\n", " ").replace("\\\n", " ")
    lines = text.splitlines()
    if _INDENTED.search(text):
        lines = [line.lstrip() for line in lines]
    v_lines = [line for line in lines if line[:2] in _V]
    f_lines = [line for line in lines if line[:2] in _F]
    if not v_lines:
        raise r.fail("no vertex ('v') lines found: not an OBJ mesh, or the file is empty")
    if not f_lines:
        raise r.fail(
            "no face ('f') lines found: the file contains no triangles",
            "a point cloud cannot be used as a surface mesh",
        )
    vertices = _vertex_table(r, v_lines)
    counts, idx = _face_corners(r, f_lines)
    if np.any(counts < 3):
        k = int(np.flatnonzero(counts < 3)[0])
        raise r.fail(
            f"face {k + 1} has fewer than 3 corners (a damaged or truncated file?)",
            "every 'f' line needs at least 3 vertex indices",
        )
    line_of = np.repeat(np.arange(len(counts)), counts)
    if np.any(idx == 0):
        k = int(line_of[np.flatnonzero(idx == 0)[0]])
        raise r.fail(f"face {k + 1} uses vertex index 0 (OBJ numbers vertices from 1)")
    if np.any(idx < 0):  # relative to the vertices defined so far
        seen, n_before = 0, []
        for line in lines:
            head = line[:2]
            if head in _V:
                seen += 1
            elif head in _F:
                n_before.append(seen)
        zero_based = np.where(idx > 0, idx - 1, np.asarray(n_before, np.int64)[line_of] + idx)
    else:
        zero_based = idx - 1
    return r.finish(vertices, fan_triangulate(counts, zero_based, r))


def encode(vertices: np.ndarray, faces: np.ndarray, binary: bool = True) -> bytes:
    """OBJ text (``binary`` is ignored: OBJ is always text), exact doubles."""
    del binary
    head = (
        f"# {UNITS_NOTE}\n# written by {WRITER_NAME}\n"
        f"# {len(vertices)} vertices, {len(faces)} triangles\n"
    )
    body = format_rows("v %r %r %r\n", vertices)
    body += format_rows("f %d %d %d\n", np.asarray(faces) + 1)
    return (head + body).encode("ascii")
