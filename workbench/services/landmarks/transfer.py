"""Transfer the reference head's landmark set onto a target skull or skin surface.

Kähler (2003, §8.4.2) lets the user place three or more landmarks, warps the
reference onto them, and copies every remaining landmark across as a rough
layout to correct by hand.  We do the same with zero to a few user points
and go further:

1. **Coarse alignment** (:mod:`workbench.services.landmarks.alignment`): similarity
   from the seeds (three or more), else a trimmed-ICP search, started from an
   orientation hint when one is known.
2. **Non-rigid refinement**: a few hundred well-spread points of the
   reference surface are warped onto the target, matched to their closest
   target points, and a *regularised* landmark warp (φ(r) = r, §8.3.1) is
   re-fitted from the accepted matches in rounds of decreasing search radius
   (15 → 3 mm) and smoothing.  Matches are accepted conservatively, as
   §8.4.3 insists ("one wrongly placed landmark can distort the whole
   deformed geometry"): close enough, surface normals agreeing, not on the
   rim of a hole or of the field of view, and not an outlier of the round.
3. **Projection**: each warped landmark moves to the closest target point.
   A landmark whose closest point is far away, or lies on the rim of a hole
   or cut, is reported **absent** (never a point floating in space).
   Confidence in [0, 1] falls with the projection distance, with normal
   disagreement and with the distance to the nearest accepted match.

Seeds (user-placed landmarks) keep their positions and status ``placed``.
Units mm; positions are returned in the **target's input frame**.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from workbench.core.landmarks import Landmark, LandmarkSet
from workbench.core.mesh import Mesh
from workbench.core.normals import vertex_normals
from workbench.core.spatial import MeshIndex
from workbench.core.tps import fit_warp
from workbench.services.landmarks.alignment import SCALE_RANGE, Alignment, align_to_reference

#: (search radius mm, smoothing λ) per refinement round
ROUNDS = (
    (15.0, 40.0),
    (12.0, 30.0),
    (10.0, 20.0),
    (8.0, 12.0),
    (6.0, 8.0),
    (5.0, 5.0),
    (4.0, 3.0),
    (3.0, 2.0),
)
N_SAMPLES = 350
#: a landmark this far from the target surface (after the warp) is absent
ABSENT_MM = 6.0
MIN_NORMAL_DOT = 0.5
#: ... unless accepted surface matches lie closer than this (then it is a poor fit)
UNSUPPORTED_MM = 15.0


@dataclass(frozen=True)
class TransferResult:
    """Landmarks suggested on a target surface.

    Attributes
    ----------
    landmarks : LandmarkSet
        Input frame, mm; statuses placed (seeds) / suggested / absent.
    alignment : Alignment
        Coarse target → head-frame similarity.
    warp_residual_mm : float
        RMS distance of the accepted matches after the last round.
    matches : int
        Accepted surface matches in the last round.
    correspondences : (source_points, target_points)
        The accepted matches of the last round (head frame, source; target
        in head-frame coordinates of the aligned target), for callers that
        warp whole meshes with the same field.
    warnings : tuple of str
    """

    landmarks: LandmarkSet
    alignment: Alignment
    warp_residual_mm: float
    matches: int
    correspondences: tuple[np.ndarray, np.ndarray]
    warnings: tuple[str, ...] = field(default_factory=tuple)

    @property
    def absent(self) -> tuple[str, ...]:
        return tuple(lm.code for lm in self.landmarks if lm.status == "absent")


def _farthest_points(points: np.ndarray, n: int, start: int = 0) -> np.ndarray:
    n = min(n, len(points))
    chosen = np.empty(n, dtype=np.int64)
    chosen[0] = start
    d = np.linalg.norm(points - points[start], axis=1)
    for i in range(1, n):
        chosen[i] = int(np.argmax(d))
        d = np.minimum(d, np.linalg.norm(points - points[chosen[i]], axis=1))
    return chosen


def rim_faces(mesh: Mesh) -> np.ndarray:
    """Faces touching a boundary vertex (the rim of a hole or of the field of view)."""
    rim_vertices = np.zeros(mesh.n_vertices, dtype=bool)
    rim_vertices[mesh.edges_unique[mesh.edge_face_counts == 1].ravel()] = True
    return rim_vertices[mesh.faces].any(axis=1)


def _match(
    index: MeshIndex,
    rim: np.ndarray,
    pts: np.ndarray,
    normals: np.ndarray,
    radius: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    cp = index.closest_points(pts)
    d = np.linalg.norm(cp.points - pts, axis=1)
    # (the closest feature's normal: a face's would depend on which face a tie returned)
    dot = np.abs(np.einsum("ij,ij->i", index.pseudo_normals(cp.face_ids, cp.barycentric), normals))
    ok = (d <= radius) & (dot >= MIN_NORMAL_DOT) & ~rim[cp.face_ids]
    if ok.sum() > 10:  # drop outliers of this round (median + 3 MAD)
        med = np.median(d[ok])
        mad = np.median(np.abs(d[ok] - med)) + 1e-6
        ok &= d <= med + 3.0 * 1.4826 * mad
    return ok, cp.points, d


def transfer_landmarks(
    target: Mesh,
    reference: Mesh,
    reference_landmarks: LandmarkSet,
    *,
    seeds: LandmarkSet | None = None,
    orientation: tuple | None = None,
    alignment: Alignment | None = None,
    n_samples: int = N_SAMPLES,
) -> TransferResult:
    """Suggest ``reference_landmarks`` (head frame) on ``target`` (input frame, mm).

    Parameters
    ----------
    target : Mesh
        The skull or skin surface, in the input frame, mm (holes allowed).
    reference : Mesh
        The reference head's matching surface in the head frame.
    reference_landmarks : LandmarkSet
        The codes to transfer (head frame).
    seeds : LandmarkSet, optional
        User-placed landmarks on ``target`` (input frame); kept as they are.
    orientation : (anterior, superior[, left]) in target coordinates, optional
    alignment : Alignment, optional
        A coarse alignment already computed (e.g. from the skull, reused for
        the skin of the same CT).
    """
    warnings: list[str] = []
    ref_lms = reference_landmarks.defined()
    seed_pts = {} if seeds is None else seeds.as_dict()
    common = [c for c in ref_lms.codes if c in seed_pts]
    if alignment is None:
        seed_pair = None
        if len(common) >= 3:
            seed_pair = (np.array([seed_pts[c] for c in common]), ref_lms.positions_of(common))
        alignment = align_to_reference(target, reference, orientation=orientation, seeds=seed_pair)
    if not (SCALE_RANGE[0] + 0.01 < alignment.scale < SCALE_RANGE[1] - 0.01):
        warnings.append(
            f"the target is about {1 / alignment.scale:.2f} times the reference size; "
            "check the units or scale of the mesh"
        )
    # target in head-frame coordinates (the reference does not move)
    tmesh = target.with_vertices(alignment.apply(target.vertices))
    index = MeshIndex(tmesh)
    rim = rim_faces(tmesh)

    rv = reference.vertices
    rn = vertex_normals(reference)
    picks = _farthest_points(rv, n_samples)
    src = rv[picks]
    srcn = rn[picks]
    seed_src = ref_lms.positions_of(common) if common else np.zeros((0, 3))
    seed_dst = alignment.apply(np.array([seed_pts[c] for c in common])) if common else seed_src
    warp = None
    ok = np.zeros(len(src), dtype=bool)
    matched = src
    resid = float("nan")
    for radius, smoothing in ROUNDS:
        moved = src if warp is None else warp(src)
        ok, matched, d = _match(index, rim, moved, srcn, radius)
        if ok.sum() < 12:
            warnings.append(
                f"only {int(ok.sum())} surface matches within {radius:g} mm; "
                "the suggestion is a coarse alignment only"
            )
            break
        resid = float(np.sqrt(np.mean(d[ok] ** 2)))
        s = np.vstack([src[ok], seed_src])
        t = np.vstack([matched[ok], seed_dst])
        s, keep = np.unique(s, axis=0, return_index=True)
        warp = fit_warp(s, t[keep], smoothing=smoothing)

    codes = list(ref_lms.codes)
    pts = ref_lms.positions
    moved = pts if warp is None else warp(pts)
    lm_normals = _normals_at(reference, pts)
    cp = index.closest_points(moved)
    dist = np.linalg.norm(cp.points - moved, axis=1)
    dot = np.einsum("ij,ij->i", index.pseudo_normals(cp.face_ids, cp.barycentric), lm_normals)
    support = (
        np.min(np.linalg.norm(moved[:, None] - matched[ok][None], axis=2), axis=1)
        if ok.any()
        else np.full(len(codes), np.inf)
    )
    positions = alignment.inverse(cp.points)
    out = []
    for i, code in enumerate(codes):
        if code in seed_pts:
            out.append(
                Landmark(
                    code,
                    seed_pts[code],
                    "placed",
                    1.0,
                    seeds[code].description if seeds is not None else "",
                )
            )
            continue
        on_rim = bool(rim[cp.face_ids[i]])
        # absent: beyond the rim of a hole/cut, or far off with no surface
        # match anywhere near (a missing part); a far point among matches is
        # a poor fit instead, kept with a low confidence
        if (on_rim and dist[i] > 2.0) or (dist[i] > ABSENT_MM and support[i] > UNSUPPORTED_MM):
            why = (
                "beyond a hole or the scan's edge"
                if on_rim
                else f"{dist[i]:.1f} mm off the surface"
            )
            out.append(
                Landmark(code, np.full(3, np.nan), "absent", 0.0, f"no surface here ({why})")
            )
            continue
        conf = (
            np.exp(-((dist[i] / 3.0) ** 2))
            * np.clip(abs(dot[i]), 0.0, 1.0)
            * np.exp(-max(support[i] - 10.0, 0.0) / 20.0)
        )
        out.append(Landmark(code, positions[i], "suggested", float(np.clip(conf, 0.01, 0.99))))
    absent = [lm.code for lm in out if lm.status == "absent"]
    if absent:
        warnings.append(f"{len(absent)} landmarks absent (no surface): {', '.join(absent)}")
    return TransferResult(
        LandmarkSet(reference_landmarks.surface, tuple(out)),
        alignment,
        resid,
        int(ok.sum()),
        (src[ok], matched[ok]) if ok.any() else (np.zeros((0, 3)),) * 2,
        tuple(warnings),
    )


def _normals_at(mesh: Mesh, points: np.ndarray) -> np.ndarray:
    """The surface normal at ``points``' closest features (a landmark on a vertex gets the
    vertex's pseudo-normal, whichever of its faces the tree returns)."""
    index = MeshIndex(mesh)
    cp = index.closest_points(points)
    return index.pseudo_normals(cp.face_ids, cp.barycentric)
