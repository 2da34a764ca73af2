"""Skull → face: fit the reference head over a landmarked skull (Kähler 2003, §8.6.5).

Units mm.  The skull and its landmarks come in the **input frame** (scanner
or CT coordinates); the work happens in the head frame (x to the subject's
left, y up, z forward, Frankfort Horizontal at y = 0) computed from the
porions, orbitales and midline landmarks; every result can be mapped back
(:meth:`Reconstruction.to_input`) so the face overlays the evidence.  A
mirrored input (e.g. a CT stored in a left-handed space) is handled by a
reflection in that map, and the triangle winding is restored on the way
back.

Fit (digest §6.4–6.5):

1. Dowels (:mod:`workbench.services.dowels`): tip q_i = s_i + d_i n_i for
   every skull landmark with a table depth, plus interpolated sites on the
   cranium and mandible.
2. The reference head's paired skin landmarks p_i (and, for interpolated
   sites, the skin point above the same site on the reference skull) are
   warped onto the tips: one landmark warp (φ(r) = r, §8.3.1) moves skin,
   muscles (they ride on the skin), eyes, teeth and the reference skull
   parts together.
3. Guides (nose, mouth, lips, eyes) replace the coordinates they control of
   their skin landmarks' targets and the warp is solved again (the
   dissertation's "second warp", folded into one solve here).
4. Non-penetration: skin vertices closer to the skull than
   ``min_tissue_mm`` (or inside it) get extra correspondences that put them
   at that thickness along the skull normal, and the warp is re-solved,
   until none is left (or ``max_refits`` rounds).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial import cKDTree

from workbench.core.errors import LandmarkError
from workbench.core.frame import apply_transform
from workbench.core.landmarks import LandmarkSet
from workbench.core.mesh import Mesh
from workbench.core.spatial import MeshIndex
from workbench.core.tps import LandmarkWarp, fit_warp
from workbench.model.template import TemplateHead
from workbench.services.dowels import DepthSettings, DowelPlan, depth_samples, plan_dowels
from workbench.services.frame import head_frame_from_landmarks
from workbench.services.reference_parts import skull_surface

#: spacing of the extra non-penetration correspondences (mm)
CLEARANCE_SPACING_MM = 8.0
#: skin vertices farther than this from any bone are not checked (bone missing there)
BONE_SEARCH_MM = 30.0
#: bone farther than this from the warped reference skull is not the skull (vertebrae ...)
SKULL_LIKE_MM = 8.0
#: warp regularisation λ (mm): suggested landmarks are noisy, and an exact
#: interpolation of every tip crumples the skin between close dowels
SMOOTHING = 1.0
#: skin regions never pushed off the bone (the neck stump meets the spine)
NO_CLEARANCE_REGIONS = ("neck",)


@dataclass(frozen=True)
class FitSettings:
    """What the fit uses beyond the dowels."""

    depth: DepthSettings = field(default_factory=DepthSettings)
    min_tissue_mm: float = 2.0
    max_refits: int = 4
    #: suggested landmarks below this confidence get no dowel (placed ones always do)
    min_confidence: float = 0.15


@dataclass(frozen=True)
class Reconstruction:
    """A fitted head.

    Attributes
    ----------
    head : TemplateHead
        The reference head warped onto the skull, in the head frame (mm).
    input_to_head : (4, 4)
        Map of input coordinates into the head frame (a reflection included
        when ``mirrored_input``).
    plan : DowelPlan
        The dowels used (head frame).
    sources, targets : (k, 3)
        The final correspondences of the warp (head frame).
    labels : tuple of str
        What each correspondence is: ``"dowel:<skull code>"``,
        ``"guide:<skin code>"`` or ``"clearance"`` (a non-penetration
        point added by a refit); the interactive preview moves targets by it.
    figures : dict
        ``max_tip_error_mm``, ``min_tissue_mm``, ``penetrating_vertices``,
        ``refits``, ``extra_correspondences``, ``seconds``.
    guide_targets : dict
        Skin code → target position set by guides (head frame).
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

    def to_input(self, points: np.ndarray) -> np.ndarray:
        return apply_transform(np.linalg.inv(self.input_to_head), points)

    def mesh_to_input(self, mesh: Mesh) -> Mesh:
        """A head-frame mesh in the input frame, outward winding kept."""
        out = Mesh(self.to_input(mesh.vertices),
                   mesh.faces[:, ::-1] if self.mirrored_input else mesh.faces)
        return out

    @property
    def face(self) -> Mesh:
        """The fitted skin in the input frame."""
        return self.mesh_to_input(self.head.skin)


def input_frame(landmarks: LandmarkSet) -> tuple[np.ndarray, bool]:
    """``(input → head 4x4, mirrored)`` from skull landmarks (FH + midline)."""
    defined = landmarks.defined()
    frame = head_frame_from_landmarks(defined)
    if not frame.mirrored_input:
        return frame.input_to_head, False
    flip = np.diag([-1.0, 1.0, 1.0, 1.0])
    again = head_frame_from_landmarks(defined.transformed(flip))
    if again.mirrored_input:
        raise LandmarkError("the skull landmarks contradict each other about left and right "
                            "(check the porions, orbitales and the _l/_r labels)")
    return again.input_to_head @ flip, True


def outward(mesh: Mesh) -> Mesh:
    """``mesh`` with its triangles wound so normals point away from its centre.

    Inside/outside tests need outward normals; scanner and CT meshes (and
    mirrored files) come either way.  Judged by the area-weighted agreement
    of face normals with the direction from the centroid.
    """
    centres = mesh.triangles.mean(axis=1)
    agree = np.einsum("ij,ij->i", mesh.face_cross, centres - centres.mean(axis=0)).sum()
    return mesh if agree >= 0 else Mesh(mesh.vertices, mesh.faces[:, ::-1])


#: skin points of interpolated sites on a reference head, per (head hash, table, sites)
_REF_CACHE: dict[tuple, dict[str, np.ndarray]] = {}


def reference_correspondences(head: TemplateHead, plan: DowelPlan,
                              settings: DepthSettings) -> dict[str, np.ndarray]:
    """Skin point of the reference head for every dowel code of ``plan`` (head frame).

    Table dowels use the paired skin landmark.  Interpolated sites are
    planned on the reference skull with the same pattern; their skin point
    is where the reference's own dowel from that site meets its skin.
    """
    skin = head.skin_landmarks.as_dict()
    out = {d.code: skin[d.skin_code] for d in plan.dowels
           if d.skin_code is not None and d.skin_code in skin}
    wanted = [d.code for d in plan.dowels if d.source == "interpolated"]
    key = (head.content_hash, str(settings.table), tuple(wanted))
    if wanted and key in _REF_CACHE:
        out.update(_REF_CACHE[key])
    elif wanted:
        ref_plan = plan_dowels(skull_surface(head), head.skull_landmarks,
                               replace(settings, overrides={}, excluded=frozenset(),
                                       directions={}, build="normal"))
        skin_index = MeshIndex(head.skin)
        tips = {d.code: d for d in ref_plan.dowels if d.code in wanted}
        if tips:
            codes = list(tips)
            pts = np.array([tips[c].tip for c in codes])
            cp = skin_index.closest_points(pts).points
            found = dict(zip(codes, cp, strict=True))
            _REF_CACHE[key] = found
            out.update(found)
    return out


def warp_head(head: TemplateHead, warp: LandmarkWarp) -> TemplateHead:
    meshes = {name: m.with_vertices(warp(m.vertices)) for name, m in head.meshes.items()}
    centres = warp(head.eye_centres)
    # a globe is rigid: move it with its centre, keep its size (§8.3.2)
    eyes = head.meshes["eyes"].vertices
    owner = np.linalg.norm(eyes[:, None] - head.eye_centres[None], axis=2).argmin(axis=1)
    meshes["eyes"] = head.meshes["eyes"].with_vertices(eyes + (centres - head.eye_centres)[owner])
    axis_pts = warp(np.vstack([head.tmj_axis[0], head.tmj_axis[0] + 10 * head.tmj_axis[1]]))
    direction = axis_pts[1] - axis_pts[0]
    return replace(
        head,
        meshes=meshes,
        skin_landmarks=_warp_set(head.skin_landmarks, warp),
        skull_landmarks=_warp_set(head.skull_landmarks, warp),
        eye_centres=centres,
        tmj_axis=np.vstack([axis_pts[0], direction / np.linalg.norm(direction)]),
    )


def _warp_set(lms: LandmarkSet, warp: LandmarkWarp) -> LandmarkSet:
    defined = [lm for lm in lms if lm.is_defined]
    if not defined:
        return lms
    moved = warp(np.array([lm.position for lm in defined]))
    new = {lm.code: lm.moved(p, lm.status) for lm, p in zip(defined, moved, strict=True)}
    return LandmarkSet(lms.surface, tuple(new.get(lm.code, lm) for lm in lms))


def _thin_spots(skin: np.ndarray, skull_index: MeshIndex, min_tissue: float,
                exclude: np.ndarray, skull_like: cKDTree | None = None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Skin vertices closer than ``min_tissue`` to the bone (or inside it).

    Only bone the reference skull accounts for counts: with ``skull_like``
    (a k-d tree of the warped reference skull) a closest bone point farther
    than :data:`SKULL_LIKE_MM` from it — a vertebra, the hyoid, a CT
    artefact — is ignored.
    """
    cp = skull_index.closest_points(skin)
    signed = skull_index.signed_distance(skin)
    near = (cp.distances < BONE_SEARCH_MM) & ~exclude
    if skull_like is not None:
        d, _ = skull_like.query(cp.points)
        near &= d < SKULL_LIKE_MM
    thin = near & (signed < min_tissue)
    return thin, signed, cp.points


def _spread(points: np.ndarray, spacing: float) -> np.ndarray:
    """Indices of a subset of ``points`` no two closer than ``spacing`` (greedy)."""
    chosen: list[int] = []
    for i, p in enumerate(points):
        if all(np.linalg.norm(points[j] - p) >= spacing for j in chosen):
            chosen.append(i)
    return np.array(chosen, dtype=np.int64)


def _pairs(plan: DowelPlan, ref_points: Mapping[str, np.ndarray], skin_lms: Mapping[str, np.ndarray],
           guide_targets: Mapping[str, np.ndarray], depths: np.ndarray | None
           ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray], list[str]]:
    """Warp correspondences: reference skin points → dowel tips, guided codes → guide targets.

    Also returns a label per correspondence (see :attr:`Reconstruction.labels`).
    """
    src, dst, tip_of, labels = [], [], {}, []
    for i, d in enumerate(plan.dowels):
        if d.excluded or d.code not in ref_points or d.skin_code in guide_targets:
            continue  # a guide, when there is one, decides that skin landmark
        depth = d.depth_mm if depths is None else float(depths[i])
        tip = d.origin + depth * d.direction
        src.append(ref_points[d.code])
        dst.append(tip)
        tip_of[d.code] = tip
        labels.append(f"dowel:{d.code}")
    for code, target in guide_targets.items():
        if code in skin_lms:
            src.append(skin_lms[code])
            dst.append(np.asarray(target, float))
            labels.append(f"guide:{code}")
    if len(src) < 4:
        raise LandmarkError(f"only {len(src)} usable dowels; place more skull landmarks "
                            "(at least 4 with table depths)")
    return np.array(src), np.array(dst), tip_of, labels


GuideFn = Callable[[dict[str, np.ndarray]], dict[str, np.ndarray]]


def fit_head(head: TemplateHead, skull_h: Mesh, plan: DowelPlan, *,
             guide_targets: Mapping[str, np.ndarray] | None = None,
             guides: GuideFn | None = None,
             settings: FitSettings = FitSettings(), depths: np.ndarray | None = None,
             extra: tuple[np.ndarray, np.ndarray] | None = None,
             ref_points: dict[str, np.ndarray] | None = None,
             skull_index: MeshIndex | None = None
             ) -> tuple[TemplateHead, dict, np.ndarray, np.ndarray, dict[str, np.ndarray],
                        tuple[str, ...]]:
    """Warp ``head`` so its skin meets the dowel tips (all in the head frame).

    ``guides`` maps the skin landmark positions after the dowel warp to guide
    targets (the dissertation's second warp, §8.6.5); ``guide_targets`` gives
    them directly.  ``depths`` (one per dowel of ``plan``) replaces the
    planned depths (the ensemble); ``extra`` adds fixed correspondences and
    skips the non-penetration loop (used by the ensemble with the main
    fit's extras).  Returns the fitted head, figures, the correspondences,
    the guide targets used and a label per correspondence.
    """
    t0 = time.perf_counter()
    ref_points = ref_points if ref_points is not None else reference_correspondences(
        head, plan, settings.depth)
    guide_targets = dict(guide_targets or {})
    skin_lms = head.skin_landmarks.as_dict()
    src_a, dst_a, tip_of, labels = _pairs(plan, ref_points, skin_lms, guide_targets, depths)
    if extra is not None and len(extra[0]):
        src_a, dst_a = np.vstack([src_a, extra[0]]), np.vstack([dst_a, extra[1]])
        labels += ["clearance"] * len(extra[0])
    warp = fit_warp(src_a, dst_a, smoothing=SMOOTHING)
    if guides is not None:
        codes = list(skin_lms)
        prefit = dict(zip(codes, warp(np.array([skin_lms[c] for c in codes])), strict=True))
        guide_targets.update(guides(prefit))
        if guide_targets:
            src_a, dst_a, tip_of, labels = _pairs(plan, ref_points, skin_lms, guide_targets,
                                                  depths)
            warp = fit_warp(src_a, dst_a, smoothing=SMOOTHING)
    skin_v = head.skin.vertices
    index = skull_index or MeshIndex(skull_h)
    openings = np.zeros(len(skin_v), dtype=bool)
    for loop in head.openings.values():
        openings[np.asarray(loop, dtype=np.int64)] = True
    for name in NO_CLEARANCE_REGIONS:
        if name in head.regions:
            openings[np.asarray(head.regions[name], dtype=np.int64)] = True
    ref_bone = skull_surface(head).vertices[::3]
    refits = 0
    n_extra = 0
    if extra is None:
        for refits in range(1, settings.max_refits + 1):  # noqa: B007
            moved = warp(skin_v)
            thin, signed, bone = _thin_spots(moved, index, settings.min_tissue_mm, openings,
                                             cKDTree(warp(ref_bone)))
            if not thin.any():
                refits -= 1
                break
            ids = np.flatnonzero(thin)
            ids = ids[np.argsort(signed[ids])]  # worst first
            pick = ids[_spread(moved[ids], CLEARANCE_SPACING_MM)]
            outward = moved[pick] - bone[pick]
            lengths = np.linalg.norm(outward, axis=1, keepdims=True)
            normals = index.pseudo_normals(*_face_bary(index, moved[pick]))
            outward = np.where(signed[pick, None] > 0.05, outward / np.maximum(lengths, 1e-9),
                               normals)
            goal = bone[pick] + (settings.min_tissue_mm + 0.5) * outward
            # dowel targets stay exact; a new point too close to an existing
            # correspondence would fight it, so it is left out
            gap = np.min(np.linalg.norm(skin_v[pick][:, None] - src_a[None], axis=2), axis=1)
            new = gap > 3.0
            if not new.any():
                break
            src_a = np.vstack([src_a, skin_v[pick][new]])
            dst_a = np.vstack([dst_a, goal[new]])
            labels += ["clearance"] * int(new.sum())
            n_extra += int(new.sum())
            warp = fit_warp(src_a, dst_a, smoothing=SMOOTHING)
    fitted = warp_head(head, warp)
    moved = fitted.skin.vertices
    like = cKDTree(warp(ref_bone))
    _, signed, bone = _thin_spots(moved, index, settings.min_tissue_mm, openings, like)
    checked = ((np.linalg.norm(bone - moved, axis=1) < BONE_SEARCH_MM)
               & (like.query(bone)[0] < SKULL_LIKE_MM))
    tip_err = [float(np.linalg.norm(warp(ref_points[c][None])[0] - t)) for c, t in tip_of.items()]
    figures = {
        "max_tip_error_mm": max(tip_err) if tip_err else 0.0,
        "min_tissue_mm": float(signed[checked & ~openings].min()) if checked.any() else None,
        "penetrating_vertices": int(((signed < 0) & checked & ~openings).sum()),
        "thin_vertices": int(((signed < settings.min_tissue_mm) & checked & ~openings).sum()),
        "refits": int(refits),
        "extra_correspondences": int(n_extra),
        "correspondences": len(src_a),
        "seconds": round(time.perf_counter() - t0, 3),
    }
    return fitted, figures, src_a, dst_a, guide_targets, tuple(labels)


def _face_bary(index: MeshIndex, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    cp = index.closest_points(pts)
    return cp.face_ids, cp.barycentric


def reconstruct(skull: Mesh, landmarks: LandmarkSet, head: TemplateHead, *,
                settings: FitSettings = FitSettings(),
                guide_targets: Mapping[str, np.ndarray] | None = None,
                guides: Callable[[Mesh, LandmarkSet, DowelPlan], GuideFn | None] | None = None
                ) -> Reconstruction:
    """Fit ``head`` over ``skull`` (input frame, mm) from its skull ``landmarks``.

    ``guides(skull_h, landmarks_h, plan)`` may return a function giving guide
    targets from the dowel-fitted skin landmarks (see :func:`fit_head`).
    """
    to_head, mirrored = input_frame(landmarks)
    # a rigid copy (Mesh.transformed) shares the input skull's ray-casting
    # scene instead of building its own for every fit
    skull_h = outward(skull.transformed(to_head))
    lms_h = landmarks.transformed(to_head)
    doubtful = [lm.code for lm in lms_h if lm.status == "suggested"
                and lm.confidence < settings.min_confidence]
    if doubtful:
        # a wrongly placed dowel distorts the whole face (§8.4.3): doubtful
        # suggestions get no dowel until the user confirms or moves them
        lms_h = LandmarkSet(lms_h.surface, tuple(
            lm.moved(lm.position, "absent") if lm.code in doubtful else lm for lm in lms_h))
    plan = plan_dowels(skull_h, lms_h, settings.depth)
    guide_fn = None if guides is None else guides(skull_h, lms_h, plan)
    fitted, figures, src, dst, used, labels = fit_head(
        head, skull_h, plan, guide_targets=guide_targets, guides=guide_fn, settings=settings)
    warnings = list(plan.warnings)
    if doubtful:
        warnings.append(f"{len(doubtful)} suggested landmarks below confidence "
                        f"{settings.min_confidence:g} got no dowel (confirm or move them): "
                        + ", ".join(doubtful))
    if mirrored:
        warnings.append("the input is mirrored (left-handed coordinates): the head frame "
                        "includes a reflection, and results are mapped back the same way")
    if figures["penetrating_vertices"]:
        warnings.append(f"{figures['penetrating_vertices']} skin vertices still inside the bone "
                        f"after {figures['refits']} refits")
    return Reconstruction(fitted, to_head, mirrored, plan, src, dst, figures,
                          used, tuple(warnings), labels)


def ensemble_spread(recon: Reconstruction, head: TemplateHead, skull_h: Mesh, n: int, *,
                    seed: int = 0, settings: FitSettings = FitSettings()) -> np.ndarray:
    """Per-skin-vertex spread (mm, RMS distance from the mean) over ``n`` depth draws.

    Each member redraws every dowel depth from its table mean ± SD
    (:func:`~workbench.services.dowels.depth_samples`) and re-solves the warp
    with the main fit's guide targets and non-penetration correspondences.
    """
    rng = np.random.default_rng(seed)
    ref_points = reference_correspondences(head, recon.plan, settings.depth)
    n_main = len(recon.sources) - recon.figures["extra_correspondences"]
    extra = (recon.sources[n_main:], recon.targets[n_main:])
    index = MeshIndex(skull_h)
    runs = []
    for _ in range(n):
        depths = depth_samples(recon.plan, rng)
        fitted, *_ = fit_head(head, skull_h, recon.plan, guide_targets=recon.guide_targets,
                              settings=settings, depths=depths, extra=extra,
                              ref_points=ref_points, skull_index=index)
        runs.append(fitted.skin.vertices)
    stack = np.stack(runs)
    return np.sqrt(((stack - stack.mean(axis=0)) ** 2).sum(axis=2).mean(axis=0))
