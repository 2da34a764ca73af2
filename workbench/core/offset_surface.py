"""Uniform-thickness offset of a bone surface: the baseline every reconstruction must beat.

Units: mm in the bone's frame.  ``../shared/design/VALIDATION.md``: the
outer iso-surface at ``depth_mm`` (6 mm) of the unsigned distance to the
bone, sampled on a ``spacing_mm`` (1.5 mm) grid around the bone, largest
component.  Cavities the offset shell encloses (the cranial cavity of a
complete skull, the sinuses) are filled first, so only the outer shell is
left; an open skull (a cut vault) keeps its inner shell joined at the cut.

The distance field is measured to dense surface samples (vertices plus
area-proportional points at about ``spacing_mm / 4``) with a k-d tree
bounded to ``depth_mm + 2 spacing_mm``, so its error is well under 0.1 mm
near the level.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from workbench.core.mesh import Mesh
from workbench.core.threads import worker_count


def _surface_points(mesh: Mesh, spacing: float) -> np.ndarray:
    """Vertices plus area-proportional samples (about one per ``spacing``² of area)."""
    rng = np.random.default_rng(0)
    areas = mesh.face_areas
    n = int(min(4e6, areas.sum() / spacing**2))
    pts = [mesh.vertices]
    if n > 0:
        faces = rng.choice(len(areas), size=n, p=areas / areas.sum())
        r1, r2 = rng.random(n), rng.random(n)
        s = np.sqrt(r1)
        w = np.stack([1 - s, s * (1 - r2), s * r2], axis=1)
        pts.append(np.einsum("ij,ijk->ik", w, mesh.vertices[mesh.faces[faces]]))
    return np.vstack(pts)


def uniform_offset(bone: Mesh, depth_mm: float = 6.0, spacing_mm: float = 1.5) -> Mesh:
    """The outer surface at ``depth_mm`` from ``bone`` (outward-wound, mm, bone frame)."""
    from skimage.measure import marching_cubes

    from workbench.core.isosurface import keep_largest_component

    if not (0 < depth_mm < 100 and 0.2 <= spacing_mm <= 10):
        raise ValueError("offset depth must be 0-100 mm and the grid spacing 0.2-10 mm")
    pad = depth_mm + 3 * spacing_mm
    lo = bone.bounds[0] - pad
    shape = np.ceil((bone.bounds[1] + pad - lo) / spacing_mm).astype(int) + 1
    axes = [lo[i] + spacing_mm * np.arange(shape[i]) for i in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    cap = depth_mm + 2 * spacing_mm
    tree = cKDTree(_surface_points(bone, spacing_mm / 4))
    dist, _ = tree.query(grid, distance_upper_bound=cap, workers=worker_count())
    field = np.minimum(dist, cap).reshape(shape)
    solid = field < depth_mm
    labels, n = ndimage.label(solid)
    if n == 0:
        raise ValueError("the bone surface is empty")
    sizes = np.bincount(labels.ravel())
    sizes[0] = 0
    solid = ndimage.binary_fill_holes(labels == sizes.argmax())
    field = np.where(solid & (field >= depth_mm), 0.0, field)
    field = np.where(~solid & (field < depth_mm), cap, field)
    verts, faces, _, _ = marching_cubes(
        field.astype(np.float32), level=depth_mm, spacing=(spacing_mm,) * 3, allow_degenerate=False
    )
    verts = verts + lo
    # marching cubes winds toward the high values (outside here): already outward
    v, f, _ = keep_largest_component(verts.astype(np.float64), faces.astype(np.int64))
    mesh = Mesh(v, f)
    if mesh.volume < 0:
        mesh = Mesh(v, f[:, ::-1])
    return mesh
