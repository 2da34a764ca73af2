"""Colour transfer from a scan to the fitted skin (vertex colours or a texture image).

Frame and units
---------------
Both meshes are in the same frame, usually the head frame of
:mod:`workbench.core.frame` (x to the subject's left, x = 0 midsagittal,
y up, z toward the face), in millimetres.  Colours are 8-bit sRGB.

Method
------
Every skin vertex takes the colour of its closest point on the scan
(:class:`~workbench.core.spatial.MeshIndex`, certified nearest): the
barycentric blend of the scan's vertex colours there, or the texture image
sampled bilinearly at the blend of the triangle's corner texture coordinates
(as Lee et al. transferred their scanner's reflectance image).  A skin vertex
is *observed* when that point is within ``max_distance_mm`` and the offset
is not mostly sideways off a hole's or the field of view's rim (the skin
over a hole finds the rim beside it, not under it).  The colours of the
other vertices are filled smoothly: a harmonic (graph-Laplace) interpolation
of the observed colours over the skin's edges, solved with one sparse
factorisation; parts of the skin that touch no observed vertex get the mean
observed colour.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.sparse.linalg import spsolve

from workbench.core.errors import InputError
from workbench.core.mesh import Mesh
from workbench.core.spatial import ClosestPoints, MeshIndex

#: colour of a skin with no observed vertex at all (mid grey)
NO_COLOUR = (128, 128, 128)
#: an offset longer than this (mm) must be mostly along the scan's normal to count
SIDEWAYS_FREE_MM = 0.5
#: ... at least this cosine between the offset and the scan triangle's normal
MIN_NORMAL_COSINE = 0.5


@dataclass(frozen=True, eq=False)
class ScanColours:
    """Colours a scan carries, aligned with the scan mesh as read from its file.

    Attributes
    ----------
    source : str
        The scan file (for messages).
    n_vertices : int
        Vertex count of the mesh the colours belong to.
    faces : (m, 3) int64
        That mesh's triangles as read; ``corner_uv`` follows their corner
        order (a mesh whose triangles were re-wound still matches).
    vertex_rgb : (n_vertices, 3) uint8, optional
        Per-vertex colours.
    corner_uv : (m, 3, 2) float64, optional
        Texture coordinates (u right, v up, 0..1 across the image; repeats
        outside) per triangle corner; NaN for triangles without a texture.
    image : (H, W, 3) uint8, optional
        The texture image, first row at the top (v = 1).
    """

    source: str
    n_vertices: int
    faces: np.ndarray
    vertex_rgb: np.ndarray | None = None
    corner_uv: np.ndarray | None = None
    image: np.ndarray | None = None

    def __post_init__(self) -> None:
        faces = np.asarray(self.faces, np.int64).reshape(-1, 3)
        object.__setattr__(self, "faces", faces)
        if self.vertex_rgb is not None:
            rgb = np.asarray(self.vertex_rgb)
            if rgb.shape != (self.n_vertices, 3) or rgb.dtype != np.uint8:
                raise ValueError(
                    f"vertex_rgb must be ({self.n_vertices}, 3) uint8, got {rgb.shape} {rgb.dtype}"
                )
        if (self.corner_uv is None) != (self.image is None):
            raise ValueError("corner_uv and image go together")
        if self.corner_uv is not None and self.image is not None:
            uv = np.asarray(self.corner_uv, np.float64)
            if uv.shape != (len(faces), 3, 2):
                raise ValueError(f"corner_uv must be ({len(faces)}, 3, 2), got {uv.shape}")
            object.__setattr__(self, "corner_uv", uv)
            img = np.asarray(self.image)
            if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8 or 0 in img.shape:
                raise ValueError(f"image must be (H, W, 3) uint8, got {img.shape} {img.dtype}")
        if self.vertex_rgb is None and self.image is None:
            raise ValueError("ScanColours needs vertex_rgb or corner_uv and image")

    @property
    def kind(self) -> str:
        """``"texture"`` when a texture image is used (it wins over vertex colours), else
        ``"vertex"``."""
        return "texture" if self.image is not None else "vertex"


@dataclass(frozen=True, eq=False)
class SkinColours:
    """Colours of the fitted skin's vertices.

    Attributes
    ----------
    rgb : (n_skin, 3) uint8
        Observed colours, and filled ones where ``observed`` is False.
    observed : (n_skin,) bool
        The colour came from the scan (within ``max_distance_mm``, not over a hole).
    distance : (n_skin,) float64
        Distance from each skin vertex to the scan (mm).
    kind : str
        ``"texture"`` or ``"vertex"``: where the scan's colours came from.
    """

    rgb: np.ndarray
    observed: np.ndarray
    distance: np.ndarray
    kind: str

    @property
    def observed_fraction(self) -> float:
        return float(self.observed.mean()) if len(self.observed) else 0.0


def _check_alignment(scan: Mesh, colours: ScanColours) -> np.ndarray | None:
    """Corner permutation ``(m, 3)`` mapping ``scan.faces`` corners to ``colours.faces``
    corners (None for vertex colours only); InputError when the meshes differ."""
    problem = None
    if scan.n_vertices != colours.n_vertices:
        problem = (
            f"the colours belong to a mesh of {colours.n_vertices} vertices, the scan has "
            f"{scan.n_vertices}"
        )
    elif colours.corner_uv is not None and scan.n_faces != len(colours.faces):
        problem = (
            f"the texture coordinates belong to {len(colours.faces)} triangles, the scan has "
            f"{scan.n_faces}"
        )
    if problem is None and colours.corner_uv is not None:
        same = scan.faces[:, :, None] == colours.faces[:, None, :]
        if not same.any(axis=2).all():
            problem = "the scan's triangles are not those the texture coordinates belong to"
        else:
            return np.asarray(same.argmax(axis=2))
    if problem is not None:
        raise InputError(
            colours.source, problem, "read the colours from the same file as the scan mesh"
        )
    return None


def sample_image(image: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear samples ``(k, 3)`` float of ``image`` ``(H, W, 3)`` at ``uv`` ``(k, 2)``.

    ``u`` runs left to right and ``v`` bottom to top over ``[0, 1]`` (pixel
    centres at ``(i + 0.5) / W``); coordinates outside repeat the image.
    NaN coordinates give NaN colours.
    """
    h, w = image.shape[:2]
    uv = np.asarray(uv, np.float64).reshape(-1, 2)
    bad = np.asarray(~np.isfinite(uv).all(axis=1), dtype=bool)
    uv = np.where(bad[:, None], 0.0, uv)
    x = np.mod(uv[:, 0], 1.0) * w - 0.5
    y = (1.0 - np.mod(uv[:, 1], 1.0)) * h - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    x0i, y0i = x0.astype(np.int64), y0.astype(np.int64)
    # clamp at the borders (texture atlases have no meaningful wrap-around neighbours)
    xa, xb = np.clip(x0i, 0, w - 1), np.clip(x0i + 1, 0, w - 1)
    ya, yb = np.clip(y0i, 0, h - 1), np.clip(y0i + 1, 0, h - 1)

    # only the pixels read are converted (a whole 8192^2 texture as float32 is 800 MB)
    def px(rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        return image[rows, cols].astype(np.float32)

    top = px(ya, xa) * (1 - fx) + px(ya, xb) * fx
    bottom = px(yb, xa) * (1 - fx) + px(yb, xb) * fx
    out = (top * (1 - fy) + bottom * fy).astype(np.float64)
    out[bad] = np.nan
    return out


def scan_colour_at(
    scan: Mesh, colours: ScanColours, face_ids: np.ndarray, barycentric: np.ndarray
) -> np.ndarray:
    """Colour ``(k, 3)`` float 0..255 of the scan at points given by face and barycentric
    coordinates (weights of ``scan.faces`` corners); NaN where the scan has none."""
    face_ids = np.asarray(face_ids, np.int64)
    bary = np.asarray(barycentric, np.float64).reshape(-1, 3)
    perm = _check_alignment(scan, colours)
    if colours.corner_uv is not None and colours.image is not None and perm is not None:
        corner = colours.corner_uv[face_ids[:, None], perm[face_ids]]  # (k, 3, 2)
        uv = np.einsum("kc,kcu->ku", bary, corner)
        return sample_image(colours.image, uv)
    assert colours.vertex_rgb is not None
    rgb = colours.vertex_rgb[scan.faces[face_ids]].astype(np.float64)  # (k, 3, 3)
    return np.einsum("kc,kcj->kj", bary, rgb)


def _observed(
    points: np.ndarray, index: MeshIndex, near: ClosestPoints, max_d: float
) -> np.ndarray:
    """Close enough, and not reaching sideways off a rim."""
    offset = points - near.points
    # (the closest feature's normal: a face's would depend on which face a tie returned)
    normals = index.pseudo_normals(near.face_ids, near.barycentric)
    along = np.abs(np.einsum("ij,ij->i", offset, normals))
    d = near.distances
    return (d <= max_d) & ((d <= SIDEWAYS_FREE_MM) | (along >= MIN_NORMAL_COSINE * d))


def fill_colours(mesh: Mesh, rgb: np.ndarray, known: np.ndarray) -> np.ndarray:
    """Harmonic fill: ``rgb`` ``(n, 3)`` float kept where ``known``, the rest solved so
    each unknown vertex is the mean of its edge neighbours (graph Laplace equation).

    Components of the mesh without a known vertex get the mean known colour
    (``NO_COLOUR`` when nothing is known).  Returns ``(n, 3)`` float.
    """
    n = mesh.n_vertices
    rgb = np.asarray(rgb, np.float64).reshape(n, 3).copy()
    known = np.asarray(known, bool).reshape(n)
    if not known.any():
        rgb[:] = NO_COLOUR
        return rgb
    unknown = np.flatnonzero(~known)
    if len(unknown) == 0:
        return rgb
    mean = rgb[known].mean(axis=0)
    edges = mesh.edges_unique
    if len(edges) == 0:
        rgb[unknown] = mean
        return rgb
    ones = np.ones(len(edges))
    adj = sparse.coo_matrix(
        (
            np.concatenate([ones, ones]),
            (np.r_[edges[:, 0], edges[:, 1]], np.r_[edges[:, 1], edges[:, 0]]),
        ),
        shape=(n, n),
    ).tocsr()
    degree = np.asarray(adj.sum(axis=1)).ravel()
    lap = (sparse.diags(degree) - adj).tocsr()
    # a tiny pull toward the mean keeps components without known vertices solvable
    eps = 1e-6
    a = lap[unknown][:, unknown] + eps * sparse.identity(len(unknown), format="csr")
    b = -(lap[unknown][:, np.flatnonzero(known)] @ rgb[known]) + eps * mean
    solved = spsolve(a.tocsc(), b)
    rgb[unknown] = np.asarray(solved).reshape(-1, 3)
    return rgb


def transfer_colours(
    skin: Mesh,
    scan: Mesh,
    colours: ScanColours,
    max_distance_mm: float = 3.0,
    *,
    index: MeshIndex | None = None,
) -> SkinColours:
    """Colour every vertex of ``skin`` from ``scan`` (both in the head frame, mm).

    Parameters
    ----------
    skin : Mesh
        The fitted skin.
    scan : Mesh
        The scan in the same frame, with the vertices and triangles (possibly
        re-wound) of the mesh ``colours`` were read with.
    colours : ScanColours
        From :func:`workbench.io.scan_colours.read_scan_colours`.
    max_distance_mm : float
        Skin vertices farther from the scan are filled, not observed.
    index : MeshIndex, optional
        A spatial index of ``scan`` already built.

    Raises
    ------
    InputError
        ``colours`` belong to another mesh (vertex or triangle counts differ).
    """
    if not max_distance_mm > 0:
        raise ValueError(f"max_distance_mm must be positive, got {max_distance_mm}")
    _check_alignment(scan, colours)
    index = MeshIndex(scan) if index is None else index
    near = index.closest_points(skin.vertices)
    sampled = scan_colour_at(scan, colours, near.face_ids, near.barycentric)
    observed = _observed(skin.vertices, index, near, max_distance_mm)
    observed &= np.isfinite(sampled).all(axis=1)
    filled = fill_colours(skin, np.where(observed[:, None], sampled, 0.0), observed)
    rgb = np.clip(np.rint(filled), 0, 255).astype(np.uint8)
    return SkinColours(rgb, observed, near.distances, colours.kind)


__all__ = [
    "ScanColours",
    "SkinColours",
    "fill_colours",
    "sample_image",
    "scan_colour_at",
    "transfer_colours",
]
