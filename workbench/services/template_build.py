"""Adapt the built-in reference head to one person's skin and skull surfaces (a template pack).

Kähler (2003, §8.4.1) fits the reference head to a scan by a landmark warp,
refines the correspondences automatically, warps again, and lets skull and
muscles follow.  We do this for a person whose skin *and* skull are known
(e.g. the two iso-surfaces of one CT):

1. **Landmarks.**  The reference skull landmarks are suggested on the
   target bone, the skin landmarks on the target skin
   (:func:`~workbench.services.landmark_transfer.transfer_landmarks`; the
   skin reuses the skull's coarse alignment, same scanner frame).  Landmarks
   from the user are kept as seeds.  Points with no surface under them (a
   cut vault, a hole) are *absent*.
2. **Frame.**  The target's own Frankfort head frame comes from its skull
   landmarks (:func:`~workbench.services.reconstruct.input_frame`; a
   mirrored scan gets a reflection).  The pack lives in that frame, in mm,
   at the person's size: nothing is scaled to the template.
3. **Warp.**  One regularised landmark warp (φ(r) = r, §8.3.1, λ =
   :data:`SMOOTHING_MM`) from every skull and skin landmark pair plus the
   dense surface matches of both transfers moves the whole head: skin,
   cranium, mandible, teeth, tongue, the eyes rigidly with their centres,
   landmarks and jaw axis.  Muscles ride on the skin (barycentric grids).
4. **Projection** (§8.4.3, conservatively).  Warped skin vertices are cast
   along their normals, both ways, onto the target skin; cranium and
   mandible vertices onto the target bone.  A hit counts only within
   :data:`MAX_PROJECTION_MM`, with agreeing normals (cos ≥
   :data:`MIN_NORMAL_DOT`), off the rim of holes and of the field of view,
   within :data:`OUTLIER_MM` of a smooth field (a regularised warp fitted to
   a spread subset of the hits), and only if it neither folds, squashes nor
   creases a triangle.  Vertices without a hit (holes, beyond the scan, the
   simplified ears) get a membrane (harmonic) fill of their neighbours'
   offsets, so nothing jumps; teeth, tongue, eyes and jaw axis follow the
   smooth bone field.  Skin closer than :data:`MIN_TISSUE_MM` to the new
   skull is pushed out.
5. **Landmarks of the pack** are the reference landmarks carried on their
   surfaces (same triangle, same barycentric weights) onto the new skin and
   bone; the frame is then settled on the pack's own porions and orbitales.
   Landmarks absent on the target ride on the unprojected surface and are
   listed in the provenance with every landmark's residual.

Units mm; head frame of the *target* (x to the subject's left, x = 0
midsagittal, y up, z toward the face, Frankfort Horizontal at y = 0, origin
between the porions).  ``provenance["input_to_head"]`` maps the input files'
coordinates into it.
"""

from __future__ import annotations

import hashlib
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from os import PathLike
from pathlib import Path

import numpy as np
from scipy import sparse
from scipy.sparse.linalg import spsolve

from workbench.core.errors import InputError
from workbench.core.frame import apply_transform
from workbench.core.landmarks import Landmark, LandmarkSet
from workbench.core.mesh import Mesh, concatenate
from workbench.core.normals import vertex_normals
from workbench.core.raycast import RayCaster
from workbench.core.spatial import MeshIndex
from workbench.core.tps import LandmarkWarp, fit_warp
from workbench.model.evidence import sha256_file
from workbench.model.template import TemplateHead
from workbench.services.alignment import Alignment, align_to_reference
from workbench.services.landmark_transfer import TransferResult, rim_faces, transfer_landmarks
from workbench.services.reconstruct import input_frame, outward, warp_head
from workbench.services.reference_parts import skull_surface

SMOOTHING_MM = 1.5          #: λ of the landmark warp: wrong matches must not crumple the mesh
FIELD_SMOOTHING_MM = 2.0    #: λ of the smooth projection field
FIELD_SPACING_MM = 5.0      #: one field sample per cube of this size
MAX_PROJECTION_MM = 6.0     #: farthest accepted hit along a normal
MIN_NORMAL_DOT = 0.6        #: vertex normal · hit-surface normal
OUTLIER_MM = 2.5            #: a hit this far from the smooth field is an outlier
MAX_FOLD_DEG = 45.0         #: a projected triangle turns at most this much ...
MAX_CREASE_DEG = 30.0       #: ... bends at most this much more against a neighbour ...
MAX_AREA_RATIO = 4.0        #: ... and changes its area at most by this factor
SMOOTHING_PASSES = 2        #: umbrella passes over the offsets (CT stair steps are finer)
FIELD_PULL = 1e-3           #: weak pull of the membrane fill toward the smooth field
MIN_TISSUE_MM = 1.0         #: skin kept at least this far outside the skull
#: skin not projected (the simplified ears do not match a real one) / not pushed off the bone
UNPROJECTED_REGIONS = ("ear_l", "ear_r")
NO_CLEARANCE_REGIONS = ("neck",)
BONE_PARTS = ("cranium", "mandible")
SKULL_PARTS = ("cranium", "mandible", "upper_teeth", "lower_teeth")

Progress = Callable[[str], None]


@dataclass(frozen=True)
class BuildResult:
    """A reference head adapted to one person.

    Attributes
    ----------
    head : TemplateHead
        In the target's head frame, mm.
    input_to_head : (4, 4)
        Input-file coordinates → head frame (a reflection when ``mirrored_input``).
    skull_transfer, skin_transfer : TransferResult
        The landmark suggestions (input frame).
    figures : dict
        Warp residuals, projected fractions, distances (mm), seconds.
    """

    head: TemplateHead
    input_to_head: np.ndarray
    mirrored_input: bool
    skull_transfer: TransferResult
    skin_transfer: TransferResult
    figures: dict
    warnings: tuple[str, ...] = ()

    def to_input(self, points: np.ndarray) -> np.ndarray:
        """Head-frame points back in the input files' coordinates."""
        return _apply(np.linalg.inv(self.input_to_head), points)


def _apply(m: np.ndarray, p: np.ndarray) -> np.ndarray:
    return apply_transform(m, np.reshape(p, (-1, 3)))


def _adjacency(mesh: Mesh) -> sparse.csr_matrix:
    e, n = mesh.edges_unique, mesh.n_vertices
    a = sparse.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    return (a + a.T).tocsr()


def _mask(n: int, groups: Sequence) -> np.ndarray:
    m = np.zeros(n, dtype=bool)
    for ids in groups:
        m[np.asarray(ids, dtype=np.int64)] = True
    return m


# ------------------------------------------------------------------ 1-3: landmarks and warp
def _coarse(skull: Mesh, reference: Mesh, reference_landmarks: LandmarkSet,
            seeds: LandmarkSet | None, orientation: tuple | None) -> Alignment | None:
    """Coarse skull alignment (``None``: let the transfer search).

    An orientation hint wins (it also tells a mirrored scan).  Seeds alone
    give a similarity, which cannot match a mirrored scan (a CT in a
    left-handed space), so the reflected scan is tried too, the closer kept.
    """
    if orientation is not None:
        return align_to_reference(skull, reference, orientation=orientation)
    own, ref = ({} if seeds is None else seeds.as_dict()), reference_landmarks.as_dict()
    common = [c for c in own if c in ref]
    if len(common) < 3:
        return None
    pts, ref_pts = np.array([own[c] for c in common]), np.array([ref[c] for c in common])
    fits = []
    for flip in (np.eye(4), np.diag([-1.0, 1.0, 1.0, 1.0])):
        a = align_to_reference(Mesh(_apply(flip, skull.vertices), skull.faces), reference,
                               seeds=(_apply(flip, pts), ref_pts))
        fits.append(replace(a, matrix=a.matrix @ flip,
                            method=a.method if flip[0, 0] > 0 else f"{a.method} (mirrored)"))
    return min(fits, key=lambda a: a.rms_mm)


def _correspondences(base: TemplateHead, trs: Sequence[TransferResult],
                     to_head: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Reference → target (head frame): landmark pairs, then dense matches."""
    src, dst = [], []
    for ref, tr in zip((base.skull_landmarks, base.skin_landmarks), trs, strict=True):
        ref_d, tgt = ref.as_dict(), tr.landmarks.as_dict()
        codes = [c for c in ref_d if c in tgt]
        src += [ref_d[c] for c in codes]
        dst += list(_apply(to_head, np.array([tgt[c] for c in codes]))) if codes else []
    for tr in trs:
        s, matched = tr.correspondences
        if len(s):
            src += list(s)
            dst += list(_apply(to_head, tr.alignment.inverse(matched)))
    src_a, keep = np.unique(np.round(np.array(src).reshape(-1, 3), 6), axis=0, return_index=True)
    return src_a, np.array(dst).reshape(-1, 3)[keep]


# ------------------------------------------------------------------ 4: projection
@dataclass(frozen=True)
class _Projection:
    accepted: np.ndarray       # (n,) bool
    hits: np.ndarray           # (n, 3) hit points (NaN where none)
    field: LandmarkWarp | None


def _project(mesh: Mesh, target: Mesh, allowed: np.ndarray) -> _Projection:
    """Nearest acceptable hit along ± each vertex normal, and the smooth field of the hits."""
    caster, rim, tn = RayCaster(target), rim_faces(target), target.face_normals
    points, normals = mesh.vertices, vertex_normals(mesh)
    best, hits = np.full(len(points), np.inf), np.full_like(points, np.nan)
    for sign in (1.0, -1.0):
        h = caster.first_hits(points, sign * normals, max_distance=MAX_PROJECTION_MM)
        face = np.where(h.hit, h.face_ids, 0)
        ok = (h.hit & (np.einsum("ij,ij->i", tn[face], normals) >= MIN_NORMAL_DOT)
              & ~rim[face] & (h.distance < best))
        best[ok], hits[ok] = h.distance[ok], h.points[ok]
    accepted = np.isfinite(best) & allowed
    field = None
    for _ in range(2):  # fit the field, drop hits it disagrees with, fit again
        ids = np.flatnonzero(accepted)
        if len(ids) < 12:
            return _Projection(np.zeros_like(accepted), hits, None)
        _, first = np.unique(np.floor(points[ids] / FIELD_SPACING_MM).astype(np.int64), axis=0,
                             return_index=True)
        pick = ids[np.sort(first)]
        field = fit_warp(points[pick], hits[pick], smoothing=FIELD_SMOOTHING_MM)
        accepted[ids[np.linalg.norm(field(points[ids]) - hits[ids], axis=1) > OUTLIER_MM]] = False
    return _Projection(accepted, hits, field)


def _harmonic(adj: sparse.csr_matrix, accepted: np.ndarray, known: np.ndarray,
              fallback: np.ndarray) -> np.ndarray:
    """Offsets: ``known`` on accepted vertices, a membrane fill (uniform Laplacian) elsewhere.

    The fill never exceeds the offsets around it; a weak pull toward
    ``fallback`` (the smooth field) decides pieces without any hit.
    """
    out = np.where(accepted[:, None], known, 0.0)
    free = np.flatnonzero(~accepted)
    if len(free):
        deg = np.asarray(adj.sum(axis=1)).ravel()
        system = (sparse.diags(deg[free] + FIELD_PULL) - adj[free][:, free]).tocsc()
        rhs = adj[free][:, np.flatnonzero(accepted)] @ known[accepted] + FIELD_PULL * fallback[free]
        out[free] = spsolve(system, rhs).reshape(-1, 3)
    return out


def _bend(normals: np.ndarray, pairs: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    dot = np.einsum("ij,ij->i", normals[pairs[0]], normals[pairs[1]])
    return np.degrees(np.arccos(np.clip(dot, -1.0, 1.0)))


def _settle(mesh: Mesh, proj: _Projection) -> tuple[np.ndarray, np.ndarray]:
    """New vertices (hits, membrane fill between them) and the hits finally kept.

    A hit that folds, squashes or creases a triangle against the warped mesh
    (:data:`MAX_FOLD_DEG`, :data:`MAX_AREA_RATIO`, :data:`MAX_CREASE_DEG`)
    is dropped with the other corners of that triangle and the fill redone.
    """
    v = mesh.vertices
    fallback = (v if proj.field is None else proj.field(v)) - v
    known = np.where(proj.accepted[:, None], proj.hits - v, 0.0)
    accepted = proj.accepted.copy()
    adj = _adjacency(mesh)
    deg = np.maximum(np.asarray(adj.sum(axis=1)).ravel(), 1.0)[:, None]
    edges = np.sort(mesh.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    owner = np.repeat(np.arange(mesh.n_faces), 3)
    order = np.lexsort((edges[:, 1], edges[:, 0]))
    edges, owner = edges[order], owner[order]
    same = (edges[1:] == edges[:-1]).all(axis=1)
    pairs = (owner[:-1][same], owner[1:][same])          # triangles sharing an edge
    bend0, normals0 = _bend(mesh.face_normals, pairs), mesh.face_normals
    area0 = np.maximum(mesh.face_areas, 1e-12)
    for _ in range(8):
        offset = _harmonic(adj, accepted, known, fallback)
        for _ in range(SMOOTHING_PASSES):
            offset = 0.5 * offset + 0.5 * (adj @ offset) / deg
        moved = mesh.with_vertices(v + offset)
        ratio = moved.face_areas / area0
        turn = np.einsum("ij,ij->i", moved.face_normals, normals0)
        bad = ((turn < np.cos(np.radians(MAX_FOLD_DEG))) | (ratio < 1 / MAX_AREA_RATIO)
               | (ratio > MAX_AREA_RATIO))
        crease = _bend(moved.face_normals, pairs) > bend0 + MAX_CREASE_DEG
        bad[pairs[0][crease]] = bad[pairs[1][crease]] = True
        drop = _mask(len(v), [mesh.faces[bad].ravel()]) & accepted
        if not drop.any():
            break
        accepted &= ~drop
    return v + offset, accepted


def _push_out(skin: np.ndarray, skull: Mesh, exclude: np.ndarray) -> tuple[np.ndarray, int, float]:
    """Skin vertices closer than :data:`MIN_TISSUE_MM` to ``skull`` moved out to it."""
    index = MeshIndex(skull)
    v = skin.copy()
    cp = index.closest_points(v)
    signed = index.signed_distance(v)
    thin = (signed < MIN_TISSUE_MM) & ~exclude & (cp.distances < 30.0)
    if thin.any():
        normals = index.pseudo_normals(cp.face_ids[thin], cp.barycentric[thin])
        out = v[thin] - cp.points[thin]
        out /= np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-9)
        out = np.where(signed[thin, None] > 0.05, out, normals)
        v[thin] = cp.points[thin] + MIN_TISSUE_MM * out
    return v, int(thin.sum()), float(signed[~exclude].min())


def _projected(base: TemplateHead, warped: TemplateHead, skin_h: Mesh, bone_h: Mesh
               ) -> tuple[TemplateHead, dict]:
    """The warped head projected onto the target skin and bone (head frame)."""
    n_skin = base.skin.n_vertices
    skin_proj = _project(warped.skin, skin_h,
                         ~_mask(n_skin, [base.regions[r] for r in UNPROJECTED_REGIONS
                                         if r in base.regions]))
    bone_w = concatenate([warped.meshes[p] for p in BONE_PARTS])
    bone_proj = _project(bone_w, bone_h, np.ones(bone_w.n_vertices, dtype=bool))
    new_skin, skin_ok = _settle(warped.skin, skin_proj)
    new_bone, bone_ok = _settle(bone_w, bone_proj)
    field = bone_proj.field or (lambda p: np.asarray(p, float))
    meshes = dict(warped.meshes)
    ends = np.cumsum([warped.meshes[p].n_vertices for p in BONE_PARTS])
    for p, chunk in zip(BONE_PARTS, np.split(new_bone, ends[:-1]), strict=True):
        meshes[p] = warped.meshes[p].with_vertices(chunk)
    for p in ("upper_teeth", "lower_teeth", "tongue"):
        meshes[p] = warped.meshes[p].with_vertices(field(warped.meshes[p].vertices))
    centres = field(warped.eye_centres)   # globes are rigid: they move with their centres
    eyes = warped.meshes["eyes"].vertices
    owner = np.linalg.norm(eyes[:, None] - warped.eye_centres[None], axis=2).argmin(axis=1)
    meshes["eyes"] = warped.meshes["eyes"].with_vertices(
        eyes + (centres - warped.eye_centres)[owner])
    axis = field(np.vstack([warped.tmj_axis[0], warped.tmj_axis[0] + 10 * warped.tmj_axis[1]]))
    keep = [base.regions[r] for r in NO_CLEARANCE_REGIONS if r in base.regions]
    skin_v, pushed, min_tissue = _push_out(new_skin, concatenate([meshes[p] for p in SKULL_PARTS]),
                                           _mask(n_skin, keep + list(base.openings.values())))
    meshes["skin"] = warped.skin.with_vertices(skin_v)
    direction = (axis[1] - axis[0]) / np.linalg.norm(axis[1] - axis[0])
    head = replace(warped, meshes=meshes, eye_centres=centres,
                   tmj_axis=np.vstack([axis[0], direction]))
    face = np.asarray(base.regions.get("face", np.arange(n_skin)), dtype=np.int64)
    cp = MeshIndex(skin_h).closest_points(skin_v[face])
    near = (cp.distances < 10.0) & ~rim_faces(skin_h)[cp.face_ids]
    figures = {
        "skin_projected_fraction": float(skin_ok.mean()),
        "bone_projected_fraction": float(bone_ok.mean()),
        "face_projected_fraction": float(skin_ok[face].mean()),
        "face_vertices_near_target": int(near.sum()),
        "face_within_1_5mm_fraction": float((cp.distances[near] <= 1.5).mean())
        if near.any() else 0.0,
        "face_median_distance_mm": float(np.median(cp.distances[near])) if near.any() else None,
        "pushed_out_vertices": pushed,
        "min_tissue_before_push_mm": min_tissue,
    }
    return head, figures


# ------------------------------------------------------------------ 5: landmarks and frame
def _carry(lms: LandmarkSet, warped_lms: LandmarkSet, base: Mapping[str, Mesh],
           warped: Mapping[str, Mesh], after: Mapping[str, Mesh],
           parts_of: Callable[[str], Sequence[str]], absent: Sequence[str]) -> LandmarkSet:
    """Reference landmarks moved with their surface (same triangle and barycentric weights).

    A landmark off its surface on the reference keeps its offset from the
    warped surface.
    """
    defined = [lm for lm in lms if lm.is_defined]
    moved_to = warped_lms.as_dict()
    best: dict[str, tuple[float, np.ndarray]] = {}
    for part in sorted({p for lm in defined for p in parts_of(lm.code)}):
        mine = [lm for lm in defined if part in parts_of(lm.code)]
        cp = MeshIndex(base[part]).closest_points(np.array([lm.position for lm in mine]))

        def at(mesh: Mesh, cp=cp) -> np.ndarray:  # noqa: ANN001
            return np.einsum("ij,ijk->ik", cp.barycentric, mesh.vertices[mesh.faces[cp.face_ids]])

        off = np.array([moved_to[lm.code] for lm in mine]) - at(warped[part])
        off[cp.distances < 1e-6] = 0.0
        for lm, d, p in zip(mine, cp.distances, at(after[part]) + off, strict=True):
            if lm.code not in best or d < best[lm.code][0]:
                best[lm.code] = (float(d), p)
    note = "absent on the target surface: position carried by the warp, not measured"
    return LandmarkSet(lms.surface, tuple(
        Landmark(lm.code, best[lm.code][1], lm.status, lm.confidence,
                 note if lm.code in absent else lm.description) if lm.is_defined else lm
        for lm in lms))


def _moved(head: TemplateHead, m: np.ndarray) -> TemplateHead:
    """``head`` under the rigid motion ``m`` (4x4, no reflection)."""
    point, ahead = _apply(m, np.vstack([head.tmj_axis[0], head.tmj_axis[0] + head.tmj_axis[1]]))
    return replace(
        head, meshes={p: x.with_vertices(_apply(m, x.vertices)) for p, x in head.meshes.items()},
        skin_landmarks=head.skin_landmarks.transformed(m),
        skull_landmarks=head.skull_landmarks.transformed(m),
        eye_centres=_apply(m, head.eye_centres), tmj_axis=np.vstack([point, ahead - point]))


def _residuals(carried: LandmarkSet, tr: TransferResult, to_head: np.ndarray) -> dict[str, float]:
    found = tr.landmarks.as_dict()
    codes = [c for c in carried.codes if c in found]
    if not codes:
        return {}
    target = _apply(to_head, [found[c] for c in codes])
    d = np.linalg.norm(carried.positions_of(codes) - target, axis=1)
    return {c: round(float(x), 2) for c, x in zip(codes, d, strict=True)}


# ------------------------------------------------------------------ entry points
def build_template(skin: Mesh, skull: Mesh, base: TemplateHead, *,
                   skin_seeds: LandmarkSet | None = None, skull_seeds: LandmarkSet | None = None,
                   orientation: tuple | None = None, inputs: Sequence[Mapping] = (),
                   progress: Progress | None = None) -> BuildResult:
    """Adapt ``base`` (head frame) to ``skin`` and ``skull`` (one input frame, mm).

    ``skin``/``skull`` may have holes and a cut field of view;
    ``skin_seeds``/``skull_seeds`` are landmarks placed by hand (input frame,
    kept as given); ``orientation`` = (anterior, superior[, left]) in the
    input frame; ``inputs`` = ``{"role", "file", "sha256"}`` per input file
    (recorded in the provenance, hashed into the template id).
    """
    say = progress or (lambda _m: None)
    t0 = time.perf_counter()
    seconds: dict[str, float] = {}
    say("suggesting skull landmarks on the bone ...")
    ref_skull = skull_surface(base)
    skull_tr = transfer_landmarks(skull, ref_skull, base.skull_landmarks, seeds=skull_seeds,
                                  orientation=orientation,
                                  alignment=_coarse(skull, ref_skull, base.skull_landmarks,
                                                    skull_seeds, orientation))
    say("suggesting skin landmarks on the skin ...")
    skin_tr = transfer_landmarks(skin, base.skin, base.skin_landmarks, seeds=skin_seeds,
                                 alignment=skull_tr.alignment)
    warnings = [f"{s}: {w}" for s, tr in (("skull", skull_tr), ("skin", skin_tr))
                for w in tr.warnings]
    if skin_tr.matches < 50:
        warnings.append(f"only {skin_tr.matches} skin surface matches: is the skin in the same "
                        "frame and units as the skull?")
    to_head, mirrored = input_frame(skull_tr.landmarks)
    if mirrored:
        warnings.append("the input is mirrored (left-handed coordinates): the head frame "
                        "includes a reflection")
    seconds["landmarks"] = time.perf_counter() - t0

    t = time.perf_counter()
    say("warping the reference head ...")
    src, dst = _correspondences(base, (skull_tr, skin_tr), to_head)
    if len(src) < 12:
        raise InputError("template build", f"only {len(src)} correspondences between the "
                         "reference and the target surfaces",
                         hint="check the units and orientation, or give landmark files")
    warp = fit_warp(src, dst, smoothing=SMOOTHING_MM)
    resid = warp.residuals(src, dst)
    warped = warp_head(base, warp)
    seconds["warp"] = time.perf_counter() - t

    t = time.perf_counter()
    say("projecting onto the target surfaces ...")
    head, figures = _projected(base, warped, outward(skin.transformed(to_head)),
                               outward(skull.transformed(to_head)))
    absent = {"skull": list(skull_tr.absent), "skin": list(skin_tr.absent)}
    teeth = ("upper_teeth", "lower_teeth")
    skull_lms = _carry(base.skull_landmarks, warped.skull_landmarks, base.meshes, warped.meshes,
                       head.meshes, lambda c: teeth if base.skull_landmark_part.get(c) == "teeth"
                       else (base.skull_landmark_part.get(c, "cranium"),), absent["skull"])
    skin_lms = _carry(base.skin_landmarks, warped.skin_landmarks, base.meshes, warped.meshes,
                      head.meshes, lambda _c: ("skin",), absent["skin"])
    head = replace(head, skin_landmarks=skin_lms, skull_landmarks=skull_lms)
    # settle the frame on the pack's own porions and orbitales (they moved with the bone)
    settle, flipped = input_frame(head.skull_landmarks)
    if not flipped:
        head, to_head = _moved(head, settle), settle @ to_head
    seconds["project"] = time.perf_counter() - t

    residuals = {s: _residuals(getattr(head, f"{s}_landmarks"), tr, to_head)
                 for s, tr in (("skull", skull_tr), ("skin", skin_tr))}
    figures |= {"correspondences": len(src),
                "warp_rms_residual_mm": float(np.sqrt(np.mean(resid ** 2))),
                "warp_max_residual_mm": float(resid.max())}
    for s, r in residuals.items():
        figures[f"{s}_landmark_median_residual_mm"] = (float(np.median(list(r.values())))
                                                       if r else None)
    seconds["total"] = time.perf_counter() - t0
    figures["seconds"] = {k: round(v, 2) for k, v in seconds.items()}
    digest = hashlib.sha256("".join(str(i.get("sha256", "")) for i in inputs).encode()
                            + base.content_hash.encode()).hexdigest()[:12]
    a = skull_tr.alignment
    provenance = {
        "built_from": [dict(i) for i in inputs],
        "base_template": {"template_id": base.template_id, "content_hash": base.content_hash},
        "method": "Kähler 2003 §8.4.1: landmark warp from suggested skull and skin landmarks and "
                  "dense surface matches, projection along normals onto the target skin and bone "
                  "(§8.4.3), membrane fill where nothing was hit",
        "frame": "the target's head frame (Frankfort Horizontal from its skull landmarks), mm",
        "input_to_head": to_head, "mirrored_input": bool(mirrored),
        "alignment": {"method": a.method, "rms_mm": a.rms_mm, "overlap": a.overlap,
                      "scale": a.scale},
        "transfer": {s: {"matches": tr.matches, "residual_mm": tr.warp_residual_mm}
                     for s, tr in (("skull", skull_tr), ("skin", skin_tr))},
        "absent_landmarks": absent,
        "landmark_residuals_mm": residuals,
        "settings": {"smoothing_mm": SMOOTHING_MM, "field_smoothing_mm": FIELD_SMOOTHING_MM,
                     "max_projection_mm": MAX_PROJECTION_MM, "min_normal_dot": MIN_NORMAL_DOT,
                     "outlier_mm": OUTLIER_MM, "min_tissue_mm": MIN_TISSUE_MM},
        "figures": figures, "warnings": list(warnings),
    }
    head = replace(head, template_id=f"{base.template_id}/built/{digest}", provenance=provenance)
    return BuildResult(head, to_head, bool(mirrored), skull_tr, skin_tr, figures, tuple(warnings))


def _sha256(path: Path) -> str:
    return sha256_file(path)[0]


def build_template_pack(skin_path: str | PathLike[str], skull_path: str | PathLike[str],
                        out: str | PathLike[str], *, sex: str = "male", units: str = "auto",
                        scale: float | None = None,
                        skin_landmarks: str | PathLike[str] | None = None,
                        skull_landmarks: str | PathLike[str] | None = None,
                        orientation: tuple | None = None, base: TemplateHead | None = None,
                        progress: Progress | None = None) -> tuple[BuildResult, list[Path]]:
    """Read the inputs, :func:`build_template` on ``base`` (default: the built-in
    head of ``sex``), and write the pack to ``out``.

    Meshes and landmark files share one frame and one unit (``units`` or
    ``scale`` converts both to mm).  Returns the result and the files written.
    """
    from workbench.core.units import resolve_units
    from workbench.io.catalogue import load_catalogue
    from workbench.io.markups import read_landmarks
    from workbench.io.meshes import read_mesh
    from workbench.io.template_pack import export_template
    from workbench.services.template_cache import reference_head

    meshes, factors, inputs = {}, {}, []
    for role, path, kind in (("skin", Path(skin_path), "head"),
                             ("skull", Path(skull_path), "skull")):
        read = read_mesh(path, units=units if scale is None else "auto", scale=scale, kind=kind)
        if scale is None and units == "auto":
            resolve_units(read.units, "auto", source=str(path))
        meshes[role], factors[role] = read.mesh, read.scale_applied
        inputs.append({"role": role, "file": path.name, "sha256": _sha256(path)})
    seeds: dict[str, LandmarkSet | None] = {"skin": None, "skull": None}
    for surface, path in (("skin", skin_landmarks), ("skull", skull_landmarks)):
        if path is not None:
            lms = read_landmarks(path, surface, catalogue=load_catalogue(),
                                 allow_undefined=True).landmarks
            f = factors[surface]
            seeds[surface] = lms.transformed(np.diag([f, f, f, 1.0]))
            inputs.append({"role": f"{surface}_landmarks", "file": Path(path).name,
                           "sha256": _sha256(Path(path))})
    result = build_template(meshes["skin"], meshes["skull"], base or reference_head(sex),
                            skin_seeds=seeds["skin"], skull_seeds=seeds["skull"],
                            orientation=orientation, inputs=inputs, progress=progress)
    return result, export_template(result.head, out)
