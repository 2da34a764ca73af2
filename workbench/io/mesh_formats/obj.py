"""Wavefront OBJ: ``v`` and ``f`` records, plus what colours the faces.

Face corners may be written ``v``, ``v/vt``, ``v//vn`` or ``v/vt/vn``; indices
are 1-based, negative indices count back from the latest vertex.  Polygons are
split into triangle fans.  Normals, groups, objects, smoothing groups, lines
and comments are ignored, except 3D Slicer's ``SPACE=RAS``/``SPACE=LPS`` tag in
the comment block that opens the file (:attr:`ParsedMesh.space`), where the
writer puts ``# SPACE=RAS``.

:func:`encode_groups` writes several parts into one OBJ (an ``o`` object
each, smoothing group ``s 1`` so importers shade it smooth), their triangles
grouped by ``usemtl`` material and, where a part has texture coordinates,
``v/vt`` corners; :func:`encode_mtl` writes the material
library it names (``Kd``, ``map_Kd`` and the PBR extension's ``Pr``/``Pm``).

Colour data are kept but never make a readable mesh unreadable: vertex
colours written ``v x y z r g b`` (0..1, or 0..255) become
:attr:`ParsedMesh.vertex_rgb`; ``vt`` texture coordinates become
:attr:`ParsedMesh.corner_uv` (per triangle corner, split like the faces)
when every face corner has one, else a note says why they were dropped;
``mtllib`` names and each triangle's ``usemtl`` material are kept for
:mod:`workbench.io.scan_colours`, which reads the material files.
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

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

_SLASH_SUFFIX = re.compile(r"/\S*")
_INDENTED = re.compile(r"^[ \t]", re.MULTILINE)
_V = ("v ", "v\t")
_F = ("f ", "f\t")
_VT = ("vt ", "vt\t")
_NO_UV_CORNER = re.compile(r"(?<!\S)[^\s/]+(?!\S)|(?<!\S)[^\s/]*//\S*")
_UV_OF_CORNER = re.compile(r"(?<!\S)[^\s/]*/([^\s/]+)\S*")


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


def _vertex_colours(r: Reader, lines: list[str]) -> np.ndarray | None:
    """``v x y z r g b`` colours when every vertex line has them, else None."""
    first = lines[0].split("#")[0].split()
    if len(first) != 7:
        return None
    table = _fast_table(lines, np.float64, (4, 5, 6))
    if table is None or len(table) != len(lines):
        r.note("vertex colours are on only some 'v' lines and were ignored")
        return None
    return colour_bytes(table, None)


def _corner_uv(
    r: Reader, lines: list[str], f_lines: list[str], counts: np.ndarray
) -> np.ndarray | None:
    """Texture coordinates per triangle corner, or None (with a note why)."""
    vt_lines = [line for line in lines if line[:3] in _VT]
    if not vt_lines:
        return None
    body = "\n".join(line[1:].split("#")[0] for line in f_lines)
    if _NO_UV_CORNER.search(body):
        r.note("some face corners have no texture coordinate; the 'vt' records were ignored")
        return None
    uv = _fast_table(vt_lines, np.float64, (1, 2))
    if uv is None or len(uv) != len(vt_lines):
        r.note("unreadable 'vt' texture coordinates were ignored")
        return None
    flat_text = _UV_OF_CORNER.sub(r"\1", body).split()
    try:
        idx = np.asarray(flat_text, dtype=np.int64)
    except ValueError:
        r.note("unreadable texture indices in the faces; the 'vt' records were ignored")
        return None
    if len(idx) != int(counts.sum()):
        r.note("texture indices do not match the face corners; the 'vt' records were ignored")
        return None
    if np.any(idx < 0):  # relative to the texture coordinates defined so far
        seen, n_before = 0, []
        for line in lines:
            if line[:3] in _VT:
                seen += 1
            elif line[:2] in _F:
                n_before.append(seen)
        line_of = np.repeat(np.arange(len(counts)), counts)
        idx = np.where(idx > 0, idx, np.asarray(n_before, np.int64)[line_of] + idx + 1)
    if np.any(idx < 1) or np.any(idx > len(uv)):
        r.note(
            f"texture indices out of range (the file has {len(uv)} 'vt' records); "
            "the 'vt' records were ignored"
        )
        return None
    corners = fan_triangulate(counts, idx - 1, r, quiet=True)
    return uv[corners]


def _materials(lines: list[str], counts: np.ndarray) -> tuple[list[str], list[str], np.ndarray]:
    """``mtllib`` names, material names and each triangle's material (-1: none)."""
    libraries: list[str] = []
    names: list[str] = []
    per_line: list[int] = []
    current = -1
    for line in lines:
        head = line[:2]
        if head in _F:
            per_line.append(current)
        elif line.startswith(("mtllib ", "mtllib\t")):
            name = line[6:].split("#")[0].strip()
            if name and name not in libraries:
                libraries.append(name)
        elif line.startswith(("usemtl ", "usemtl\t")):
            name = line[6:].split("#")[0].strip()
            if name not in names:
                names.append(name)
            current = names.index(name)
    n_tri = np.maximum(counts - 2, 0)
    return libraries, names, np.repeat(np.asarray(per_line, np.int64), n_tri)


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
    parsed = r.finish(vertices, fan_triangulate(counts, zero_based, r))
    parsed.vertex_rgb = _vertex_colours(r, v_lines)
    parsed.corner_uv = _corner_uv(r, lines, f_lines, counts)
    if "mtllib" in text or "usemtl" in text:
        libraries, names, face_material = _materials(lines, counts)
        parsed.material_libraries, parsed.material_names = libraries, names
        parsed.face_material = face_material if names else None
    parsed.space = _header_space(lines)
    return parsed


def _header_space(lines: list[str]) -> str | None:
    """Slicer's ``SPACE=`` tag in the comment block that opens the file (VTK's OBJ "comment")."""
    block = []
    for line in lines:
        if line.strip() and not line.startswith("#"):
            break
        block.append(line)
    return space_in("\n".join(block))


def encode(
    vertices: np.ndarray, faces: np.ndarray, binary: bool = True, *, space: str = "RAS"
) -> bytes:
    """OBJ text (``binary`` is ignored: OBJ is always text), exact doubles."""
    del binary
    head = (
        f"# {UNITS_NOTE}\n# {space_tag(space)}\n# written by {WRITER_NAME}\n"
        f"# {len(vertices)} vertices, {len(faces)} triangles\n"
    )
    body = format_rows("v %r %r %r\n", vertices)
    body += format_rows("f %d %d %d\n", np.asarray(faces) + 1)
    return (head + body).encode("ascii")


@dataclass(frozen=True, eq=False)
class ObjGroup:
    """One part of a multi-part OBJ.

    ``face_material`` indexes ``materials`` per triangle (None: all the first);
    ``corner_uv`` ``(m, 3, 2)`` gives every triangle corner a texture
    coordinate (u right, v up), or None for no ``vt``.
    """

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    materials: Sequence[str]
    face_material: np.ndarray | None = None
    corner_uv: np.ndarray | None = None


def _group_text(group: ObjGroup, v0: int, t0: int) -> tuple[str, int, int]:
    """The text of one group; vertex and ``vt`` numbers start after ``v0`` and ``t0``."""
    faces = np.asarray(group.faces, np.int64).reshape(-1, 3)
    out = [f"o {group.name}\n", format_rows("v %r %r %r\n", np.asarray(group.vertices, float))]
    n_uv = 0
    if group.corner_uv is not None:
        uv, index = np.unique(
            np.asarray(group.corner_uv, float).reshape(-1, 2), axis=0, return_inverse=True
        )
        out.append(format_rows("vt %.7f %.7f\n", uv))
        n_uv = len(uv)
        rows = np.stack([faces + v0 + 1, index.reshape(-1, 3) + t0 + 1], axis=-1).reshape(-1, 6)
        fmt = "f %d/%d %d/%d %d/%d\n"
    else:
        rows, fmt = faces + v0 + 1, "f %d %d %d\n"
    which = (
        np.zeros(len(faces), np.int64)
        if group.face_material is None
        else np.asarray(group.face_material, np.int64)
    )
    out.append("s 1\n")  # smooth shading (else Blender and others import every face flat)
    for k, material in enumerate(group.materials):
        mine = rows[which == k]
        if len(mine):
            out.append(f"usemtl {material}\n")
            out.append(format_rows(fmt, mine))
    return "".join(out), v0 + len(group.vertices), t0 + n_uv


def encode_groups(
    groups: Sequence[ObjGroup],
    *,
    mtllib: str,
    comments: Sequence[str] = (),
    space: str = "RAS",
) -> bytes:
    """One OBJ of several parts with their materials (``mtllib``), exact doubles."""
    lines = [UNITS_NOTE, space_tag(space), f"written by {WRITER_NAME}", *comments]
    text = "".join(f"# {line}\n" for line in lines) + f"mtllib {mtllib}\n"
    v0 = t0 = 0
    for group in groups:
        part, v0, t0 = _group_text(group, v0, t0)
        text += part
    return text.encode("utf-8")


@dataclass(frozen=True)
class MtlMaterial:
    """One ``newmtl`` entry: diffuse colour ``kd`` (0-1), roughness, optional texture."""

    name: str
    kd: tuple[float, float, float]
    roughness: float
    map_kd: str = ""
    metallic: float = 0.0
    comment: str = ""


def encode_mtl(materials: Sequence[MtlMaterial], comments: Sequence[str] = ()) -> bytes:
    """A material library: ``Kd`` (white under a ``map_Kd`` texture), no ambient or
    metal (``Ka`` 0, ``Pm``), a dim specular whose ``Ns`` matches the roughness ``Pr``
    (Blender's importer reads ``Pr``/``Pm``; others read ``Ns``)."""
    text = "".join(f"# {line}\n" for line in [f"written by {WRITER_NAME}", *comments])
    for m in materials:
        kd = (1.0, 1.0, 1.0) if m.map_kd else m.kd
        ns = 1000.0 * (1.0 - m.roughness) ** 2
        text += f"\nnewmtl {m.name}\n" + (f"# {m.comment}\n" if m.comment else "")
        text += "Ka 0 0 0\nKd {:.6f} {:.6f} {:.6f}\n".format(*kd)
        text += f"Ks 0.1 0.1 0.1\nNs {ns:.3f}\nPr {m.roughness:.3f}\nPm {m.metallic:.3f}\n"
        text += "d 1\nillum 2\n" + (f"map_Kd {m.map_kd}\n" if m.map_kd else "")
    return text.encode("utf-8")
