"""Helpers shared by the mesh format readers and writers.

Every reader returns a :class:`ParsedMesh` in *file units* (no scaling) and
raises :class:`~workbench.core.errors.InputError` for anything it cannot
read.  Writers return the complete file content as ``bytes``; the atomic
write itself happens in :mod:`workbench.io.meshes`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from workbench.core.errors import InputError

UNITS_NOTE = "units: mm"
WRITER_NAME = "forensic-workbench"
#: 3D Slicer's coordinate-system token (``vtkMRMLModelStorageNode``): Slicer reads
#: ``SPACE=RAS`` / ``SPACE=LPS`` from a mesh file's header and takes a file without
#: one as LPS.  Files the workbench writes hold its mesh frame, which it shares with
#: the landmark files as Slicer's RAS, so every writer puts this token in the header.
SPACE_RAS = "SPACE=RAS"


def space_tag(space: str) -> str:
    """``"SPACE=RAS"`` or ``"SPACE=LPS"``: the tag a writer puts in a header.

    ``space`` names the frame the coordinates are in; ValueError for anything
    but "RAS" or "LPS".
    """
    if space not in ("RAS", "LPS"):
        raise ValueError(f"space must be 'RAS' or 'LPS', got {space!r}")
    return f"SPACE={space}"


def space_in(text: str | bytes | None) -> str | None:
    """``"RAS"`` / ``"LPS"`` when ``text`` holds Slicer's ``SPACE=RAS`` / ``SPACE=LPS``.

    Checked as Slicer does (a substring anywhere in the header text, RAS first);
    None when neither token is there.
    """
    if text is None:
        return None
    if isinstance(text, bytes):
        text = text.decode("ascii", errors="replace")
    for space in ("RAS", "LPS"):
        if f"SPACE={space}" in text:
            return space
    return None


@dataclass
class ParsedMesh:
    """Raw mesh data as stored in the file (file units, usually unknown).

    Attributes
    ----------
    vertices : (n, 3) float64
        Positions in file units.
    faces : (m, 3) int64
        Zero-based triangle corner indices (already range-checked).
    messages : list of str
        Notes for the user (polygons split, properties ignored, ...).
    vertex_rgb : (n, 3) uint8, optional
        Per-vertex colours the file carries (PLY red/green/blue, OBJ
        ``v x y z r g b``), aligned with ``vertices``; None when there are none.
    corner_uv : (m, 3, 2) float64, optional
        Texture coordinates (u, v) of every triangle corner, aligned with
        ``faces`` (OBJ ``vt`` records); None when the faces carry none.
    material_libraries : list of str
        Material files named by the mesh file, as written (OBJ ``mtllib``).
    material_names : list of str
        Materials the faces use (OBJ ``usemtl``), in order of first use.
    face_material : (m,) int64, optional
        Index into ``material_names`` per triangle, -1 for none; None when
        the file names no materials.
    space : {"RAS", "LPS"}, optional
        The coordinate system the header names with 3D Slicer's ``SPACE=``
        token (see :func:`space_in`); None when it names none.
    """

    vertices: np.ndarray
    faces: np.ndarray
    messages: list[str] = field(default_factory=list)
    vertex_rgb: np.ndarray | None = field(default=None, kw_only=True)
    corner_uv: np.ndarray | None = field(default=None, kw_only=True)
    material_libraries: list[str] = field(default_factory=list, kw_only=True)
    material_names: list[str] = field(default_factory=list, kw_only=True)
    face_material: np.ndarray | None = field(default=None, kw_only=True)
    space: str | None = field(default=None, kw_only=True)


class Reader:
    """Bundles the path with error helpers so parsers can fail in plain words."""

    def __init__(self, path: Path, data: bytes, label: str):
        self.path = path
        self.data = data
        self.label = label
        self.messages: list[str] = []
        self.index_base = 0  # how the format numbers vertices (OBJ: 1), for messages

    def fail(self, problem: str, hint: str | None = None) -> InputError:
        """Build (not raise) an :class:`InputError` naming this file."""
        return InputError(self.path, f"{self.label} file: {problem}", hint)

    def truncated(self, what: str) -> InputError:
        return self.fail(
            f"the file ends early while reading {what} (truncated or damaged)",
            "copy or export the file again",
        )

    def note(self, message: str) -> None:
        self.messages.append(message)

    def to_float(self, tokens: np.ndarray | list, what: str) -> np.ndarray:
        """Convert text tokens to float64, raising InputError for non-numbers."""
        try:
            return np.asarray(tokens).astype(np.float64)
        except (ValueError, TypeError, OverflowError):
            raise self.fail(f"non-numeric data among the {what}") from None

    def to_int(self, tokens: np.ndarray | list, what: str) -> np.ndarray:
        """Convert text tokens to int64 (accepting "3.0"-style integers)."""
        arr = np.asarray(tokens)
        try:
            return arr.astype(np.int64)
        except (ValueError, TypeError, OverflowError):
            pass
        values = self.to_float(arr, what)
        if not np.all(np.isfinite(values)) or np.any(values != np.round(values)):
            raise self.fail(f"the {what} must be whole numbers")
        return values.astype(np.int64)

    def frombuffer(self, dtype: np.dtype | str, count: int, offset: int, what: str) -> np.ndarray:
        """``np.frombuffer`` with a plain-words error when the data run out."""
        dtype = np.dtype(dtype)
        if count < 0:
            raise self.fail(f"negative count for the {what}")
        if offset + count * dtype.itemsize > len(self.data):
            raise self.truncated(what)
        return np.frombuffer(self.data, dtype=dtype, count=count, offset=offset)

    def finish(self, vertices: np.ndarray, faces: np.ndarray) -> ParsedMesh:
        """Check shapes and index ranges and package the result."""
        vertices = np.ascontiguousarray(vertices, dtype=np.float64).reshape(-1, 3)
        faces = np.ascontiguousarray(faces, dtype=np.int64).reshape(-1, 3)
        if len(vertices) == 0:
            raise self.fail("the file contains no vertices")
        if len(faces) == 0:
            raise self.fail(
                "the file contains no triangles (only points or lines?)",
                "the workbench needs a surface mesh made of triangles or polygons",
            )
        n = len(vertices)
        bad = (faces < 0) | (faces >= n)
        if bad.any():
            row, col = (int(i) for i in np.argwhere(bad)[0])
            value = int(faces[row, col]) + self.index_base
            raise self.fail(
                f"face index out of range: triangle {row + 1} uses vertex {value}, but the "
                f"file has only {n} vertices",
                "the file is damaged or was written incorrectly",
            )
        bad_coords = int((~np.isfinite(vertices).all(axis=1)).sum())
        if bad_coords:
            self.note(f"{bad_coords} vertices have NaN or infinite coordinates")
        return ParsedMesh(vertices, faces, self.messages)


def fan_triangulate(
    counts: np.ndarray, flat: np.ndarray, reader: Reader, *, quiet: bool = False
) -> np.ndarray:
    """Split polygons into triangle fans, vectorised.

    Parameters
    ----------
    counts : (k,) int
        Number of corners of every polygon.
    flat : (sum(counts),) int
        Corner indices of all polygons, one after another.
    reader : Reader
        Receives a note when polygons are split or dropped (unless ``quiet``:
        for a second table, e.g. texture indices, split the same way).

    Returns
    -------
    (m, 3) int64
        Triangles ``(c0, ci, ci+1)`` for every polygon with at least 3 corners.
    """
    counts = np.asarray(counts, dtype=np.int64)
    flat = np.asarray(flat, dtype=np.int64)
    if len(counts) == 0:
        return np.zeros((0, 3), np.int64)
    if int(counts.sum()) != len(flat):
        raise reader.fail("polygon corner counts do not match the number of indices")
    if np.all(counts == 3):
        return flat.reshape(-1, 3)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    small = counts < 3
    if small.any() and not quiet:
        reader.note(f"{int(small.sum())} polygons with fewer than 3 corners were skipped")
    n_tri = np.maximum(counts - 2, 0)
    big = int((counts > 3).sum())
    if big and not quiet:
        reader.note(f"{big} polygons with more than 3 corners were split into triangles")
    poly = np.repeat(np.arange(len(counts)), n_tri)
    first_tri = np.cumsum(n_tri) - n_tri
    j = np.arange(int(n_tri.sum())) - first_tri[poly]
    s = starts[poly]
    return np.stack([flat[s], flat[s + j + 1], flat[s + j + 2]], axis=1)


def colour_bytes(values: np.ndarray, integer_max: float | None) -> np.ndarray:
    """Colour channels as uint8 0-255.

    ``integer_max`` is the full scale of integer channels (255 for uchar,
    65535 for ushort); None for floating-point channels, which are taken as
    0..1 unless some value exceeds 1 (then 0..255, as some writers do).
    Values outside the range are clipped; NaN becomes 0.
    """
    values = np.nan_to_num(np.asarray(values, dtype=np.float64), nan=0.0)
    if integer_max is None:
        top = float(values.max()) if values.size else 0.0
        scale = 255.0 if top <= 1.0 else 1.0
    else:
        scale = 255.0 / integer_max
    return np.clip(np.rint(values * scale), 0, 255).astype(np.uint8)


def format_rows(fmt: str, values: np.ndarray) -> str:
    """Format a 2-D array row by row with one printf-style ``fmt`` per row.

    Use ``%r`` for floats: the shortest text that reads back as the same double.
    """
    values = np.asarray(values)
    if values.size == 0:
        return ""
    return (fmt * len(values)) % tuple(values.ravel().tolist())
