"""Iso-surface extraction from CT volumes: tissue presets, marching cubes, clean-up.

Output frame
------------
Meshes are in millimetres in the volume's physical frame (``volume.frame``,
LPS or RAS), i.e. vertex = ``volume.index_to_physical(ijk)``.  Faces are
wound so that normals point *out of* the high-value region (out of the bone
or the body): a closed surface has positive signed volume.

Tissue presets (:func:`choose_iso`)
-----------------------------------
* Hounsfield units (``volume.units == "HU"``):

  - bone 300 HU.  Bone thresholds in the literature and in segmentation
    software range over about 200-400 HU (Materialise Mimics' predefined
    "Bone (CT)" range starts at 226 HU; many craniofacial 3-D studies use
    250-300 HU).  300 HU stays clear of muscle/blood (40-80 HU) and of
    contrast/partial-volume soft tissue, while thin facial bones (orbit
    walls, maxilla), whose values are lowered by partial volume, survive
    better than with 400+ HU.
  - skin -300 HU.  The skin surface is the air (-1000 HU) / soft-tissue
    boundary; fat is about -100 HU, skin and muscle +20..+60 HU.  Any level
    between -900 and -150 finds that boundary; -300 is far from both the
    air noise (a few tens of HU) and from fat, so subcutaneous fat is never
    cut, and it lies on the steep part of the partial-volume ramp so the
    surface sits within a fraction of a voxel of the true boundary.

* Units not stated but the values are Hounsfield units (a NIfTI from a CT
  rarely says so): signed data whose air peak lies at -1000 ± 50 (at least
  :data:`AIR_PEAK_SHARE` of the voxels between -1200 and -500 HU fall there)
  and whose values reach 1000: the HU presets, said so in the rule.  The
  Visible Human NIfTIs (-1024..3063) used to get multi-Otsu's 609 instead,
  which loses about half of the thin bone (orbital walls, nasal bones).
* Not HU, value range like VTK's ``headsq`` sample (integer data,
  min >= 0, max between 1500 and 4600, i.e. 12-bit CT numbers with air at
  0): the VTK "Medical" examples' levels skin 500 and bone 1150.
* Anything else: three-class multi-Otsu (air / soft tissue / bone) on the
  voxel histogram; skin = the lower threshold, bone = the upper.

The rule used is returned with the level and recorded in the result.

Pipeline (:func:`extract_isosurface`)
-------------------------------------
crop to the bounding box of voxels above the level (+1 voxel) -> marching
cubes (scikit-image, Lewiner, ``allow_degenerate=False``) in slabs along k
with a one-slice overlap, each slab cast to float32 -> exact welding of the
vertices on the shared slices (and any coincident vertices) -> map to mm ->
largest edge-connected component -> Taubin smoothing -> quadric decimation
(fast_simplification) -> largest component again (decimation can split off
slivers).  The component is selected *before* smoothing and decimation so
that the triangle target applies to the kept surface and no time is spent on
debris.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from time import perf_counter
from typing import Any

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import connected_components

from workbench.core import helper_process
from workbench.core.errors import InputError
from workbench.core.mesh import Mesh
from workbench.core.volume import Volume

HU_PRESETS = {"bone": 300.0, "skin": -300.0}
VTK_MEDICAL_PRESETS = {"skin": 500.0, "bone": 1150.0}
TISSUES = ("bone", "skin")
SLAB_BYTES = 64 * 2**20  # float32 bytes per marching-cubes slab

Progress = Callable[[str, float], None]


@dataclass(frozen=True)
class IsoChoice:
    """An iso level (native voxel units) and why it was chosen."""

    iso: float
    rule: str


@dataclass(frozen=True)
class IsoSurfaceResult:
    """Mesh (mm, ``frame``), level used (voxel units), rule and statistics."""

    mesh: Mesh
    iso: float
    rule: str
    stats: dict[str, Any] = field(default_factory=dict)
    frame: str = "LPS"


# ---------------------------------------------------------------- presets
def choose_iso(volume: Volume, tissue: str) -> IsoChoice:
    """Preset iso level for ``tissue`` ("bone" or "skin"); see the module docstring."""
    if tissue not in TISSUES:
        raise ValueError(f"tissue must be one of {TISSUES}, got {tissue!r}")
    if volume.units == "HU":
        level = HU_PRESETS[tissue]
        return IsoChoice(level, f"HU preset: {tissue} {level:g} HU")
    lo, hi = volume.value_range()
    if looks_like_hu(volume):
        level = HU_PRESETS[tissue]
        return IsoChoice(
            level,
            f"HU preset: {tissue} {level:g} HU (the file does not state its units; the values "
            f"look like Hounsfield units: air at -1000, data {lo:g}..{hi:g})",
        )
    if volume.data.dtype.kind in "iu" and lo >= 0 and 1500 < hi <= 4600:
        level = VTK_MEDICAL_PRESETS[tissue]
        return IsoChoice(
            level,
            f"VTK Medical-example convention for raw 0..~4000 CT numbers: {tissue} {level:g} "
            f"(data range {lo:g}..{hi:g}, not HU)",
        )
    from skimage.filters import threshold_multiotsu

    counts, centres = volume.histogram()
    if len(counts) < 3:
        raise InputError(
            volume.source, f"the volume has fewer than 3 distinct values ({lo:g}..{hi:g})"
        )
    t_low, t_high = threshold_multiotsu(classes=3, hist=(counts, centres))
    level = float(t_high if tissue == "bone" else t_low)
    return IsoChoice(
        level,
        f"multi-Otsu (3 classes air/soft tissue/bone, thresholds {t_low:g}, {t_high:g}): "
        f"{tissue} {level:g} (data range {lo:g}..{hi:g}, units {volume.units})",
    )


#: share of the voxels between -1200 and -500 that must lie within 50 of -1000 (air) for
#: data of unstated units to be read as Hounsfield units
AIR_PEAK_SHARE = 0.5


def looks_like_hu(volume: Volume) -> bool:
    """Whether data of unstated units are Hounsfield units: signed values with an air peak
    at -1000 ± 50 (see the module docstring) and values up to at least 1000 (bone)."""
    lo, hi = volume.value_range()
    if lo > -900 or hi < 1000:
        return False
    counts, centres = volume.histogram()
    band = (centres >= -1200) & (centres <= -500)
    if counts[band].sum() == 0:
        return False
    air = band & (np.abs(centres + 1000) <= 50)
    return bool(counts[air].sum() >= AIR_PEAK_SHARE * counts[band].sum())


def thin_bone_loss(volume: Volume, iso: float, reference: float) -> dict[str, float] | None:
    """What a bone level ``iso`` leaves out of the bone seen at ``reference`` (same units).

    ``lost`` is the share of the voxels at or above ``reference`` that fall below
    ``iso``; ``thin_lost`` that share among the *thin* bone at ``reference`` (voxels a
    3 x 3 x 3 opening removes: plates under about three voxels thick, such as the
    orbital walls, the nasal bones, the sinus walls and the ethmoid, whose values
    partial volume lowers first).  None when ``iso`` is not above ``reference``.
    """
    from scipy import ndimage

    if not iso > reference:
        return None
    data = np.asarray(volume.data)
    bone = data >= reference
    if not bone.any():
        return None
    box = tuple(
        slice(max(s.start - 1, 0), s.stop + 1)
        for s in ndimage.find_objects(bone.astype(np.int8))[0]
    )
    sub = bone[box]
    cube = np.ones((3, 3, 3), bool)
    thick = ndimage.binary_dilation(ndimage.binary_erosion(sub, cube), cube)
    thin = sub & ~thick
    kept = data[box] >= iso
    n_thin = int(thin.sum())
    return {
        "lost": float(1.0 - kept[sub].mean()),
        "thin_lost": float(1.0 - kept[thin].mean()) if n_thin else 0.0,
        "thin_share": float(n_thin / sub.sum()),
    }


# ---------------------------------------------------------------- mesh helpers
def _edge_keys(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e.sort(axis=1)
    return e[:, 0] * np.int64(n_vertices) + e[:, 1]


def face_component_labels(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """``(m,)`` label of the edge-connected component of each face."""
    m = len(faces)
    if m == 0:
        return np.zeros(0, np.int64)
    keys = _edge_keys(faces, n_vertices)
    order = np.argsort(keys, kind="stable")
    same = keys[order][1:] == keys[order][:-1]
    face_of = np.tile(np.arange(m), 3)[order]
    a, b = face_of[:-1][same], face_of[1:][same]
    graph = sparse.coo_matrix((np.ones(len(a), np.int8), (a, b)), shape=(m, m)).tocsr()
    return connected_components(graph, directed=False)[1]


def _compact(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    used = np.zeros(len(vertices), bool)
    used[faces.ravel()] = True
    new_index = np.cumsum(used) - 1
    return vertices[used], new_index[faces]


def keep_largest_component(vertices: np.ndarray, faces: np.ndarray):
    """Largest edge-connected piece; returns (vertices, faces, n_components)."""
    labels = face_component_labels(faces, len(vertices))
    if len(labels) == 0:
        return vertices, faces, 0
    sizes = np.bincount(labels)
    v, f = _compact(vertices, faces[labels == int(np.argmax(sizes))])
    return v, f, len(sizes)


def taubin_smooth(
    vertices: np.ndarray, faces: np.ndarray, iterations: int, lam: float = 0.5, mu: float = -0.53
) -> np.ndarray:
    """Taubin lambda/mu smoothing (uniform umbrella Laplacian), boundary vertices fixed.

    Each iteration is a shrinking step (``lam`` > 0) followed by an
    inflating step (``mu`` < -``lam``): a low-pass filter that removes
    marching-cubes terracing without the volume loss of plain Laplacian
    smoothing.  Units are those of ``vertices`` (mm).
    """
    n = len(vertices)
    keys = _edge_keys(faces, n)
    uniq, counts = np.unique(keys, return_counts=True)
    a, b = uniq // n, uniq % n
    adjacency = sparse.coo_matrix(
        (np.ones(2 * len(a)), (np.concatenate([a, b]), np.concatenate([b, a]))), shape=(n, n)
    ).tocsr()
    degree = np.asarray(adjacency.sum(axis=1)).ravel()
    with np.errstate(divide="ignore"):
        weights = sparse.diags(np.where(degree > 0, 1.0 / np.maximum(degree, 1), 0.0)) @ adjacency
    movable = (degree > 0)[:, None].astype(np.float64)
    movable[np.concatenate([a[counts == 1], b[counts == 1]])] = 0.0
    v = np.array(vertices, dtype=np.float64, copy=True)
    for _ in range(int(iterations)):
        for factor in (lam, mu):
            v += factor * movable * (weights @ v - v)
    return v


#: fast_simplification keeps its working mesh in process-wide globals
#: (``Simplify::vertices``/``triangles`` in its Simplify.h): two calls at
#: once from different threads corrupt the heap, so calls are serialised.
_SIMPLIFY_LOCK = threading.Lock()


@helper_process.runnable
def decimate(vertices: np.ndarray, faces: np.ndarray, target_triangles: int):
    """Quadric decimation to about ``target_triangles`` faces (open borders kept).

    Thread-safe (one decimation at a time, see ``_SIMPLIFY_LOCK``).  It keeps
    the GIL throughout (~230 ms per 100k triangles), so callers that may run
    beside a GUI go through :func:`workbench.core.helper_process.run`.
    """
    import fast_simplification

    if target_triangles >= len(faces):
        return vertices, faces
    v_in = np.array(vertices, np.float64, order="C")
    f_in = np.array(faces, np.int64, order="C")
    with _SIMPLIFY_LOCK:
        v, f = fast_simplification.simplify(
            v_in,
            f_in,
            target_count=int(target_triangles),
            preserve_border=True,  # no-op on closed meshes
        )
    return _compact(np.asarray(v, np.float64), np.asarray(f, np.int64))


# ---------------------------------------------------------------- marching cubes
def _crop_box(data: np.ndarray, above: Callable[[np.ndarray], np.ndarray]):
    """Index ranges (k, j, i) [start, stop) of voxels above the level, grown by 1."""
    nk, nj, ni = data.shape
    k_any = np.zeros(nk, bool)
    j_any = np.zeros(nj, bool)
    i_any = np.zeros(ni, bool)
    step = max(1, (16 * 2**20) // max(1, nj * ni))
    for k0 in range(0, nk, step):
        mask = above(data[k0 : k0 + step])
        k_any[k0 : k0 + step] = mask.any(axis=(1, 2))
        j_any |= mask.any(axis=(0, 2))
        i_any |= mask.any(axis=(0, 1))
    if not k_any.any():
        return None
    box = []
    for flags, size in ((k_any, nk), (j_any, nj), (i_any, ni)):
        idx = np.flatnonzero(flags)
        box.append((max(int(idx[0]) - 1, 0), min(int(idx[-1]) + 2, size)))
    return box


def _weld(
    verts: np.ndarray, faces: np.ndarray, seams: list[int]
) -> tuple[np.ndarray, np.ndarray, int]:
    """Merge the vertices that two slabs both produced on their shared slices ``seams``.

    Within a slab scikit-image already shares each edge vertex between its
    triangles; across a seam both slabs interpolate the same two voxel values,
    so the duplicates are bit-identical and are merged exactly.
    """
    if not seams:
        return verts, faces, 0
    cand = np.flatnonzero(np.isin(verts[:, 0], np.asarray(seams, np.float64)))
    if len(cand) < 2:
        return verts, faces, 0
    sub = verts[cand]
    order = np.lexsort((sub[:, 2], sub[:, 1], sub[:, 0]))
    s = sub[order]
    new_group = np.ones(len(s), bool)
    new_group[1:] = np.any(s[1:] != s[:-1], axis=1)
    n_merged = int((~new_group).sum())
    if n_merged == 0:
        return verts, faces, 0
    first = cand[order][new_group]
    remap = np.arange(len(verts))
    remap[cand[order]] = first[np.cumsum(new_group) - 1]
    faces = remap[faces]
    ok = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 2] != faces[:, 0])
    v, f = _compact(verts, faces[ok])
    return v, f, n_merged


def _marching_cubes_slabs(data, level, box, slab_slices, report):
    from skimage.measure import marching_cubes

    (k0, k1), (j0, j1), (i0, i1) = box
    if slab_slices is None:
        slab_slices = max(2, SLAB_BYTES // (4 * (j1 - j0) * (i1 - i0)))
    slab_slices = max(1, int(slab_slices))
    starts = list(range(k0, k1 - 1, slab_slices))
    verts_parts, face_parts, n_verts = [], [], 0
    for n, start in enumerate(starts):
        stop = min(start + slab_slices + 1, k1)  # one slice shared with the next slab
        slab = data[start:stop, j0:j1, i0:i1].astype(np.float32)
        if slab.shape[0] >= 2 and slab.min() < level < slab.max():
            try:
                v, f, _, _ = marching_cubes(slab, level, allow_degenerate=False)
            except RuntimeError:  # no surface in this slab
                v = np.zeros((0, 3), np.float32)
            if len(v):
                verts_parts.append(v.astype(np.float64) + (start, j0, i0))
                face_parts.append(f.astype(np.int64) + n_verts)
                n_verts += len(v)
        del slab
        report("marching cubes", (n + 1) / len(starts))
    if not verts_parts:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64), starts
    return np.concatenate(verts_parts), np.concatenate(face_parts), starts


def extract_isosurface(
    volume: Volume,
    iso: float | str,
    *,
    largest_component: bool = True,
    smooth_iterations: int = 0,
    target_triangles: int | None = None,
    progress: Progress | None = None,
    slab_slices: int | None = None,
) -> IsoSurfaceResult:
    """Iso-surface of ``volume`` at ``iso`` as a mesh in mm (volume frame).

    Parameters
    ----------
    volume : Volume
        Scalar volume; ``iso`` is in its native units (HU for CT).
    iso : float or {"bone", "skin"}
        Level, or a tissue name resolved with :func:`choose_iso`.
    largest_component : bool
        Keep only the largest edge-connected piece.
    smooth_iterations : int
        Taubin lambda/mu iterations (0 = none).
    target_triangles : int, optional
        Decimate to about this many triangles (quadric error metric).
    progress : callable(step: str, fraction: float), optional
        Called with the step name and the overall fraction done (0..1).
    slab_slices : int, optional
        Slices per marching-cubes slab (default: about 64 MB of float32).

    Returns
    -------
    IsoSurfaceResult
        ``mesh`` (mm, outward normals), ``iso`` used, ``rule``, ``stats``
        (counts and per-step timings in s) and ``frame``.
    """
    spans = {
        "crop": (0.0, 0.05),
        "marching cubes": (0.05, 0.75),
        "components": (0.75, 0.8),
        "smoothing": (0.8, 0.9),
        "decimation": (0.9, 1.0),
    }

    def report(step: str, fraction: float) -> None:
        if progress is not None:
            a, b = spans[step]
            progress(step, a + (b - a) * min(max(fraction, 0.0), 1.0))

    timings: dict[str, float] = {}
    clock = perf_counter()

    def lap(name: str) -> None:
        nonlocal clock
        now = perf_counter()
        timings[name] = round(now - clock, 4)
        clock = now

    choice = (
        choose_iso(volume, iso) if isinstance(iso, str) else IsoChoice(float(iso), "explicit level")
    )
    data = volume.data
    lo, hi = volume.value_range()
    if not lo < choice.iso < hi:
        raise InputError(
            volume.source, f"iso level {choice.iso:g} is outside the data range {lo:g}..{hi:g}"
        )
    # Shift the level by a negligible amount so that no voxel equals it exactly
    # (integer CT values equal to an integer level would put vertices on grid
    # points and create coincident vertices); voxels == iso count as inside.
    level = choice.iso - max(1e-6 * (hi - lo), 4 * float(np.spacing(np.float32(abs(choice.iso)))))
    if data.dtype.kind in "iu":
        threshold = int(np.floor(level))
        above = lambda a: a > threshold  # noqa: E731 - integer compare, no float copy
    else:
        above = lambda a: a > level  # noqa: E731
    report("crop", 0.0)
    box = _crop_box(data, above)
    lap("crop")
    if box is None:
        raise InputError(volume.source, f"no voxel is above the iso level {choice.iso:g}")
    verts, faces, starts = _marching_cubes_slabs(data, np.float32(level), box, slab_slices, report)
    lap("marching_cubes")
    if len(faces) == 0:
        raise InputError(volume.source, f"no surface found at iso level {choice.iso:g}")
    stats: dict[str, Any] = {
        "level_used": float(level),
        "crop_kji": [list(b) for b in box],
        "n_slabs": len(starts),
        "n_faces_marching_cubes": int(len(faces)),
    }
    verts, faces, stats["n_vertices_welded"] = _weld(verts, faces, starts[1:])
    # (k, j, i) -> (i, j, k) is an odd permutation: skimage's inward winding becomes outward
    verts = volume.index_to_physical(verts[:, ::-1])
    if np.linalg.det(volume.direction) < 0:
        faces = faces[:, ::-1]
    lap("weld")
    if largest_component:
        verts, faces, stats["n_components"] = keep_largest_component(verts, faces)
        stats["n_faces_largest_component"] = int(len(faces))
    report("components", 1.0)
    lap("components")
    if smooth_iterations:
        verts = taubin_smooth(verts, faces, smooth_iterations)
    report("smoothing", 1.0)
    lap("smoothing")
    if target_triangles is not None and target_triangles < len(faces):
        verts, faces = helper_process.run(
            "workbench.core.isosurface:decimate", verts, faces, int(target_triangles)
        )
        if largest_component:
            verts, faces, _ = keep_largest_component(verts, faces)
    report("decimation", 1.0)
    lap("decimation")
    mesh = Mesh(verts, faces)
    stats.update(
        n_vertices=mesh.n_vertices,
        n_faces=mesh.n_faces,
        frame=volume.frame,
        timings_s=timings,
    )
    return IsoSurfaceResult(mesh, choice.iso, choice.rule, stats, volume.frame)
