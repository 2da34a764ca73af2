"""STL, ascii and binary (auto-detected; binary files may begin with "solid").

STL stores every triangle's corners separately; the reader merges corners
with exactly equal coordinates so the result is an indexed mesh (vertex order
= first appearance).  Binary STL is float32; ascii STL is written with full
double precision.  The writer emits face normals computed from the triangles
and puts 3D Slicer's ``SPACE=RAS`` tag in the header (binary: the 80-byte
header text; ascii: the solid's name), where Slicer looks for it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from workbench.io.mesh_formats._common import (
    UNITS_NOTE,
    WRITER_NAME,
    ParsedMesh,
    Reader,
    format_rows,
    space_in,
    space_tag,
)

_RECORD = np.dtype([("normal", "<f4", (3,)), ("corners", "<f4", (3, 3)), ("attr", "<u2")])


def merge_corners(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Merge bit-identical corner positions.

    Parameters
    ----------
    corners : (m, 3, 3) float
        Triangle corners (any float type; compared exactly, -0 equals +0).

    Returns
    -------
    vertices : (n, 3) float64
        Unique positions in order of first appearance.
    faces : (m, 3) int64
    """
    flat = np.ascontiguousarray(corners.reshape(-1, 3) + 0.0)  # +0.0 turns -0.0 into 0.0
    if len(flat) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    keys = flat.view(np.dtype((np.void, flat.dtype.itemsize * 3))).ravel()
    _, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    vertices = flat[first[order]].astype(np.float64)
    faces = rank[inverse.ravel()].reshape(-1, 3).astype(np.int64)
    return vertices, faces


def _looks_ascii(data: bytes) -> bool:
    head = data[:1024].lstrip()
    if not head[:5].lower() == b"solid":
        return False
    sample = data[:4096]
    if b"\0" in sample:
        return False
    return b"facet" in sample.lower() or b"endsolid" in data[-1024:].lower()


def _read_binary(r: Reader) -> ParsedMesh:
    if len(r.data) < 84:
        raise r.truncated("the 84-byte binary STL header")
    n = int(np.frombuffer(r.data, "<u4", 1, 80)[0])
    expected = 84 + 50 * n
    if len(r.data) < expected:
        raise r.fail(
            f"binary STL header announces {n} triangles ({expected} bytes) but the file has only "
            f"{len(r.data)} bytes (truncated or damaged)",
            "copy or export the file again",
        )
    if len(r.data) > expected:
        r.note(f"{len(r.data) - expected} extra bytes after the last STL triangle were ignored")
    records = np.frombuffer(r.data, _RECORD, n, 84)
    vertices, faces = merge_corners(records["corners"])
    parsed = r.finish(vertices, faces)
    parsed.space = space_in(r.data[:80])  # Slicer reads the tag from the 80-byte header
    return parsed


def _read_ascii(r: Reader) -> ParsedMesh:
    text = r.data.lower()
    body_start = text.find(b"\n") + 1  # skip the "solid name" line: the name is free text
    body_end = text.rfind(b"endsolid")
    if body_start <= 0 or body_end < body_start:
        raise r.fail(
            "the ascii STL file has no final 'endsolid' line (truncated or damaged)",
            "copy or export the file again",
        )
    tokens = np.array(text[body_start:body_end].split())
    where = np.flatnonzero(tokens == b"vertex")
    n_facets = int((tokens == b"facet").sum())
    if len(where) == 0:
        raise r.fail("the ascii STL file contains no 'vertex' lines (no triangles)")
    if where[-1] + 3 >= len(tokens):
        raise r.truncated("the last vertex")
    corners = r.to_float(tokens[where[:, None] + np.arange(1, 4)], "vertex coordinates")
    if len(corners) != 3 * n_facets:
        raise r.fail(
            f"found {len(corners)} vertices in {n_facets} facets; every facet must have "
            "exactly 3 vertices (damaged file, or polygons instead of triangles)"
        )
    vertices, faces = merge_corners(corners.reshape(-1, 3, 3))
    parsed = r.finish(vertices, faces)
    parsed.space = space_in(r.data[: body_start - 1])  # the "solid NAME" line
    return parsed


def read(path: Path, data: bytes) -> ParsedMesh:
    """Parse STL bytes (format detected from content); vertices in file units."""
    r = Reader(path, data, "STL")
    if len(data) >= 84:
        n = int(np.frombuffer(data, "<u4", 1, 80)[0])
        if 84 + 50 * n == len(data) and n > 0:
            return _read_binary(r)
    if _looks_ascii(data):
        return _read_ascii(r)
    return _read_binary(r)


def encode(
    vertices: np.ndarray, faces: np.ndarray, binary: bool = True, *, space: str = "RAS"
) -> bytes:
    """STL bytes (binary default, ascii option) with normals from the faces."""
    corners = np.asarray(vertices, np.float64)[faces]
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    norm = np.linalg.norm(cross, axis=1, keepdims=True)
    normals = np.divide(cross, norm, out=np.zeros_like(cross), where=norm > 0)
    if binary:
        title = f"binary STL by {WRITER_NAME}, {UNITS_NOTE}, {space_tag(space)}".encode("ascii")
        header = title.ljust(80, b" ")[:80] + np.uint32(len(faces)).astype("<u4").tobytes()
        rec = np.zeros(len(faces), _RECORD)
        rec["normal"] = normals
        rec["corners"] = corners
        return header + rec.tobytes()
    table = np.concatenate([normals, corners.reshape(-1, 9)], axis=1)
    facet = (  # full double precision: ascii STL need not lose the mm fractions
        " facet normal %.9g %.9g %.9g\n  outer loop\n"
        "   vertex %r %r %r\n   vertex %r %r %r\n   vertex %r %r %r\n"
        "  endloop\n endfacet\n"
    )
    name = f"workbench_mesh {space_tag(space)} ({UNITS_NOTE})"
    text = f"solid {name}\n" + format_rows(facet, table) + f"endsolid {name}\n"
    return text.encode("ascii")
