"""Write the coloured fitted skin: a vertex-colour PLY and a textured OBJ with its atlas.

Frame and units: the skin's vertices as given, normally the head frame (x to
the subject's left, x = 0 midsagittal, y up, z toward the face), in mm; the
PLY header says so.

Texture atlas
-------------
Every triangle of the skin gets its own patch of the atlas: triangles are
paired into square cells of ``c`` x ``c`` pixels laid out on a grid, the
first of a pair in the cell's lower-left half, the second in its upper-right
half, each inset from the cell border and from the shared diagonal so
bilinear filtering never reads another triangle's texels.  Every texel of
the cell takes the colour of the nearest point of its own triangle (its
barycentric coordinates clipped to the triangle), which fills the gutter
around each patch (dilation).  The colour is the blend of the skin's vertex
colours, or, when the scan's colours and the scan are given, the scan's own
colour (its texture image sampled) at the scan point closest to the texel's
point on the skin, so the atlas keeps detail finer than the skin's triangles;
texels whose scan point is farther than ``max_distance_mm`` keep the blend.
"""

from __future__ import annotations

import math
from os import PathLike
from pathlib import Path

import numpy as np

from workbench.core.appearance import SkinTexture
from workbench.core.colour_transfer import ScanColours, SkinColours, scan_colour_at
from workbench.core.mesh import Mesh
from workbench.core.spatial import MeshIndex
from workbench.io.mesh_formats import ply

PLY_NAME = "skin_colour.ply"
#: the PLY header line that names the frame of a fitted skin
HEAD_FRAME_COMMENT = (
    "frame: head (x to the subject's left, x=0 midsagittal, y up, z toward the face)"
)
OBJ_NAME = "skin_textured.obj"
MTL_NAME = "skin_textured.mtl"
PNG_NAME = "skin_texture.png"
MATERIAL = "skin"
#: pixels between a triangle's patch and its cell's border, and across the diagonal
INSET_PX = 1.0
DIAGONAL_GAP_PX = 1.5
#: smallest cell (pixels) for a legible patch; the atlas grows to fit
MIN_CELL_PX = 6
#: texels per closest-point batch when sampling the scan (bounds memory)
SAMPLE_CHUNK = 1 << 18


def atlas_layout(n_faces: int, atlas_size: int) -> tuple[int, int, int]:
    """``(size, grid, cell)``: atlas side (px), cells per side, cell side (px).

    The cells fill the top-left ``grid * cell`` pixels.  The atlas is
    ``atlas_size`` unless the triangles need cells smaller than
    :data:`MIN_CELL_PX`; then it grows to the smallest side that fits.
    """
    cells = max(1, math.ceil(n_faces / 2))
    grid = math.ceil(math.sqrt(cells))
    cell = atlas_size // grid
    if cell < MIN_CELL_PX:
        cell = MIN_CELL_PX
    return max(atlas_size, grid * cell), grid, cell


def _cell_template(cell: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Corner positions (px, cell-local, y down) of the two triangles of a cell, and per
    texel of the cell: which triangle (0/1) and its clipped barycentric weights."""
    lo, hi = INSET_PX, cell - INSET_PX
    gap = DIAGONAL_GAP_PX
    # y grows downward in the image; "lower-left" is large y
    first = np.array([[lo, hi], [hi - gap, hi], [lo, lo + gap]])  # corners 0, 1, 2
    second = np.array([[hi, lo], [lo + gap, lo], [hi, hi - gap]])
    centres = np.stack(np.meshgrid(np.arange(cell) + 0.5, np.arange(cell) + 0.5), axis=-1)
    pts = centres.reshape(-1, 2)  # (x, y) of each texel, row-major
    which = (pts[:, 0] - pts[:, 1] > 0).astype(np.int64)  # above the diagonal → second
    weights = np.empty((len(pts), 3))
    for k, tri in enumerate((first, second)):
        rows = which == k
        weights[rows] = _clipped_barycentric(pts[rows], tri)
    return np.stack([first, second]), which, weights


def _clipped_barycentric(pts: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Barycentric weights of the nearest point of 2-D triangle ``tri`` to each of ``pts``."""
    a, b, c = tri
    best = np.full(len(pts), np.inf)
    out = np.zeros((len(pts), 3))
    m = np.array([b - a, c - a]).T
    vw = np.linalg.solve(m, (pts - a).T).T
    inside = (vw >= 0).all(axis=1) & (vw.sum(axis=1) <= 1)
    out[inside] = np.c_[1 - vw[inside].sum(axis=1), vw[inside]]
    best[inside] = 0.0
    for i, j in ((0, 1), (1, 2), (2, 0)):
        p0, p1 = tri[i], tri[j]
        e = p1 - p0
        t = np.clip((pts - p0) @ e / (e @ e), 0.0, 1.0)
        d = np.linalg.norm(pts - (p0 + t[:, None] * e), axis=1)
        better = ~inside & (d < best)
        best[better] = d[better]
        w = np.zeros((int(better.sum()), 3))
        w[:, i], w[:, j] = 1 - t[better], t[better]
        out[better] = w
    return out


def texture_atlas(
    skin: Mesh,
    colours: SkinColours,
    *,
    atlas_size: int = 2048,
    scan: Mesh | None = None,
    scan_colours: ScanColours | None = None,
    max_distance_mm: float = 3.0,
    index: MeshIndex | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The atlas image ``(S, S, 3)`` uint8 and each skin triangle's corner texture
    coordinates ``(m, 3, 2)`` (u right, v up, 0..1).

    With ``scan`` and ``scan_colours`` (the scan in the skin's frame) the
    texels sample the scan's colours; otherwise they blend ``colours.rgb``.
    """
    m = skin.n_faces
    size, grid, cell = atlas_layout(m, atlas_size)
    corners, which, weights = _cell_template(cell)
    tri = np.arange(m)
    cell_of, half = tri // 2, tri % 2
    origin = np.stack([(cell_of % grid) * cell, (cell_of // grid) * cell], axis=1).astype(float)
    px = origin[:, None, :] + corners[half]  # (m, 3, 2) pixel coordinates, y down
    uv = np.stack([px[..., 0] / size, 1.0 - px[..., 1] / size], axis=-1)

    # texels: (cells, cell*cell); a texel belongs to triangle 2*cell + which
    n_cells = math.ceil(m / 2)
    tex_tri = 2 * np.arange(n_cells)[:, None] + which[None, :]
    valid = tex_tri < m
    tex_tri = np.minimum(tex_tri, m - 1)
    rgb_corners = colours.rgb[skin.faces].astype(np.float32)  # (m, 3, 3)
    w32 = weights.astype(np.float32)
    texels = np.zeros((n_cells, cell * cell, 3), np.float32)
    for c in range(3):
        texels += w32[None, :, c, None] * rgb_corners[tex_tri, c]
    if scan is not None and scan_colours is not None:
        index = MeshIndex(scan) if index is None else index
        corner_xyz = skin.vertices[skin.faces]  # (m, 3, 3)
        step = max(1, SAMPLE_CHUNK // (cell * cell))
        for start in range(0, n_cells, step):
            rows = slice(start, min(start + step, n_cells))
            tris = tex_tri[rows]  # (k, texels)
            points = np.einsum("tc,ktcj->ktj", weights, corner_xyz[tris]).reshape(-1, 3)
            near = index.closest_points(points)
            sampled = scan_colour_at(scan, scan_colours, near.face_ids, near.barycentric)
            good = (near.distances <= max_distance_mm) & np.isfinite(sampled).all(axis=1)
            block = texels[rows].reshape(-1, 3)
            block[good] = sampled[good]
            texels[rows] = block.reshape(texels[rows].shape)
    texels[~valid] = 0.0
    blocks = np.zeros((grid * grid, cell * cell, 3), np.float32)
    blocks[:n_cells] = texels
    cells = np.clip(np.rint(blocks), 0, 255).astype(np.uint8).reshape(grid, grid, cell, cell, 3)
    image = np.zeros((size, size, 3), np.uint8)
    image[: grid * cell, : grid * cell] = cells.transpose(0, 2, 1, 3, 4).reshape(
        grid * cell, grid * cell, 3
    )
    return image, uv


def _obj_text(skin: Mesh, uv: np.ndarray) -> str:
    m = skin.n_faces
    lines = [
        "# units: mm, head frame (x to the subject's left, y up, z toward the face)",
        "# written by forensic-workbench: fitted skin with its colour atlas",
        f"mtllib {MTL_NAME}",
    ]
    body = "\n".join(lines) + "\n"
    body += "".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in skin.vertices.tolist())
    body += "".join(f"vt {u:.7f} {v:.7f}\n" for u, v in uv.reshape(-1, 2).tolist())
    body += f"usemtl {MATERIAL}\n"
    vi = skin.faces + 1
    ti = np.arange(1, 3 * m + 1).reshape(m, 3)
    table = np.stack([vi, ti], axis=-1).reshape(m, 6)
    body += ("f %d/%d %d/%d %d/%d\n" * m) % tuple(table.ravel().tolist())
    return body


def write_coloured_skin(
    folder: str | PathLike[str],
    skin: Mesh,
    colours: SkinColours,
    *,
    atlas_size: int = 2048,
    scan: Mesh | None = None,
    scan_colours: ScanColours | None = None,
    max_distance_mm: float = 3.0,
    index: MeshIndex | None = None,
) -> list[Path]:
    """Write ``skin_colour.ply``, ``skin_textured.obj``, ``.mtl`` and ``skin_texture.png``.

    Parameters
    ----------
    folder : path-like
        An existing folder (the caller stages it and writes it atomically).
    skin : Mesh
        The fitted skin (head frame, mm).
    colours : SkinColours
        Its vertex colours (:func:`workbench.core.colour_transfer.transfer_colours`).
    atlas_size : int
        Side of the square atlas in pixels (grows when the skin has too many
        triangles for legible patches).
    scan, scan_colours : optional
        The scan in the same frame and its colours: the atlas samples them
        texel by texel instead of blending the vertex colours.
    max_distance_mm : float
        Texels whose closest scan point is farther keep the vertex blend.
    index : MeshIndex, optional
        A spatial index of ``scan`` already built.

    Returns
    -------
    list of Path
        The four files written.
    """
    from PIL import Image

    folder = Path(folder)
    if len(colours.rgb) != skin.n_vertices:
        raise ValueError(f"{len(colours.rgb)} colours for {skin.n_vertices} skin vertices")
    ply_path = folder / PLY_NAME
    ply_path.write_bytes(
        ply.encode(
            skin.vertices,
            np.asarray(skin.faces),
            binary=True,
            comments=[
                HEAD_FRAME_COMMENT,
                f"colours: {colours.kind} colours of the scan, "
                f"{int(colours.observed.sum())} of {skin.n_vertices} vertices observed, "
                "the rest filled",
            ],
            vertex_rgb=colours.rgb,
        )
    )
    image, uv = texture_atlas(
        skin,
        colours,
        atlas_size=atlas_size,
        scan=scan,
        scan_colours=scan_colours,
        max_distance_mm=max_distance_mm,
        index=index,
    )
    png_path = folder / PNG_NAME
    Image.fromarray(image, "RGB").save(png_path, format="PNG", optimize=False)
    mtl_path = folder / MTL_NAME
    mtl_path.write_text(
        f"# written by forensic-workbench\nnewmtl {MATERIAL}\n"
        "Ka 1 1 1\nKd 1 1 1\nKs 0 0 0\nillum 1\n"
        f"map_Kd {PNG_NAME}\n"
    )
    obj_path = folder / OBJ_NAME
    obj_path.write_text(_obj_text(skin, uv))
    return [ply_path, obj_path, mtl_path, png_path]


def read_skin_texture(folder: str | PathLike[str], skin: Mesh) -> SkinTexture | None:
    """The atlas a pack holds for ``skin`` (``skin_textured.obj`` + ``skin_texture.png``).

    None when either file is missing or the OBJ's triangles or vertices are not
    ``skin``'s (within 1e-6 mm): the atlas belongs to another skin.
    """
    from PIL import Image

    from workbench.io.mesh_formats import obj

    root = Path(folder)
    obj_path, png_path = root / OBJ_NAME, root / PNG_NAME
    if not (obj_path.is_file() and png_path.is_file()):
        return None
    parsed = obj.read(obj_path, obj_path.read_bytes())
    same = (
        parsed.corner_uv is not None
        and np.array_equal(parsed.faces, skin.faces)
        and parsed.vertices.shape == skin.vertices.shape
        and np.allclose(parsed.vertices, skin.vertices, rtol=0.0, atol=1e-6)
    )
    if not same or parsed.corner_uv is None:
        return None
    with Image.open(png_path) as im:
        image = np.asarray(im.convert("RGB"), dtype=np.uint8)
    return SkinTexture(image, np.asarray(parsed.corner_uv, float), file=PNG_NAME)


__all__ = ["atlas_layout", "read_skin_texture", "texture_atlas", "write_coloured_skin"]
