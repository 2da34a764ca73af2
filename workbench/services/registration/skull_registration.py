"""Dense registration of the reference skull onto a target skull, part by part.

Units mm.  Input: the target bone surface in its **input frame** (a CT's
physical frame, a scanner's frame, any axes, any handedness) and a
reference head (head frame: x to the subject's left, x = 0 midsagittal,
y up, z toward the face, Frankfort Horizontal at y = 0).  Output: the map
of the input into the *target's own* head frame (mm, rigid, a reflection
when the input is mirrored) and the reference skull — cranium with upper
teeth, mandible with lower teeth — registered onto the target in that
frame, with per-vertex evidence ("observed" where real bone supports it).

Steps:

1. **Orientation** (:func:`workbench.core.rigid_search.search_pose`): from
   the bone alone, or an orientation hint, or three or more landmarks the
   user placed (seeds).  The similarity found is split into a rigid map of
   the input (its head frame, mm kept) and a uniform scale applied to the
   *reference*, so the target is never resized.
2. **Target weights**: vertices near a hole rim or the edge of the field
   of view (:data:`RIM_MM`) and vertices far from the reference skull
   (:data:`EXTRA_MM`: C-spine, hyoid, tubes, pins, the CT table) fade to
   zero weight.
3. **Mandible pose**: open or shifted jaws are normal, so the mandible
   gets its own rigid pose (starts rotated about the jaw axis), and is
   declared **missing** when too little of it finds bone
   (:mod:`workbench.core.jaw_pose`); a missing mandible follows the cranium and is
   marked inferred.
4. **Non-rigid** (:func:`workbench.core.nonrigid.register`): coarse to fine,
   both parts at once, independently; user-placed landmarks are hard
   constraints.
5. **Landmarks** ride on the registered surface (same triangle, same
   barycentric weights); a landmark whose surface is observed is
   *suggested* with a confidence, one over missing bone is *absent* (its
   carried position is kept in :attr:`SkullRegistration.inferred`).
6. **Frankfort frame** from the registered porions and orbitales (observed
   or inferred — never refused; which ones were inferred is reported).

Deterministic (seeded sampling, no data-dependent random choices).

The result type is :class:`workbench.services.registration.result.SkullRegistration`;
bringing the jaw into occlusion afterwards is
:func:`workbench.services.registration.articulation.articulate` (both importable
from here).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from workbench.core.bone_pieces import apparatus_faces, judge_pieces
from workbench.core.errors import InputError
from workbench.core.jaw_pose import JawPose, pose_jaw
from workbench.core.landmarks import Landmark, LandmarkSet
from workbench.core.mesh import Mesh, boundary_loops, concatenate
from workbench.core.nonrigid import Registration, Target, register, smoothstep
from workbench.core.rigid_search import PoseResult, search_pose
from workbench.core.skull_pose import SkullPoseResult
from workbench.core.spatial import MeshIndex
from workbench.core.tps import LandmarkWarp, fit_warp
from workbench.model.template import TemplateHead
from workbench.services.landmarks.frame import head_frame_from_landmarks
from workbench.services.registration.articulation import (
    articulate as articulate,  # re-exported: callers import it from here
)
from workbench.services.registration.result import (
    OBSERVED_WEIGHT,
    PART_OF,
    PartReport,
    SkullRegistration,
    apply_points,
)

#: target vertices this close to a hole rim or the field-of-view edge fade out (mm)
RIM_MM = 5.0
#: target vertices farther than EXTRA_MM[0] from the posed reference skull start to fade,
#: beyond EXTRA_MM[1] they are ignored (mm)
EXTRA_MM = (10.0, 20.0)
#: teeth are decimated to about this many triangles for the registration
TEETH_TRIANGLES = 3000
FH_CODES = ("po_l", "po_r", "or_l", "or_r")

PART_NAMES = ("cranium", "mandible")

Progress = Callable[[str], None]


def _registration_parts(head: TemplateHead, scale: float) -> dict[str, Mesh]:
    """Reference skull parts at registration resolution, scaled about the head-frame origin."""
    from workbench.core.isosurface import decimate

    out = {}
    for name in PART_OF:
        m = head.meshes[name]
        if name.endswith("teeth") and m.n_faces > TEETH_TRIANGLES:
            m = Mesh(*decimate(m.vertices, m.faces, TEETH_TRIANGLES))
        out[name] = m.scaled(scale)
    return out


def target_weights(target_h: Mesh, reference: Mesh | None) -> tuple[np.ndarray, dict]:
    """Per target vertex belief 0..1: hole rims and (with a ``reference``) extra anatomy fade out."""
    w = np.ones(target_h.n_vertices)
    loops = boundary_loops(target_h)
    rim_fraction = 0.0
    if loops:
        rim = np.concatenate(loops)
        d, _ = cKDTree(target_h.vertices[rim]).query(target_h.vertices)
        fade = smoothstep(d / RIM_MM)
        rim_fraction = float(np.mean(fade < 0.5))
        w *= fade
    extra = np.ones(target_h.n_vertices)
    if reference is not None:
        d, _ = cKDTree(reference.vertices).query(target_h.vertices)
        extra = 1.0 - smoothstep((d - EXTRA_MM[0]) / (EXTRA_MM[1] - EXTRA_MM[0]))
        w *= extra
    areas = np.zeros(target_h.n_vertices)
    np.add.at(areas, target_h.faces.ravel(), np.repeat(target_h.face_areas / 3.0, 3))
    figures = {
        "target_rim_fraction": round(rim_fraction, 4),
        "target_extra_area_fraction": round(float(areas[extra < 0.5].sum() / areas.sum()), 4),
        "target_open_boundaries": len(loops),
    }
    return w, figures


def _rotation_about(axis_point: np.ndarray, axis_dir: np.ndarray, deg: float) -> np.ndarray:
    a = axis_dir / np.linalg.norm(axis_dir)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    th = np.radians(deg)
    r = np.eye(3) + np.sin(th) * k + (1 - np.cos(th)) * k @ k
    m = np.eye(4)
    m[:3, :3] = r
    m[:3, 3] = axis_point - r @ axis_point
    return m


def _carry_landmarks(
    head: TemplateHead,
    rest: Mapping[str, Mesh],
    moved: Mapping[str, Mesh],
    observed: Mapping[str, np.ndarray],
    scale: float,
) -> tuple[dict[str, np.ndarray], dict[str, float]]:
    """Reference skull landmarks carried by the registration; per code its support 0..1."""
    out: dict[str, np.ndarray] = {}
    support: dict[str, float] = {}
    groups = {
        "cranium": ("cranium", "upper_teeth"),
        "mandible": ("mandible", "lower_teeth"),
        "teeth": ("upper_teeth", "lower_teeth"),
    }
    lms = [lm for lm in head.skull_landmarks if lm.is_defined]
    pos = scale * np.array([lm.position for lm in lms])
    found = {name: MeshIndex(rest[name]).closest_points(pos) for name in rest}
    for i, lm in enumerate(lms):
        names = groups.get(head.skull_landmark_part.get(lm.code, "cranium"), ("cranium",))
        name = min(names, key=lambda nm: found[nm].distances[i])
        cp = found[name]
        tri = rest[name].faces[cp.face_ids[i]]
        bary = cp.barycentric[i]
        offset = pos[i] - cp.points[i]
        out[lm.code] = bary @ moved[name].vertices[tri] + offset
        support[lm.code] = float(bary @ observed[name][tri])
    return out, support


def reference_in_frame(head: TemplateHead, reg: SkullRegistration) -> TemplateHead:
    """``head`` scaled by the registration's reference scale and settled in its frame."""
    k = reg.reference_scale
    return head_transformed(head, reg.settle @ np.diag([k, k, k, 1.0]))


def head_transformed(head: TemplateHead, m: np.ndarray) -> TemplateHead:
    """``head`` mapped by the similarity ``m`` (4 x 4, mm → mm; e.g. a scale and a settle
    into a head frame): meshes, landmarks, eye centres and radius, the jaw axis."""
    from dataclasses import replace

    k = float(abs(np.linalg.det(m[:3, :3])) ** (1 / 3))
    axis = apply_points(m, np.vstack([head.tmj_axis[0], head.tmj_axis[0] + head.tmj_axis[1]]))
    return replace(
        head,
        meshes={p: x.with_vertices(apply_points(m, x.vertices)) for p, x in head.meshes.items()},
        skin_landmarks=head.skin_landmarks.transformed(m),
        skull_landmarks=head.skull_landmarks.transformed(m),
        eye_centres=apply_points(m, head.eye_centres),
        eye_radius=head.eye_radius * k,
        tmj_axis=np.vstack([axis[0], (axis[1] - axis[0]) / np.linalg.norm(axis[1] - axis[0])]),
    )


def skull_field(reg: SkullRegistration, smoothing_mm: float = 1.0) -> LandmarkWarp:
    """The registration as a smooth space warp (φ(r) = r, Kähler §8.3.1) on a spread subset."""
    rest, moved = reg.displacement_samples()
    return fit_warp(rest, moved, smoothing=smoothing_mm)


def carry_head(head: TemplateHead, reg: SkullRegistration) -> TemplateHead:
    """The whole reference head carried by the skull's displacement field (head frame, mm).

    Skin, muscles (on the skin), eyes (rigidly, with their centres), teeth,
    tongue and landmarks follow the warp fitted to the registered skull; the
    skull parts are the registered ones where observed.
    """

    return reference_in_frame(head, reg).warped(skull_field(reg))


def mirror_from_landmarks(landmarks: LandmarkSet | None) -> str:
    """``"yes"``/``"no"`` when labelled landmarks tell the file's handedness, else ``"auto"``.

    A skull's shape cannot tell a mirrored file, but landmarks labelled
    ``_l``/``_r`` with the porions, orbitales and midline points can
    (:func:`workbench.services.landmarks.frame.head_frame_from_landmarks` checks which
    way up the labelled Frankfort plane makes the face).
    """
    if landmarks is None:
        return "auto"
    from workbench.core.errors import LandmarkError

    try:
        from workbench.services.landmarks.frame import input_frame

        _, mirrored = input_frame(landmarks)
    except (LandmarkError, ValueError, np.linalg.LinAlgError):
        return "auto"
    return "yes" if mirrored else "no"


_CACHE: dict[str, SkullRegistration] = {}
_CACHE_SIZE = 4


def _cache_key(
    skull: Mesh, head: TemplateHead, hint: tuple | None, seeds: LandmarkSet | None, mirror: str
) -> str:
    import hashlib

    h = hashlib.sha256()
    h.update(np.ascontiguousarray(skull.vertices).tobytes())
    h.update(np.ascontiguousarray(skull.faces).tobytes())
    h.update(head.content_hash.encode())
    h.update(repr((hint, mirror)).encode())
    for lm in seeds or ():
        if lm.status == "placed":
            h.update(lm.code.encode())
            h.update(np.ascontiguousarray(lm.position).tobytes())
    return h.hexdigest()


def register_skull(
    skull: Mesh,
    head: TemplateHead,
    *,
    hint: tuple | None = None,
    seeds: LandmarkSet | None = None,
    mirror: str = "auto",
    progress: Progress | None = None,
) -> SkullRegistration:
    """Register ``head``'s skull onto ``skull`` (input frame, mm); see the module docstring.

    ``seeds`` are skull landmarks the user placed (input frame): three or
    more start the orientation, and every one is a hard constraint.  The
    last few results are kept (keyed by the skull's content, the head, the
    hint and the placed seeds), so the window's "Suggest" and the fit after
    it register once.
    """
    key = _cache_key(skull, head, hint, seeds, mirror)
    if key in _CACHE:
        return _CACHE[key]
    result = _register(skull, head, hint=hint, seeds=seeds, mirror=mirror, progress=progress)
    _CACHE[key] = result
    while len(_CACHE) > _CACHE_SIZE:
        _CACHE.pop(next(iter(_CACHE)))
    return result


@dataclass(frozen=True)
class _Placed:
    """The target in the reference's frame under one pose, with the mandible posed on it."""

    rigid: np.ndarray
    mirrored: bool
    k: float
    target_h: Mesh
    parts: dict[str, Mesh]
    layout: dict[str, Mesh]
    weights: np.ndarray
    tfig: dict
    target: Target
    jaw: JawPose


def _orient_and_pose_jaw(
    skull: Mesh, head: TemplateHead, pose: PoseResult, not_bone: np.ndarray | None = None
) -> _Placed:
    """``skull`` mapped by ``pose`` (rigid part; the reference scaled by 1/scale), its
    weights, and the reference mandible posed on it (moved only when found).

    ``not_bone`` marks vertices of pieces that are not bone (a table, a head holder:
    :mod:`workbench.core.bone_pieces`); they get no weight."""
    lin = pose.matrix[:3, :3]
    s = pose.scale
    rigid = np.eye(4)
    rigid[:3, :3] = lin / s
    rigid[:3, 3] = pose.matrix[:3, 3] / s
    mirrored = bool(np.linalg.det(rigid[:3, :3]) < 0)
    k = 1.0 / s  # the reference is scaled instead of the target
    target_h = Mesh(
        apply_points(rigid, skull.vertices), skull.faces[:, ::-1] if mirrored else skull.faces
    )
    if target_h.volume < 0:
        target_h = Mesh(target_h.vertices, target_h.faces[:, ::-1])
    parts = _registration_parts(head, k)
    layout = dict(parts)  # the scaled reference before the jaw pose: what the field maps from
    # the jaw is posed on the bone with only the rims faded (an open jaw lies far from the
    # reference's closed one); the far-anatomy fade follows, with the jaw where it was found
    rims, _ = target_weights(target_h, None)
    if not_bone is not None:
        rims = np.where(not_bone, 0.0, rims)
    jaw = pose_jaw(
        concatenate([parts["mandible"], parts["lower_teeth"]]),
        concatenate([parts["cranium"], parts["upper_teeth"]]),
        np.vstack([k * head.tmj_axis[0], head.tmj_axis[1]]),
        target_h,
        rims,
    )
    if jaw.present:
        for name in ("mandible", "lower_teeth"):
            parts[name] = Mesh(apply_points(jaw.matrix, parts[name].vertices), parts[name].faces)
    weights, tfig = target_weights(target_h, concatenate(list(parts.values())))
    if not_bone is not None:
        weights = np.where(not_bone, 0.0, weights)
    if not (weights > 0.05).any():
        raise InputError(
            "skull",
            "no part of the surface lies near the reference skull after orientation",
            hint="check the units and that the file holds a skull",
        )
    target = Target(target_h, weights, pull_stride=max(1, int(np.sum(weights > 0.05)) // 6000))
    return _Placed(
        rigid,
        mirrored,
        k,
        target_h,
        parts,
        layout,
        weights,
        tfig,
        target,
        jaw,
    )


#: bilateral landmark pairs compared by the self-check (beside the Frankfort points)
BILATERAL = ("zy", "ec", "fe", "mso", "ms", "go", "ecm2s", "mr", "ol", "sgl", "lo", "im")


def _check_measures(
    head: TemplateHead,
    found: SkullPoseResult | None,
    input_to_head: np.ndarray,
    settle: np.ndarray,
    carried: Mapping[str, np.ndarray],
    support: Mapping[str, float],
    observed: Mapping[str, np.ndarray],
    jaw: JawPose,
    k: float,
) -> dict:
    """Figures the self-check judges a registration by (head frame, mm, degrees)."""
    from workbench.core.skull_pose import face_mask

    out: dict = {"scale": round(k, 4)}
    if found is not None:
        out["margin"] = round(found.margin, 4) if np.isfinite(found.margin) else None
        normal = input_to_head[:3, :3] @ found.symmetry_normal
        normal /= np.linalg.norm(normal)
        out["symmetry_deg"] = round(float(np.degrees(np.arccos(min(1.0, abs(normal[0]))))), 2)
        out["symmetry_loss"] = round(found.symmetry_loss, 4)
        out["face_cover"] = round(1.0 - found.best.backward, 4)
    out["settle_deg"] = round(
        float(np.degrees(np.arccos(np.clip((np.trace(settle[:3, :3]) - 1) / 2, -1.0, 1.0)))), 2
    )
    face = face_mask(head.meshes["cranium"].vertices)
    out["face_observed"] = round(float(np.mean(observed["cranium"][face] > OBSERVED_WEIGHT)), 4)
    gaps = []
    for code in BILATERAL + ("po", "or"):
        left, right = carried.get(f"{code}_l"), carried.get(f"{code}_r")
        if left is None or right is None:
            continue
        if min(support.get(f"{code}_l", 0.0), support.get(f"{code}_r", 0.0)) < OBSERVED_WEIGHT:
            continue
        gaps.append(float(np.linalg.norm(left - right * np.array([-1.0, 1.0, 1.0]))))
    out["asymmetry_mm"] = round(float(np.median(gaps)), 2) if gaps else None
    out["jaw_shift_mm"] = round(float(np.linalg.norm(jaw.shift_mm)), 2) if jaw.present else None
    return out


def _register(
    skull: Mesh,
    head: TemplateHead,
    *,
    hint: tuple | None = None,
    seeds: LandmarkSet | None = None,
    mirror: str = "auto",
    progress: Progress | None = None,
    candidate: int | None = None,
) -> SkullRegistration:
    """Orientation, then the registration from its best pose; see :func:`register_skull`.

    From the bone alone, a registration whose orientation the self-check
    doubts is done again from the search's runner-up poses that scored nearly
    as well (at most :data:`SECOND_OPINIONS`, within
    :data:`SECOND_OPINION_COST`); a runner-up replaces it only when it is
    judged better (not doubted, or no longer refused).  ``candidate``
    (calibration only) forces one pose.
    """
    say = progress or (lambda _m: None)
    t0 = time.perf_counter()
    if skull.n_faces < 100:
        raise InputError("skull", f"has only {skull.n_faces} triangles; a skull surface is needed")
    ref_lms = head.skull_landmarks.as_dict()
    seed_pairs = None
    placed = (
        {}
        if seeds is None
        else {lm.code: lm.position for lm in seeds if lm.status == "placed" and lm.code in ref_lms}
    )
    if len(placed) >= 3:
        codes = sorted(placed)
        seed_pairs = (np.array([placed[c] for c in codes]), np.array([ref_lms[c] for c in codes]))
    say("orienting the skull ...")
    # pieces that are not bone (a CT table, a head holder) take no part
    pieces = judge_pieces(skull)
    gone = apparatus_faces(skull, pieces)
    bone, not_bone = skull, None
    if gone.any():
        bone = Mesh(skull.vertices, skull.faces[~gone])
        not_bone = np.ones(skull.n_vertices, bool)
        not_bone[skull.faces[~gone].ravel()] = False
    found: SkullPoseResult | None = None
    if seed_pairs is None:
        from workbench.core.skull_pose import as_pose_result, search_skull_pose

        found = search_skull_pose(
            bone,
            concatenate([head.meshes["cranium"], head.meshes["upper_teeth"]]),
            concatenate([head.meshes["mandible"], head.meshes["lower_teeth"]]),
            head.tmj_axis,
            hint=hint,
            mirror="yes" if mirror == "yes" else "no",
        )
        if candidate is not None:  # calibration of the self-check: a runner-up on purpose
            found = replace(found, candidates=found.candidates[candidate:])
        pose = as_pose_result(found, "search" if hint is None else "hint")
    else:
        ref_full = concatenate([head.meshes[p] for p in PART_OF])
        pose = search_pose(bone, ref_full, hint=hint, seeds=seed_pairs, mirror=mirror)
    oriented = time.perf_counter() - t0
    notes = tuple(
        f"a piece of the surface that is not bone was left out: {p.describe()}"
        for p in pieces
        if p.apparatus
    )
    first = _register_from_pose(skull, head, pose, found, placed, seeds, say, not_bone, notes)
    if pose.method != "search" or candidate is not None or not _doubted(first):
        return _finish(first, oriented, t0)
    tried = [first]
    # only runner-ups the search found nearly as good: a post-hoc figure must not overrule
    # a clear search (VHP male at 700 HU: the right pose's thin face kept 78 % of the face
    # skeleton on bone, a pose 40° off and 0.08 worse in the search 80 %)
    rivals = [a for a in pose.alternatives if a.cost <= pose.cost + SECOND_OPINION_COST]
    for i, alt in enumerate(rivals[:SECOND_OPINIONS], start=1):
        say(f"second opinion: the search's runner-up pose {i} ...")
        other = replace(found, candidates=found.candidates[i:]) if found is not None else None
        tried.append(
            _register_from_pose(skull, head, alt, other, placed, seeds, say, not_bone, notes)
        )
    # a runner-up replaces the best-scoring pose only when it is judged better: not doubted,
    # or refused no longer; between equals the search's own order stands
    best = min(tried, key=lambda r: (_doubted(r), _rank(r)))
    if best is not first:
        note = (
            "orientation from the bone alone: the best-scoring pose did not pass the "
            f"self-check ({first.figures['self_check']['reasons'][0]}); a runner-up pose did "
            "better and was used"
        )
        best = replace(best, warnings=(note, *best.warnings))
    return _finish(best, oriented, t0)


#: runner-up poses registered when the best one's orientation is doubted, if their search
#: cost is within SECOND_OPINION_COST of the best's (wrong poses scored 0.036-0.067 worse on
#: the development cases)
SECOND_OPINIONS = 2
SECOND_OPINION_COST = 0.03


def _doubted(reg: SkullRegistration) -> bool:
    return bool(reg.figures["self_check"].get("orientation_doubt"))


def _rank(reg: SkullRegistration) -> int:
    from workbench.services.registration.skull_check import OUTCOMES

    return OUTCOMES.index(reg.figures["self_check"]["outcome"])


def _finish(reg: SkullRegistration, oriented: float, t0: float) -> SkullRegistration:
    """Times into the figures; a refused registration raises (the self-check's message)."""
    from workbench.services.registration.skull_check import SelfCheck, refusal

    seconds = dict(reg.figures["seconds"])
    seconds["orientation"] = round(oriented, 3)
    seconds["total"] = round(time.perf_counter() - t0, 3)
    figures = {**reg.figures, "seconds": seconds}
    check = reg.figures["self_check"]
    if check["outcome"] == "refused":
        raise refusal(SelfCheck(check["outcome"], tuple(check["reasons"])), "skull")
    return replace(reg, figures=figures)


def _register_from_pose(
    skull: Mesh,
    head: TemplateHead,
    pose: PoseResult,
    found: SkullPoseResult | None,
    placed: Mapping[str, np.ndarray],
    seeds: LandmarkSet | None,
    say: Progress,
    not_bone: np.ndarray | None = None,
    notes: tuple[str, ...] = (),
) -> SkullRegistration:
    """The registration of ``head``'s skull onto ``skull`` from one orientation ``pose``;
    ``not_bone`` marks the vertices of pieces left out (said in ``notes``)."""
    from workbench.services.registration.skull_check import judge

    t0 = time.perf_counter()
    seconds: dict[str, float] = {}
    warnings: list[str] = []
    say("posing the mandible ...")
    t = time.perf_counter()
    warnings += notes
    placed_jaw = _orient_and_pose_jaw(skull, head, pose, not_bone)
    seconds["mandible"] = time.perf_counter() - t
    rigid, mirrored, k = placed_jaw.rigid, placed_jaw.mirrored, placed_jaw.k
    jaw = placed_jaw.jaw
    if not jaw.present:
        warnings.append(
            f"no mandible found (only {100 * jaw.support:.0f} % of the reference "
            "mandible finds bone): it follows the cranium and the lower face is "
            "inferred from the reference"
            + (
                "; the skull was oriented from the bone alone, so if it has a mandible "
                "the orientation is wrong: give one"
                if pose.method == "search"
                else ""
            )
        )
    say("registering the reference skull onto the bone ...")
    t = time.perf_counter()
    fit = _fit_parts(head, placed_jaw, placed if seeds is not None else {})
    seconds["nonrigid"] = time.perf_counter() - t
    reports = _part_reports(fit.observed, jaw.present)

    carried, support = _carry_landmarks(head, fit.rest, fit.moved, fit.observed, k)
    settle = _target_frame(carried, support, warnings)
    input_to_head = settle @ rigid
    moved = {p: Mesh(apply_points(settle, m.vertices), m.faces) for p, m in fit.moved.items()}
    rest = {p: Mesh(apply_points(settle, m.vertices), m.faces) for p, m in fit.rest.items()}
    target_h = Mesh(apply_points(settle, placed_jaw.target_h.vertices), placed_jaw.target_h.faces)
    carried = {c: apply_points(settle, p[None])[0] for c, p in carried.items()}
    landmarks = _input_landmarks(head, carried, support, placed, np.linalg.inv(input_to_head))
    axis = np.vstack([k * head.tmj_axis[0], head.tmj_axis[1]])
    measures = _check_measures(
        head, found, input_to_head, settle, carried, support, fit.observed, jaw, k
    )
    check = judge(measures, pose.method, jaw.figures())
    seconds["total"] = time.perf_counter() - t0
    figures = {
        "orientation": {
            "method": pose.method,
            "cost": round(pose.cost, 4),
            "matched_fraction": round(pose.matched_fraction, 4),
            "handedness": pose.handedness,
            "mirrored": mirrored,
            "reference_scale": round(k, 4),
            # a search's next-best distinct poses: how close the call was
            "alternative_costs": [round(a.cost, 4) for a in pose.alternatives],
        },
        "mandible_pose_fraction": round(jaw.support, 4),
        "jaw": jaw.figures(),
        "check_measures": measures,
        "self_check": check.to_dict(),
        "observed_fraction": {r.name: r.observed_fraction for r in reports},
        "median_observed_distance_mm": _median_observed_distance(fit.reg),
        "iterations": fit.reg.iterations,
        **placed_jaw.tfig,
        "seconds": {kk: round(v, 3) for kk, v in seconds.items()},
    }
    _add_input_warnings(pose, mirrored, placed_jaw.tfig, figures, warnings)
    return SkullRegistration(
        input_to_head,
        mirrored,
        k,
        moved,
        rest,
        fit.observed,
        landmarks,
        carried,
        target_h,
        placed_jaw.weights,
        tuple(reports),
        pose,
        settle,
        figures,
        tuple(warnings),
        jaw.transformed(settle),
        np.vstack([apply_points(settle, axis[0])[0], settle[:3, :3] @ axis[1]]),
    )


@dataclass(frozen=True)
class _PartsFit:
    """The non-rigid registration of the reference skull parts (oriented reference frame, mm)."""

    reg: Registration
    moved: dict[str, Mesh]  # per part: registered onto the bone
    rest: dict[str, Mesh]  # per part: the scaled reference layout before the jaw pose
    observed: dict[str, np.ndarray]  # per part, per vertex: weight 0..1 of the match to bone


def _fit_parts(
    head: TemplateHead, placed_jaw: _Placed, placed: Mapping[str, np.ndarray]
) -> _PartsFit:
    """Register the reference parts onto the oriented target, both parts at once.

    Without a mandible the jaw's parts move with the cranium and take no
    part (inactive, never observed).  ``placed`` (user landmarks, input frame,
    mm) become hard constraints on the reference vertices nearest their
    scaled reference positions.
    """
    parts, k, mandible_present = placed_jaw.parts, placed_jaw.k, placed_jaw.jaw.present
    names = list(PART_OF)
    src = concatenate([parts[p] for p in names])
    offsets = np.cumsum([0] + [parts[p].n_vertices for p in names])
    labels = np.concatenate(
        [np.full(parts[p].n_vertices, PART_OF[p] if mandible_present else 0) for p in names]
    )
    active = np.ones(src.n_vertices, bool)
    if not mandible_present:
        for p in ("mandible", "lower_teeth"):
            i = names.index(p)
            active[offsets[i] : offsets[i + 1]] = False
    hard = None
    if placed:
        ref_lms = head.skull_landmarks.as_dict()
        tree_src = cKDTree(src.vertices)
        ids = []
        pts = []
        for code, pos in placed.items():
            _, vid = tree_src.query(k * ref_lms[code])
            ids.append(int(vid))
            pts.append(apply_points(placed_jaw.rigid, pos[None])[0])
        hard = (np.array(ids), np.array(pts))
    reg: Registration = register(src, placed_jaw.target, parts=labels, active=active, hard=hard)
    moved, observed, rest = {}, {}, {}
    for i, p in enumerate(names):
        sl = slice(offsets[i], offsets[i + 1])
        moved[p] = Mesh(reg.vertices[sl], parts[p].faces)
        rest[p] = placed_jaw.layout[p]
        observed[p] = np.where(active[sl], reg.weights[sl], 0.0)
    return _PartsFit(reg, moved, rest, observed)


def _part_reports(observed: Mapping[str, np.ndarray], mandible_present: bool) -> list[PartReport]:
    """Cranium and mandible (each with its teeth): observed fraction and presence."""
    reports = []
    for part, members in (
        ("cranium", ("cranium", "upper_teeth")),
        ("mandible", ("mandible", "lower_teeth")),
    ):
        frac = float(np.mean(np.concatenate([observed[m] for m in members]) > OBSERVED_WEIGHT))
        present = part == "cranium" or mandible_present
        note = "" if present else "missing: follows the cranium (inferred)"
        reports.append(PartReport(part, present, round(frac, 4), note))
    return reports


def _target_frame(
    carried: Mapping[str, np.ndarray], support: Mapping[str, float], warnings: list[str]
) -> np.ndarray:
    """The settle (4 x 4) into the target's own Frankfort frame from the registered porions
    and orbitales (oriented reference frame → head frame, mm); the identity when they give
    none.  Frankfort points not on observed bone are named in ``warnings``."""
    fh_set = LandmarkSet("skull", tuple(Landmark(c, carried[c], "suggested", 1.0) for c in carried))
    inferred_fh = [c for c in FH_CODES if support.get(c, 0.0) < OBSERVED_WEIGHT]
    if inferred_fh:
        warnings.append(
            "Frankfort Horizontal from the registered reference: "
            + ", ".join(inferred_fh)
            + " not on observed bone (inferred)"
        )
    fh = head_frame_from_landmarks(fh_set).input_to_head
    return fh if np.isfinite(fh).all() else np.eye(4)


def _input_landmarks(
    head: TemplateHead,
    carried: Mapping[str, np.ndarray],
    support: Mapping[str, float],
    placed: Mapping[str, np.ndarray],
    back: np.ndarray,
) -> LandmarkSet:
    """The skull landmarks in the input frame (``back``: head frame → input, mm).

    A landmark the user placed stays as placed; a carried one on observed
    bone is suggested with its support as confidence; one over missing bone
    is absent (its carried position stays in the registration's
    ``inferred``).
    """
    lms = []
    for lm in head.skull_landmarks:
        if lm.code not in carried:
            continue
        sup = support[lm.code]
        if lm.code in placed:
            lms.append(Landmark(lm.code, placed[lm.code], "placed", 1.0, lm.description))
        elif sup >= OBSERVED_WEIGHT:
            lms.append(
                Landmark(
                    lm.code,
                    apply_points(back, carried[lm.code][None])[0],
                    "suggested",
                    round(min(1.0, sup), 3),
                    "from the dense skull registration",
                )
            )
        else:
            lms.append(
                Landmark(
                    lm.code,
                    np.full(3, np.nan),
                    "absent",
                    0.0,
                    "no bone under the registered reference (inferred position "
                    "kept by the registration)",
                )
            )
    return LandmarkSet("skull", tuple(lms))


def _median_observed_distance(reg: Registration) -> float:
    """Median distance (mm) of the observed registered vertices to the bone (NaN: none)."""
    return round(
        float(np.median(reg.distances[reg.weights > OBSERVED_WEIGHT]))
        if (reg.weights > OBSERVED_WEIGHT).any()
        else float("nan"),
        3,
    )


def _add_input_warnings(
    pose: PoseResult, mirrored: bool, tfig: Mapping[str, Any], figures: dict, warnings: list[str]
) -> None:
    """Warnings (and the orientation's handedness note) about the input file itself: a
    mirrored file, an assumed handedness, much bone surface far from any skull part."""
    if mirrored:
        warnings.append(
            "the input is mirrored (left-handed coordinates): the head frame "
            "includes a reflection, and results are mapped back the same way"
        )
    if pose.handedness == "assumed":
        figures["orientation"]["handedness_note"] = (
            "a skull is nearly symmetric, so its shape cannot tell a mirrored file; the file's "
            "handedness was kept (give an orientation with 'left' or left/right landmarks)"
        )
    if tfig["target_extra_area_fraction"] > 0.02:
        warnings.append(
            f"{100 * tfig['target_extra_area_fraction']:.0f} % of the bone surface "
            "lies far from any skull part (C-spine, hyoid, apparatus, debris) and "
            "was ignored"
        )
