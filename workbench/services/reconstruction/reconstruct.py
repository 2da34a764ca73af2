"""Skull → face: the reference head carried onto a real skull and its soft tissue modelled.

Units mm.  The skull comes in the **input frame** (a CT's physical frame, a
scanner's frame, any axes); the work happens in the target's head frame (x
to the subject's left, x = 0 midsagittal, y up, z toward the face,
Frankfort Horizontal at y = 0) found by the registration; every result maps
back (:meth:`Reconstruction.to_input`) so the face overlays the evidence.
A mirrored input is handled by a reflection in that map.

The fit (issue 11; Kähler 2003 §8.6 made dense):

1. **Dense registration** of the reference skull onto the bone, part by
   part (:mod:`workbench.services.registration.skull_registration`): orientation from the
   bone alone (or a hint, or the user's landmarks), the mandible with its own
   pose, missing parts detected, landmarks with confidences, the Frankfort
   frame.
2. **Carry**: the whole reference head — skin, muscles, eyes, teeth,
   tongue — follows the skull's displacement field (one smooth φ(r) = r
   warp, §8.3.1, fitted densely on the registered skull).
3. **Tissue model** (:mod:`workbench.services.tissue.tissue_model`): the
   reference's own thickness calibrated to the depth table, build variants
   and region factors, nose, lips, lids and ears keeping their shape.
4. **Dowels** are planned at the registered landmarks on the target bone
   (:mod:`workbench.services.tissue.dowels`): the sparse view of the field.  By
   default each shows the model's depth along it; a user's override (or
   ``pin_dowels``) pulls the skin through its tip.
5. **Guides** (nose, mouth, lips, eyes) set the coordinates they control of
   their skin landmarks in one last warp — Kähler's "second warp" — whose
   other correspondences hold the skin where the model put it
   (``anchor``), at the dowels (``dowel:<code>``) and off the bone
   (``clearance``: no skin closer than ``min_tissue_mm`` to the *target*
   bone).  The interactive preview (:mod:`workbench.services.reconstruction.preview_fit`)
   re-solves exactly this warp.
6. **Observed / inferred**: a skin vertex over bone the registration
   observed is *observed*; over missing bone (no mandible, a defect, a cut
   vault) its shape is the reference's prior and it is *inferred*
   (:attr:`Reconstruction.observed`, 0..1 per skin vertex).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.spatial import cKDTree

from workbench.core.frame import apply_transform
from workbench.core.landmarks import LandmarkSet, merge_user_landmarks
from workbench.core.mesh import Mesh, concatenate
from workbench.core.raycast import RayCaster
from workbench.core.spatial import MeshIndex
from workbench.core.thickness import adjacency, smooth_field
from workbench.core.tps import fit_warp
from workbench.model.template import TemplateHead
from workbench.services.reconstruction.eyes import eye_moves, eye_sides, lid_vertices
from workbench.services.reconstruction.lids import lids_on_globes
from workbench.services.tissue.dowels import DepthSettings, DowelPlan, plan_dowels
from workbench.services.tissue.tissue_model import (
    TissueField,
    TissueSettings,
    apply_field,
    tissue_field,
)

if TYPE_CHECKING:
    from workbench.services.registration.skull_registration import SkullRegistration

#: warp regularisation λ (mm) of the final (guide) warp
SMOOTHING = 1.0
#: anchors of the final warp: one per cell of this size (mm) ...
ANCHOR_SPACING_MM = 9.0
#: ... and none this close to a point the warp moves (mm); the interactive preview drops
#: the anchors this close to a dragged dowel, so the skin around it follows the drag
ANCHOR_CLEARANCE_MM = 12.0
#: an anchor's hold fades in over this distance beyond the clearance (mm), and a point
#: counts fully as moving from this displacement on (mm): no anchor appears or vanishes
#: when a point crosses a threshold, so 1e-9 mm of noise on the skull cannot switch one
ANCHOR_TAPER_MM = 8.0
MOVING_MM = 0.1
#: anchors holding less than this (their regulariser λ / weight) are left out
ANCHOR_MIN_WEIGHT = 0.01
#: skin within this much of the minimum tissue also gets a clearance point once any is
#: too thin, pushed out by what it lacks of min + band (zero at the band's edge)
CLEARANCE_BAND_MM = 0.5
#: spacing of the non-penetration correspondences (mm)
CLEARANCE_SPACING_MM = 6.0
#: skin vertices farther than this from the target bone are not checked (bone missing there)
BONE_SEARCH_MM = 30.0
#: skin regions never pushed off the bone (the neck stump meets the spine)
NO_CLEARANCE_REGIONS = ("neck",)
#: a skin vertex is observed when the bone beneath it is (smoothed weight above this)
OBSERVED_LEVEL = 0.5
#: spacing of the lid correspondences that carry the lids with their eyeball (mm)
LID_SPACING_MM = 4.0


@dataclass(frozen=True)
class FitSettings:
    """What the fit uses besides the skull and the reference head."""

    depth: DepthSettings = field(default_factory=DepthSettings)
    tissue: TissueSettings = field(default_factory=TissueSettings)
    max_refits: int = 3
    #: suggested landmarks below this confidence get no dowel (placed ones always do)
    min_confidence: float = 0.3
    #: move the registration's landmarks to the features their definitions name
    snap_landmarks: bool = True
    #: "occlusion": the jaw brought into occlusion for the face
    #: (:func:`~workbench.services.registration.skull_registration.articulate`); "as-scanned": left as found
    jaw: str = "occlusion"

    @property
    def min_tissue_mm(self) -> float:
        return self.tissue.min_tissue_mm


@dataclass(frozen=True)
class Reconstruction:
    """A fitted head.

    Attributes
    ----------
    head : TemplateHead
        The reference head carried onto the skull, in the head frame (mm).
    input_to_head : (4, 4)
        Map of input coordinates into the head frame (a reflection included
        when ``mirrored_input``).
    plan : DowelPlan
        The dowels (head frame).
    sources, targets : (k, 3)
        The correspondences of the final warp (head frame).
    labels : tuple of str
        Per correspondence: ``"anchor"``, ``"dowel:<skull code>"``,
        ``"guide:<skin code>"``, ``"eye:<side>"`` (lids following their eyeball) or
        ``"clearance"``.
    base_skin : (n_skin, 3)
        The skin the final warp is applied to (carried and tissue-modelled).
    dowel_depths : dict
        Skull code → the depth its correspondence holds (mm).
    observed : (n_skin,)
        0..1 per skin vertex: how much real bone the registration found under
        it (below :data:`OBSERVED_LEVEL`: inferred from the reference).
    landmarks : LandmarkSet
        The skull landmarks used (input frame; those on the mandible where the
        scan has the jaw, also when the face was fitted with it in occlusion).
    registration : SkullRegistration or None
    tissue : TissueField or None
    smoothing : (k,) or None
        The warp regulariser λ (mm) per correspondence (anchors near moving
        points hold loosely); None = :data:`SMOOTHING` for all.
    figures, warnings, guide_targets
    """

    head: TemplateHead
    input_to_head: np.ndarray
    mirrored_input: bool
    plan: DowelPlan
    sources: np.ndarray
    targets: np.ndarray
    figures: dict
    guide_targets: Mapping[str, np.ndarray] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()
    labels: tuple[str, ...] = ()
    base_skin: np.ndarray | None = None
    dowel_depths: Mapping[str, float] = field(default_factory=dict)
    observed: np.ndarray | None = None
    landmarks: LandmarkSet | None = None
    registration: SkullRegistration | None = None
    tissue: TissueField | None = None
    smoothing: np.ndarray | None = None

    def to_input(self, points: np.ndarray) -> np.ndarray:
        return apply_transform(np.linalg.inv(self.input_to_head), points)

    def mesh_to_input(self, mesh: Mesh) -> Mesh:
        """A head-frame mesh in the input frame, outward winding kept."""
        return Mesh(
            self.to_input(mesh.vertices), mesh.faces[:, ::-1] if self.mirrored_input else mesh.faces
        )

    @property
    def face(self) -> Mesh:
        """The fitted skin in the input frame."""
        return self.mesh_to_input(self.head.skin)

    @property
    def inferred(self) -> np.ndarray:
        """``(n_skin,)`` bool: skin over missing bone, shaped by the reference alone."""
        if self.observed is None:
            return np.zeros(self.head.skin.n_vertices, bool)
        return self.observed < OBSERVED_LEVEL


def _mask(n: int, head: TemplateHead, names: tuple[str, ...]) -> np.ndarray:
    m = np.zeros(n, bool)
    for name in names:
        if name in head.regions:
            m[np.asarray(head.regions[name], dtype=np.int64)] = True
    return m


def _spread(points: np.ndarray, spacing: float) -> np.ndarray:
    """Indices of one point per occupied ``spacing`` cell (the first in index order)."""
    _, first = np.unique(np.floor(points / spacing).astype(np.int64), axis=0, return_index=True)
    return np.sort(first)


GuideFn = Callable[[dict[str, np.ndarray]], dict[str, np.ndarray]]


def _skin_observed(head_skin: Mesh, reg: SkullRegistration) -> np.ndarray:
    """0..1 per skin vertex from the observed weights of the registered bone under it.

    Cranium and mandible only: teeth rarely match a CT's (metal, roots,
    missing teeth) and are no evidence of missing *bone*.  Smoothed over the
    skin, so one weak match is no "missing bone".
    """
    parts = ("cranium", "mandible")
    bone = concatenate([reg.meshes[p] for p in parts])
    weight = np.concatenate([reg.observed[p] for p in parts])
    cp = MeshIndex(bone).closest_points(head_skin.vertices)
    w = np.einsum("ij,ij->i", cp.barycentric, weight[bone.faces[cp.face_ids]])
    # observed weights are per-vertex match strengths; a neighbourhood of them is the evidence
    w = smooth_field(adjacency(head_skin), np.clip(w / 0.6, 0.0, 1.0), 16)
    return np.clip(w, 0.0, 1.0)


def _dowel_hits(plan: DowelPlan, skin: Mesh) -> dict[str, tuple[float, np.ndarray]]:
    """Per active dowel: the skin's depth along it and the skin point there."""
    active = plan.active()
    if not active:
        return {}
    o = np.array([d.origin for d in active])
    dr = np.array([d.direction for d in active])
    hits = RayCaster(skin).first_hits(o, dr, max_distance=80.0)
    return {
        d.code: (float(hits.distance[i]), hits.points[i])
        for i, d in enumerate(active)
        if hits.hit[i]
    }


@dataclass(frozen=True, eq=False)
class HeadFit:
    """What :func:`fit_head` makes (head frame, mm).

    Attributes
    ----------
    head : the fitted head
    figures : fit figures (tip errors, thin spots, refits, eye figures, seconds)
    sources, targets : (k, 3) the final warp's correspondences
    guides : the guide targets used ({skin code: (3,)})
    labels : per correspondence (see :class:`Reconstruction`)
    base_skin : (n_skin, 3) the carried, tissue-modelled skin the warp moved
    held : {skull code: the depth its dowel correspondence holds (mm)}
    smoothing : (k,) the warp's λ per correspondence (mm)
    """

    head: TemplateHead
    figures: dict
    sources: np.ndarray
    targets: np.ndarray
    guides: dict
    labels: tuple[str, ...]
    base_skin: np.ndarray
    held: dict[str, float]
    smoothing: np.ndarray


def fit_head(
    head: TemplateHead,
    reg: SkullRegistration,
    plan: DowelPlan,
    *,
    guide_targets: Mapping[str, np.ndarray] | None = None,
    guides: GuideFn | None = None,
    settings: FitSettings = FitSettings(),
    tissue: TissueField | None = None,
    depths: np.ndarray | None = None,
    landmarks_h: LandmarkSet | None = None,
) -> HeadFit:
    """Carry ``head`` with the registration, model the tissue, warp to dowels and guides.

    ``landmarks_h`` (the skull landmarks, head frame) place the eyeballs
    (:func:`eye_moves`); the lids follow their globe in the final warp.
    """
    from workbench.services.registration.skull_registration import carry_head

    t0 = time.perf_counter()
    carried = carry_head(head, reg)
    field_ = tissue if tissue is not None else tissue_field(head, settings.depth, settings.tissue)
    base = carried.skin.with_vertices(apply_field(carried.skin, field_))
    n = base.n_vertices
    skin_codes = list(carried.skin_landmarks.as_dict())
    # skin landmarks ride on the skin: re-read them from the modelled skin (same vertex weights)
    lm_index = MeshIndex(carried.skin)
    lm_pos = carried.skin_landmarks.as_dict()
    cp = lm_index.closest_points(np.array([lm_pos[c] for c in skin_codes]))
    on_base = np.einsum("ij,ijk->ik", cp.barycentric, base.vertices[base.faces[cp.face_ids]])
    prefit = dict(zip(skin_codes, on_base, strict=True))
    used_guides = dict(guide_targets or {})
    centres = {f"eye_centre_{side}": carried.eye_centres[i] for i, side in eye_sides(carried)}
    if guides is not None:
        used_guides.update(guides({**prefit, **centres}))
    moves, eye_figures, eye_notes = eye_moves(
        carried,
        landmarks_h,
        settings.tissue.eye_rule,
        {c: used_guides.pop(c) for c in centres if c in used_guides},
    )
    carried = carried.with_eyes_moved(moves)
    hits = _dowel_hits(plan, base)
    guided_pts = np.array([prefit[c] for c in used_guides if c in prefit]).reshape(-1, 3)
    src, dst, labels, held = _dowel_correspondences(
        plan, hits, used_guides, guided_pts, settings, depths
    )
    for code, target in used_guides.items():
        if code in prefit:
            src.append(prefit[code])
            dst.append(np.asarray(target, float))
            labels.append(f"guide:{code}")
    for i, side in eye_sides(carried):
        if i in moves and np.linalg.norm(moves[i]) > 0.05:  # the lids go with their eyeball
            lids = lid_vertices(carried, i, side)
            # cells of the reference's own lid (the carried one moves with the skull: noise
            # on it must not change which vertices are picked)
            lids = lids[_spread(head.skin.vertices[lids], LID_SPACING_MM)]
            src += list(base.vertices[lids])
            dst += list(base.vertices[lids] + moves[i])
            labels += [f"eye:{side}"] * len(lids)
    anchors, hold = _anchors(head.skin.vertices, base.vertices, src, dst)
    src += list(base.vertices[anchors])
    dst += list(base.vertices[anchors])
    labels += ["anchor"] * len(anchors)
    src_a, dst_a = np.array(src), np.array(dst)
    lam = np.full(len(src_a), SMOOTHING)
    lam[len(src_a) - len(anchors) :] = SMOOTHING / hold

    # no skin inside (or too close to) the target bone: clearance correspondences
    exempt = _mask(n, head, NO_CLEARANCE_REGIONS)
    for loop in head.openings.values():
        exempt[np.asarray(loop, dtype=np.int64)] = True
    cl = _clearance_refits(base, reg, settings, exempt, src_a, dst_a, lam, labels)
    src_a, dst_a, lam, warp, signed, checked = (
        cl.src,
        cl.dst,
        cl.lam,
        cl.warp,
        cl.signed,
        cl.checked,
    )
    rested, lid_figures = lids_on_globes(cl.moved, carried.meshes.get("eyes"))
    meshes = {
        **carried.meshes,
        "skin": base.with_vertices(rested),
        "cranium": reg.meshes["cranium"],
    }
    if reg.part("mandible").present:
        meshes["mandible"] = reg.meshes["mandible"]
    on_skin = LandmarkSet(
        "skin",
        tuple(
            lm.moved(prefit[lm.code], lm.status) if lm.code in prefit else lm
            for lm in carried.skin_landmarks
        ),
    )
    fitted = replace(carried, meshes=meshes, skin_landmarks=on_skin.warped(warp))
    tip_err = [
        float(np.linalg.norm(warp(s[None])[0] - t))
        for s, t, lab in zip(src_a, dst_a, labels, strict=False)
        if lab.startswith("dowel:")
    ]
    figures = {
        "max_tip_error_mm": max(tip_err) if tip_err else 0.0,
        "min_tissue_mm": float(signed[checked].min()) if checked.any() else None,
        "penetrating_vertices": int(((signed < 0) & checked).sum()),
        "thin_vertices": int(((signed < settings.min_tissue_mm) & checked).sum()),
        "refits": int(cl.refits),
        "clamped_vertices": int(cl.clamped),
        "extra_correspondences": int(cl.extra),
        "correspondences": len(src_a),
        **eye_figures,
        **lid_figures,
        "eye_notes": eye_notes,
        "seconds": round(time.perf_counter() - t0, 3),
    }
    return HeadFit(
        fitted, figures, src_a, dst_a, used_guides, tuple(labels), base.vertices, held, lam
    )


def _dowel_correspondences(
    plan: DowelPlan,
    hits: Mapping[str, tuple[float, np.ndarray]],
    used_guides: Mapping[str, np.ndarray],
    guided_pts: np.ndarray,
    settings: FitSettings,
    depths: np.ndarray | None,
) -> tuple[list[np.ndarray], list[np.ndarray], list[str], dict[str, float]]:
    """Skin points (where each dowel meets the modelled skin, ``hits``) and their targets
    at the dowel tips (head frame, mm), their labels and each dowel's held depth (mm).

    A dowel is pinned at its table (or given ``depths``) depth when the
    settings pin dowels or it was overridden; otherwise it holds the modelled
    depth.  Dowels whose skin landmark a guide decides, and held dowels
    within :data:`ANCHOR_CLEARANCE_MM` of a guided point (``guided_pts``), are
    left out; two dowels meeting the skin at one point send it to the middle
    of both tips.
    """
    src: list[np.ndarray] = []
    dst: list[np.ndarray] = []
    labels: list[str] = []
    held: dict[str, float] = {}
    for i, d in enumerate(plan.dowels):
        if d.excluded or d.code not in hits:
            continue
        depth_now, point = hits[d.code]
        pinned = settings.tissue.pin_dowels or d.source == "override" or depths is not None
        if d.skin_code in used_guides and not d.source == "override":
            continue  # a guide decides that skin landmark
        if (
            not pinned
            and len(guided_pts)
            and np.min(np.linalg.norm(guided_pts - point, axis=1)) < ANCHOR_CLEARANCE_MM
        ):
            continue  # a held dowel beside a guided point would fight the guide
        depth = (float(depths[i]) if depths is not None else d.depth_mm) if pinned else depth_now
        target = d.origin + depth * d.direction
        same = next((k for k, q in enumerate(src) if np.array_equal(q, point)), None)
        if same is not None:
            # two dowels meeting the skin at one point (ss and mp under a flat lip): one
            # skin point cannot go to two places, it goes to the middle of both tips
            dst[same] = 0.5 * (dst[same] + target)
            held[d.code] = depth
            continue
        src.append(point)
        dst.append(target)
        labels.append(f"dowel:{d.code}")
        held[d.code] = depth
    return src, dst, labels, held


#: passes of the last resort that moves skin left inside the bone out to the minimum tissue
CLAMP_PASSES = 10


@dataclass(frozen=True)
class _Clearance:
    """The skin warp after the clearance refits (head frame, mm) and what they found."""

    src: np.ndarray  # correspondence sources, clearance points appended
    dst: np.ndarray  # their targets
    lam: np.ndarray  # per correspondence smoothing
    warp: Any  # the final warp
    moved: np.ndarray  # the modelled skin's vertices moved by it
    signed: np.ndarray  # per skin vertex: signed tissue depth over the target bone (mm)
    checked: np.ndarray  # skin vertices the depth check applies to
    refits: int
    extra: int  # clearance correspondences added
    #: skin vertices still inside the bone after the refits, moved out to the minimum tissue
    clamped: int = 0


def _clearance_refits(
    base: Mesh,
    reg: SkullRegistration,
    settings: FitSettings,
    exempt: np.ndarray,
    src_a: np.ndarray,
    dst_a: np.ndarray,
    lam: np.ndarray,
    labels: list[str],
) -> _Clearance:
    """Fit the skin warp and refit, up to ``settings.max_refits`` times, while skin lies
    inside or closer than ``settings.min_tissue_mm`` to the target bone.

    Each refit adds clearance correspondences (labelled in ``labels``): the
    too-thin skin vertices of ``base`` (``exempt`` excepted), spread
    :data:`CLEARANCE_SPACING_MM` apart, held
    ``min_tissue_mm + CLEARANCE_BAND_MM`` out along the bone's normal.
    """
    index = MeshIndex(reg.target_h)
    t_weight = reg.target_weight
    refits = 0
    extra = 0
    for refits in range(settings.max_refits + 1):
        warp = fit_warp(src_a, dst_a, smoothing=lam)
        moved = warp(base.vertices)
        thin, signed, bone_pt, normal, checked = _thin_spots(
            moved, index, t_weight, settings.min_tissue_mm, exempt
        )
        if not thin.any() or refits == settings.max_refits:
            break
        band = checked & (signed < settings.min_tissue_mm + CLEARANCE_BAND_MM)
        ids = np.flatnonzero(band)
        ids = ids[np.argsort(signed[ids])]
        pick = ids[_spread(moved[ids], CLEARANCE_SPACING_MM)]
        goal = bone_pt[pick] + (settings.min_tissue_mm + CLEARANCE_BAND_MM) * normal[pick]
        # a clearance point lands where the skin is: hold its base vertex to the goal
        keep = cKDTree(src_a).query(base.vertices[pick])[0] > 1.5
        if not keep.any():
            break
        src_a = np.vstack([src_a, base.vertices[pick][keep]])
        dst_a = np.vstack([dst_a, goal[keep]])
        lam = np.concatenate([lam, np.full(int(keep.sum()), SMOOTHING)])
        labels += ["clearance"] * int(keep.sum())
        extra += int(keep.sum())
    # what the refits left inside the bone (thin bone, lips over teeth at a slender build)
    # is moved out along the bone's normal to the minimum tissue: no build offered may put
    # skin inside bone (issue 33); the count is a figure and a note of the fit
    # (a few passes: a vertex pushed out of a concave spot may land behind another face)
    clamped_ids: set[int] = set()
    for attempt in range(CLAMP_PASSES):
        inside = checked & (signed < 0.0)
        if not inside.any():
            break
        clamped_ids.update(np.flatnonzero(inside).tolist())
        moved = moved.copy()
        # a vertex still inside after a pass sits where bone folds: a little more each time
        out = settings.min_tissue_mm * (1.0 + 0.25 * attempt)
        moved[inside] = bone_pt[inside] + out * normal[inside]
        _, signed, bone_pt, normal, checked = _thin_spots(
            moved, index, t_weight, settings.min_tissue_mm, exempt
        )
    clamped = len(clamped_ids)
    return _Clearance(src_a, dst_a, lam, warp, moved, signed, checked, refits, extra, clamped)


def _anchors(
    reference: np.ndarray, base: np.ndarray, src: list, dst: list
) -> tuple[np.ndarray, np.ndarray]:
    """Skin vertices held in place by the final warp, and how firmly (0-1].

    One per :data:`ANCHOR_SPACING_MM` cell of the *reference* skin (a choice
    the target cannot change).  Near a point the warp moves, an anchor's
    hold fades: none within :data:`ANCHOR_CLEARANCE_MM`, full beyond
    another :data:`ANCHOR_TAPER_MM`, and a point counts as moving in
    proportion to its displacement up to :data:`MOVING_MM` (mm, head frame).
    """
    anchors = _spread(reference, ANCHOR_SPACING_MM)
    hold = np.ones(len(anchors))
    if src:
        s, d = np.asarray(src, float), np.asarray(dst, float)
        strength = np.clip(np.linalg.norm(d - s, axis=1) / MOVING_MM, 0.0, 1.0)
        mv = strength > 0
        if mv.any():
            reach = ANCHOR_CLEARANCE_MM + ANCHOR_TAPER_MM
            near = cKDTree(base[anchors]).sparse_distance_matrix(
                cKDTree(s[mv]), reach, output_type="coo_matrix"
            )
            t = np.clip((near.data - ANCHOR_CLEARANCE_MM) / ANCHOR_TAPER_MM, 0.0, 1.0)
            fade = 1.0 - strength[mv][near.col] * (1.0 - t * t * (3.0 - 2.0 * t))
            np.minimum.at(hold, near.row, fade)
        # nor on a point held in place (a guide already where it wants its landmark)
        hold[cKDTree(s).query(base[anchors])[0] <= 0.5] = 0.0
    keep = hold >= ANCHOR_MIN_WEIGHT
    return anchors[keep], hold[keep]


def _thin_spots(
    skin: np.ndarray, index: MeshIndex, weight: np.ndarray, min_tissue: float, exempt: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Skin vertices closer than ``min_tissue`` to believed target bone (or inside it).

    Returns ``(thin, signed distance, closest bone point, bone normal, checked)``;
    only vertices within :data:`BONE_SEARCH_MM` of bone the registration
    believes (not the C-spine, not a hole rim) are checked.
    """
    cp = index.closest_points(skin)
    normals = index.pseudo_normals(cp.face_ids, cp.barycentric)
    side = np.einsum("ij,ij->i", skin - cp.points, normals)
    signed = np.where(side < 0, -cp.distances, cp.distances)
    tri = index.mesh.faces[cp.face_ids]
    believed = np.einsum("ij,ij->i", cp.barycentric, weight[tri]) > 0.5
    near = (cp.distances < BONE_SEARCH_MM) & believed & ~exempt
    thin = near & (signed < min_tissue)
    return thin, signed, cp.points, normals, near


def reconstruct(
    skull: Mesh,
    landmarks: LandmarkSet | None,
    head: TemplateHead,
    *,
    settings: FitSettings = FitSettings(),
    guide_targets: Mapping[str, np.ndarray] | None = None,
    guides: Callable[[Mesh, LandmarkSet, DowelPlan], GuideFn | None] | None = None,
    hint: tuple | None = None,
    registration: SkullRegistration | None = None,
    progress: Callable[[str], None] | None = None,
) -> Reconstruction:
    """Fit ``head`` over ``skull`` (input frame, mm); see the module docstring.

    ``landmarks`` (input frame) may be None: the registration finds them.
    Landmarks the user *placed* are seeds and hard constraints of the
    registration and keep their positions; suggested ones are replaced by
    the registration's.  ``guides(skull_h, landmarks_h, plan)`` may return
    a function giving guide targets from the skin landmarks before the last
    warp.  ``registration`` reuses an earlier
    :func:`~workbench.services.registration.skull_registration.register_skull` result
    of the same skull (a refit after an edit).
    """
    from workbench.services.registration.skull_registration import (
        articulate,
        mirror_from_landmarks,
        register_skull,
    )

    t0 = time.perf_counter()
    reg = registration or register_skull(
        skull,
        head,
        hint=hint,
        seeds=landmarks,
        mirror=mirror_from_landmarks(landmarks),
        progress=progress,
    )
    to_head, mirrored = reg.input_to_head, reg.mirrored
    bone = skull
    if settings.jaw == "occlusion" and reg.occlusion is None:
        reg = articulate(reg, head)
    if reg.occlusion is not None:
        # the face is fitted over the articulated skull: the user's landmarks on the jaw
        # move with it, and landmarks snap to the articulated bone
        landmarks = _with_jaw_moved(landmarks, reg, head)
        bone = articulated_skull(reg)
    lms = merge_user_landmarks(reg.landmarks, landmarks)
    snapped: list[str] = []
    if settings.snap_landmarks:
        from workbench.services.landmarks.snap import snap_suggested

        lms, snapped = snap_suggested(bone, lms, fallback_frame=to_head)
    lms_h = lms.transformed(to_head)
    doubtful = [
        lm.code
        for lm in lms_h
        if lm.status == "suggested" and lm.confidence < settings.min_confidence
    ]
    if doubtful:
        lms_h = LandmarkSet(
            lms_h.surface,
            tuple(lm.moved(lm.position, "absent") if lm.code in doubtful else lm for lm in lms_h),
        )
    skull_h = reg.target_h
    say = progress or (lambda _m: None)
    say("planning the dowels ...")
    plan = plan_dowels(skull_h, lms_h, settings.depth)
    guide_fn = None if guides is None else guides(skull_h, lms_h, plan)
    say("fitting the head to the dowels and guides ...")
    fit = fit_head(
        head,
        reg,
        plan,
        guide_targets=guide_targets,
        guides=guide_fn,
        settings=settings,
        landmarks_h=lms_h,
    )
    figures = fit.figures
    observed = _skin_observed(fit.head.skin, reg)
    face = np.asarray(head.regions.get("face", np.arange(head.skin.n_vertices)), dtype=np.int64)
    figures["registration"] = reg.figures
    figures["snapped_landmarks"] = sum(" moved " in n for n in snapped)
    figures["face_observed_fraction"] = round(float(np.mean(observed[face] >= OBSERVED_LEVEL)), 4)
    figures["seconds_total"] = round(time.perf_counter() - t0, 3)
    warnings = list(reg.warnings) + list(plan.warnings) + list(figures.pop("eye_notes"))
    if doubtful:
        warnings.append(
            f"{len(doubtful)} landmarks found with confidence below "
            f"{settings.min_confidence:g} got no dowel (confirm or move them): "
            + ", ".join(doubtful)
        )
    inferred = 1.0 - figures["face_observed_fraction"]
    if inferred > 0.05:
        warnings.append(
            f"{100 * inferred:.0f} % of the face lies over missing bone and is "
            "inferred from the reference head (marked in the head pack, the report "
            "and the pictures)"
        )
    if figures.get("clamped_vertices"):
        warnings.append(
            f"{figures['clamped_vertices']} skin vertices lay inside the bone after "
            f"{figures['refits']} refits and were moved out to the minimum tissue "
            f"({settings.min_tissue_mm:g} mm)"
        )
    if figures["penetrating_vertices"]:
        warnings.append(
            f"{figures['penetrating_vertices']} skin vertices still inside the bone "
            f"after {figures['refits']} refits"
        )
    return Reconstruction(
        fit.head,
        to_head,
        mirrored,
        plan,
        fit.sources,
        fit.targets,
        figures,
        fit.guides,
        tuple(warnings),
        fit.labels,
        fit.base_skin,
        fit.held,
        observed,
        _with_jaw_moved(lms, reg, head, back=True),
        reg,
        tissue_field(head, settings.depth, settings.tissue),
        fit.smoothing,
    )


def articulated_skull(reg: SkullRegistration) -> Mesh:
    """The registration's bone in the skull file's frame (mm): with the jaw in occlusion when
    :func:`~workbench.services.registration.skull_registration.articulate` moved it."""
    return reg.target_h.transformed(np.linalg.inv(reg.input_to_head))


def _with_jaw_moved(
    given: LandmarkSet | None, reg: SkullRegistration, head: TemplateHead, *, back: bool = False
) -> LandmarkSet | None:
    """Landmarks (input frame) with those on the mandible moved into occlusion, or with
    ``back`` from occlusion to where the scan has the jaw (the case keeps its landmarks on
    the evidence)."""
    if given is None or reg.occlusion is None:
        return given
    on_jaw = {c for c, part in head.skull_landmark_part.items() if part == "mandible"}
    occ = reg.occlusion.matrix
    m = np.linalg.inv(reg.input_to_head) @ (np.linalg.inv(occ) if back else occ) @ reg.input_to_head
    return LandmarkSet(
        given.surface,
        tuple(
            lm.moved(apply_transform(m, lm.position[None])[0], lm.status)
            if lm.code in on_jaw and lm.is_defined
            else lm
            for lm in given
        ),
    )


def ensemble_spread(
    recon: Reconstruction,
    head: TemplateHead,
    skull_h: Mesh | None = None,
    n: int = 20,
    *,
    seed: int = 0,
    settings: FitSettings = FitSettings(),
) -> np.ndarray:
    """Per-skin-vertex spread (mm, RMS distance from the mean) over ``n`` depth draws.

    Each member redraws every site depth of the tissue model from its table
    mean ± SD (independent normal draws); the change reaches the skin
    through the model's influence matrix, so a member costs a matrix
    product.  Over inferred skin (no bone beneath) the reference's prior is
    the only source: :data:`PRIOR_SD_MM` is added in quadrature there.
    """
    field_ = recon.tissue or tissue_field(head, settings.depth, settings.tissue)
    rng = np.random.default_rng(seed)
    n_skin = head.skin.n_vertices
    if field_.sites and n > 0:
        sd = np.array([s.sd_mm or 0.0 for s in field_.sites])
        draws = rng.standard_normal((n, len(sd))) * sd
        offsets = draws @ field_.influence.T  # (n, n_skin) mm along the normal
        var = ((offsets - offsets.mean(axis=0)) ** 2).mean(axis=0)
    else:
        var = np.zeros(n_skin)
    if recon.observed is not None:
        var = var + (PRIOR_SD_MM * (1.0 - recon.observed)) ** 2
    return np.sqrt(var)


#: shape uncertainty of skin over missing bone (the reference's prior alone), mm
PRIOR_SD_MM = 5.0
