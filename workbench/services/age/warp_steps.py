"""The warp steps of the age change (:func:`workbench.services.age.change.age_head`, step 5).

Units mm; the head is in its Frankfort frame.  The skin's landmark spline
from the current landmarks and arc middles to the solved ones, the whole-head
deformation it drives (the source tissue depths restored below the new skin
landmarks, the eyeballs scaled by their own growth and seated in the
lids), the relaxation of skin triangles the warp turned over, and the push of
skin that ended inside the aged skull back outside it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from workbench.core.errors import WorkbenchError
from workbench.core.growth_solve import Constraint, arc_length, arc_sagitta
from workbench.core.mesh import Mesh
from workbench.core.normals import normals_within_radius
from workbench.core.spatial import MeshIndex
from workbench.core.tps import fit_warp
from workbench.model.template import TemplateHead
from workbench.services.age.eyes import scale_eyes, seat_eyes
from workbench.services.age.smooth_warp import fit_rounded_warp

#: regulariser of the inner parts' depth-restoring warp (as the scan fit's)
INNER_SMOOTHING = 2.0
#: regulariser of the skin warp at landmarks without a hard constraint (those with one
#: are met exactly, λ = 0): their solved places are a least-squares compromise, and
#: interpolating them exactly creased the lower face of an 18 -> 3 y head
LOOSE_SMOOTHING = 100.0
#: radius of the skin normal average at a landmark or arc middle (mm)
NORMAL_RADIUS_MM = 6.0
INNER_PARTS = ("cranium", "mandible", "upper_teeth", "lower_teeth", "tongue", "eyes")


#: skin found inside the aged skull is put this far outside it (mm)
SKULL_CLEARANCE_MM = 0.5


def skin_out_of_skull(
    head: TemplateHead, rest_normals: np.ndarray, keep: np.ndarray | None = None
) -> tuple[TemplateHead, int, MeshIndex]:
    """Skin vertices inside the cranium or mandible moved to just outside (mm; how many, and
    the index of the skull, which this leaves as it is).

    The warps keep the source's tissue depths at the paired landmarks, but
    between them thin skin (the orbit rims, where the reference heads already
    have a few vertices a fraction of a mm inside the bone; the nasal dorsum of
    a small child) can end inside.  The push is spread over the neighbourhood
    (pushed vertices held, the others relaxed to their neighbours' mean push),
    triangles it turned over (against ``rest_normals``; ``keep`` as in
    :func:`unfold`) are relaxed, and this repeats while skin is inside.
    """
    skull = MeshIndex(_concat([head.meshes["cranium"], head.meshes["mandible"]]))
    skin = head.skin
    adjacency = None
    first = 0
    for round_ in range(PUSH_ROUNDS):
        v = skin.vertices
        bad = np.flatnonzero(skull.signed_distance(v) < 0)
        if round_ == 0:
            first = len(bad)
        if not len(bad):
            break
        cl = skull.closest_points(v[bad])
        normal = skull.pseudo_normals(cl.face_ids, cl.barycentric)
        push = np.zeros_like(v)
        push[bad] = cl.points + SKULL_CLEARANCE_MM * normal - v[bad]
        held = np.zeros(len(v), bool)
        held[bad] = True
        adj, degree = adjacency = adjacency or _adjacency(skin)
        for _ in range(PUSH_SPREAD_PASSES):
            mean = (adj @ push) / np.maximum(degree, 1)[:, None]
            push[~held] = mean[~held]
        skin = unfold(skin.with_vertices(v + push), rest_normals, keep=keep, adjacency=adjacency)
    if skin is head.skin:
        return head, 0, skull
    return replace(head, meshes={**head.meshes, "skin": skin}), first, skull


#: rounds of push (and unfold) while skin is inside the skull
PUSH_ROUNDS = 6
#: Jacobi passes that spread the out-of-skull push over the skin around the pushed vertices
PUSH_SPREAD_PASSES = 20


def _adjacency(skin: Mesh) -> tuple[Any, np.ndarray]:
    """Vertex adjacency of ``skin`` (sparse 0/1 matrix) and each vertex's degree."""
    from scipy import sparse

    f = skin.faces
    n = skin.n_vertices
    e = np.vstack([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    adj = sparse.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n)).tocsr()
    adj = ((adj + adj.T) > 0).astype(float)
    return adj, np.asarray(adj.sum(axis=1)).ravel()


_INSIDE: dict[str, int] = {}


def inside_before(head: TemplateHead, face: np.ndarray) -> int:
    """Face skin vertices inside the source skull (once per source head: a sequence reuses it)."""
    key = head.content_hash
    if key not in _INSIDE:
        skull = MeshIndex(_concat([head.meshes["cranium"], head.meshes["mandible"]]))
        _INSIDE[key] = int((skull.signed_distance(head.skin.vertices[face]) < 0).sum())
    return _INSIDE[key]


def _concat(meshes: Sequence[Mesh]) -> Mesh:
    from workbench.core.mesh import concatenate

    return concatenate(list(meshes))


def arc_middles(
    skin: Mesh, index: MeshIndex, a: np.ndarray, b: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The skin points over the middles of chords a_i–b_i and the outward unit normals
    there, ``(k, 3)`` each (mm; one query for all arcs)."""
    middle = (np.reshape(a, (-1, 3)) + np.reshape(b, (-1, 3))) / 2
    if not len(middle):
        return np.zeros((0, 3)), np.zeros((0, 3))
    hit = index.closest_points(middle).points
    normal = normals_within_radius(skin, hit, NORMAL_RADIUS_MM)
    normal = normal / np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    return hit, normal


#: relaxation rounds for skin triangles the warp turned over (each round: the vertices
#: of turned triangles and their neighbours move halfway to their neighbours' mean)
UNFOLD_ROUNDS = 30
#: skin triangles smaller than this (mm²) are the reference's mouth-corner slivers
SLIVER_MM2 = 0.05


def unfold(
    skin: Mesh,
    rest_normals: np.ndarray,
    keep: np.ndarray | None = None,
    adjacency: tuple[Any, np.ndarray] | None = None,
) -> Mesh:
    """``skin`` with triangles that turned over (against ``rest_normals``) relaxed flat again.

    A thin-plate spline driven by landmarks that move unevenly (the chin
    rising past the cheek landmarks for a young child) can turn a few skin
    triangles over between landmarks.  Only the vertices of turned triangles
    and their one-ring move (umbrella relaxation toward their neighbours'
    mean), so the landmarks (stored as points) and the rest of the skin stay;
    ``keep`` lists triangles not to look at (the reference's own slivers);
    ``adjacency`` is :func:`_adjacency` of ``skin`` when the caller has it.
    """
    f = skin.faces
    n = skin.n_vertices
    adj, degree = adjacency or _adjacency(skin)
    # rims (neck, eye and mouth openings) stay: relaxing them would shrink the openings
    rim = np.zeros(n, bool)
    rim[skin.edges_unique[skin.edge_face_counts == 1].ravel()] = True
    v = skin.vertices.copy()
    ignore = np.zeros(len(f), bool) if keep is None else np.asarray(keep, bool)
    for _ in range(UNFOLD_ROUNDS):
        cross = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
        turned = ((cross * rest_normals).sum(axis=1) < 0) & ~ignore
        if not turned.any():
            break
        move = np.zeros(n, bool)
        move[f[turned].ravel()] = True
        move |= np.asarray(adj[move].sum(axis=0)).ravel() > 0
        move &= ~rim
        mean = (adj @ v) / np.maximum(degree, 1)[:, None]
        v[move] += 0.5 * (mean[move] - v[move])
    return skin.with_vertices(v)


def skin_warp(src: np.ndarray, dst: np.ndarray, lam: np.ndarray) -> Any:
    """The skin's landmark spline (Kähler's, with the rounded kernel of
    :mod:`workbench.services.age.smooth_warp`: no crease at a landmark): coinciding
    sources (stomion and stomion superius of closed lips) merged, hard-constraint
    landmarks exact, the rest loose (λ, mm)."""
    key = np.round(src, 6)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.ravel()
    merged = np.zeros((len(first), 3))
    np.add.at(merged, inverse, dst)
    merged /= np.bincount(inverse, minlength=len(first))[:, None]
    lam_merged = np.full(len(first), np.inf)
    np.minimum.at(lam_merged, inverse, lam)
    return fit_rounded_warp(src[first], merged, smoothing=lam_merged)


def warp_points(
    head: TemplateHead,
    p: np.ndarray,
    q: np.ndarray,
    hard: Sequence[Constraint],
    arcs: Sequence[Any],
    index: Mapping[str, int],
    scale: float,
    arc_increase: float,
    skin_index: MeshIndex | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[tuple[Any, float, float]]]:
    """Source and target points of the skin warp (landmarks, then arc middles) and their λ."""
    src_pts = [p]
    dst_pts = [q]
    arc_rows = []
    if arcs:
        assert skin_index is not None
        ends = np.array([(index[t.a], index[t.b]) for t in arcs])
        mids, normals = arc_middles(head.skin, skin_index, p[ends[:, 0]], p[ends[:, 1]])
    for k, t in enumerate(arcs):
        ia, ib = index[t.a], index[t.b]
        mid, normal = mids[k], normals[k]
        chord_c = float(np.linalg.norm(p[ia] - p[ib]))
        h_c = max(0.0, float((mid - (p[ia] + p[ib]) / 2) @ normal))
        arc_c = arc_length(chord_c, h_c)
        arc_t = scale * arc_c * (1.0 + arc_increase)
        chord_t = float(np.linalg.norm(q[ia] - q[ib]))
        h_t = arc_sagitta(chord_t, arc_t)
        # the middle moves with the solved chord's middle, then to the target sagitta
        new_mid = mid + ((q[ia] + q[ib]) - (p[ia] + p[ib])) / 2 + (h_t - h_c) * normal
        src_pts.append(mid[None])
        dst_pts.append(new_mid[None])
        arc_rows.append((t, arc_c, arc_t))
    src = np.vstack(src_pts)
    dst = np.vstack(dst_pts)
    # the warp meets the targets of hard constraints (and the arc middles) exactly and
    # follows the other landmarks, whose places are the solve's compromise, loosely
    exact = np.zeros(len(src), bool)
    exact[[c.a for c in hard] + [c.b for c in hard]] = True
    exact[len(p) :] = True
    lam = np.where(exact, 0.0, LOOSE_SMOOTHING)
    return src, dst, lam, arc_rows


def deform(head: TemplateHead, warp: Any, eye_scale: float = 1.0) -> TemplateHead:
    """``head`` (Frankfort frame, mm) moved by the skin ``warp``, settled in its new frame.

    Every part follows the warp (the eyeballs rigidly with their centres);
    triangles it turned over are relaxed; the inner parts are warped again so
    that each skull landmark lies at its source tissue depth below its skin
    partner; the eyeballs are then scaled about their centres by
    ``eye_scale`` (their own growth, :mod:`workbench.services.age.eyes`) and
    moved along their gaze to sit in the lids as on the source; last the head
    is moved into the Frankfort frame of its skull landmarks.
    """
    from workbench.io.catalogue import load_catalogue
    from workbench.services.landmarks.frame import head_frame_from_landmarks
    from workbench.services.registration.skull_registration import head_transformed

    warped = head.warped(warp)
    # triangles the warp turned over, relaxed (the reference's own sub-0.01 mm² slivers at
    # the mouth corners turn over at the slightest push and are left to themselves)
    sliver = head.skin.face_areas < SLIVER_MM2
    skin = unfold(warped.skin, head.skin.face_normals, keep=sliver)
    warped = replace(warped, meshes={**warped.meshes, "skin": skin})
    # the source tissue depths restored below the new skin landmarks
    catalogue = load_catalogue()
    skin_old = head.skin_landmarks.as_dict()
    skin_new = warped.skin_landmarks.as_dict()
    skull_old = head.skull_landmarks.as_dict()
    skull_new = warped.skull_landmarks.as_dict()
    src_in, dst_in = [], []
    for code, old in skull_old.items():
        partner = catalogue.partner(code, "skull")
        if not partner or partner not in skin_old or partner not in skin_new:
            continue
        depth = float(np.linalg.norm(skin_old[partner] - old))
        offset = skin_new[partner] - skull_new[code]
        length = float(np.linalg.norm(offset))
        if length < 1e-6:
            continue
        src_in.append(skull_new[code])
        dst_in.append(skin_new[partner] - offset / length * depth)
    if len(src_in) >= 4:
        inner = fit_warp(np.array(src_in), np.array(dst_in), smoothing=INNER_SMOOTHING)
        moved = replace(warped, meshes={**warped.meshes}).warped(inner)
        meshes = dict(warped.meshes)
        for part in INNER_PARTS:
            meshes[part] = moved.meshes[part]
        warped = replace(
            warped,
            meshes=meshes,
            skull_landmarks=moved.skull_landmarks,
            eye_centres=moved.eye_centres,
            tmj_axis=moved.tmj_axis,
        )
    warped = seat_eyes(head, scale_eyes(warped, head.eye_radius * float(eye_scale)))
    try:
        settle = head_frame_from_landmarks(warped.skull_landmarks).input_to_head
    except WorkbenchError:
        settle = np.eye(4)
    return head_transformed(warped, settle)
