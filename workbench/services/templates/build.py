"""Adapt the built-in reference head to one person's skin and skull surfaces (a template pack).

Kähler (2003, §8.4.1) fits the reference head to a scan by a landmark warp,
refines the correspondences automatically, warps again, and lets skull and
muscles follow.  For a person whose skin *and* skull are known (the two
iso-surfaces of one CT) we do this densely, with the machinery of the skull
→ face reconstruction (issue 11), so that a pack reconstructs its own CT:

1. **Skull** (:func:`workbench.services.registration.skull_registration.register_skull`):
   the reference skull registered part by part onto the bone — orientation
   from the bone, an orientation hint or the user's landmarks, the mandible
   with its own pose, missing parts inferred — in the target's own
   Frankfort head frame (mm, the person's size; a mirrored scan gets a
   reflection).
2. **Carry**: the whole head follows the skull's displacement field.
3. **Skin** (:func:`workbench.core.nonrigid.register`): the carried skin
   registered onto the CT skin, coarse to fine.  The CT skin's hole and
   field-of-view rims fade out, and so does everything far from the
   carried head (shoulders, head holders, gel pads, the table:
   :data:`SKIN_EXTRA_MM`), so the face and head are kept and the rest
   dropped; the simplified ears do not look for the scan; skin over no
   scan keeps the reference's shape (membrane).  Skin closer than
   :data:`MIN_TISSUE_MM` to the skull is pushed out.
4. **Landmarks** ride on their surfaces (same triangle, same barycentric
   weights): skull landmarks with the registered skull, skin landmarks
   with the registered skin.  Those over no bone or no scan are *absent on
   the target* and keep their carried positions.

Units mm; head frame of the *target* (x to the subject's left, x = 0
midsagittal, y up, z toward the face, Frankfort Horizontal at y = 0).
``provenance["input_to_head"]`` maps the input files' coordinates into it.
The checks of the skin and skull pair before a build are in
:mod:`workbench.services.templates.pair_checks`.
"""

from __future__ import annotations

import hashlib
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from os import PathLike
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from workbench.core.errors import InputError
from workbench.core.frame import apply_transform
from workbench.core.landmarks import Landmark, LandmarkSet
from workbench.core.mesh import Mesh, boundary_loops, concatenate
from workbench.core.nonrigid import Level, Registration, Target, register, smoothstep
from workbench.core.spatial import MeshIndex
from workbench.core.threads import worker_count
from workbench.model.evidence import file_sha256
from workbench.model.template import TemplateHead
from workbench.services.registration.skull_registration import SkullRegistration
from workbench.services.templates.pair_checks import (
    check_distinct_inputs,
    check_not_swapped,
    check_skin_fits_skull,
    measure_pair,
    vertex_mask,
)

MIN_TISSUE_MM = 1.0  #: skin kept at least this far outside the skull
#: skin not registered (the simplified ears do not match a real one) / not pushed off the bone
UNPROJECTED_REGIONS = ("ear_l", "ear_r")
NO_CLEARANCE_REGIONS = ("neck",)
SKULL_PARTS = ("cranium", "mandible", "upper_teeth", "lower_teeth")
#: bone surfaces larger than this are decimated to WORKING_TRIANGLES for the registration
MAX_WORKING_TRIANGLES = 250_000
WORKING_TRIANGLES = 200_000
#: CT skin farther than SKIN_EXTRA_MM[0] from the carried head starts to fade, beyond [1] it
#: is not the head (shoulders, head holder, gel, table)
SKIN_EXTRA_MM = (12.0, 25.0)
#: CT skin this close to a hole or field-of-view rim fades out (mm)
SKIN_RIM_MM = 4.0
#: a skin vertex is "on the scan" when its final match weight exceeds this
ON_SCAN_WEIGHT = 0.3
#: the skin registration's levels (spacing, stiffness, robust scale, iterations)
SKIN_LEVELS = (
    Level(24.0, 1.0, 8.0, 6),
    Level(14.0, 0.6, 5.0, 6),
    Level(8.0, 0.4, 3.0, 6),
    Level(5.0, 0.3, 2.0, 6),
    Level(3.5, 0.25, 1.5, 5),
)


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
    registration : SkullRegistration
        The skull registration (frame, parts, observed bone).
    skin_on_scan : (n_skin,) bool
        Skin vertices the scan supports (the rest keep the reference's shape).
    figures : dict
        Fractions on the scan and the bone, distances (mm), seconds.
    """

    head: TemplateHead
    input_to_head: np.ndarray
    mirrored_input: bool
    registration: SkullRegistration
    skin_on_scan: np.ndarray
    figures: dict
    warnings: tuple[str, ...] = ()

    def to_input(self, points: np.ndarray) -> np.ndarray:
        """Head-frame points back in the input files' coordinates."""
        return _apply(np.linalg.inv(self.input_to_head), points)


def _apply(m: np.ndarray, p: np.ndarray) -> np.ndarray:
    return apply_transform(m, np.reshape(p, (-1, 3)))


def _push_out(skin: Mesh, skull: Mesh, exclude: np.ndarray) -> tuple[np.ndarray, int, float]:
    """Skin vertices closer than :data:`MIN_TISSUE_MM` to ``skull`` moved out to it (mm).

    Returns the new vertices, how many were too close and the smallest tissue
    before.  One push from the closest point is not enough where the bone is
    concave (a vertex put 1 mm off one face can end closer to the next), so
    this repeats for :data:`PUSH_ROUNDS`.  Only the vertices too close move:
    their neighbours lie on the person's own CT skin and stay there.
    """
    index = MeshIndex(skull)
    v = skin.vertices.copy()
    too_close = np.zeros(len(v), bool)
    before = 0.0
    for round_ in range(PUSH_ROUNDS):
        cp, signed = index.signed_closest_points(v)
        if round_ == 0:
            before = float(signed[~exclude].min())
        thin = (signed < MIN_TISSUE_MM) & ~exclude & (cp.distances < 30.0)
        if not thin.any():
            break
        too_close |= thin
        normals = index.pseudo_normals(cp.face_ids[thin], cp.barycentric[thin])
        out = v[thin] - cp.points[thin]
        out /= np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-9)
        out = np.where(signed[thin, None] > 0.05, out, normals)
        # a hair more than the minimum, so a vertex at it is not pushed again for rounding
        v[thin] = cp.points[thin] + (MIN_TISSUE_MM + 0.01) * out
    return v, int(too_close.sum()), before


#: rounds of push-out while skin is closer than MIN_TISSUE_MM to the skull
PUSH_ROUNDS = 8


def skin_target_weights(skin_h: Mesh, head_skin: Mesh) -> tuple[np.ndarray, float]:
    """Per CT-skin vertex belief: rims and everything far from the carried head fade out.

    Returns the weights and the area fraction of the scan that is not the head.
    """
    w = np.ones(skin_h.n_vertices)
    loops = boundary_loops(skin_h)
    if loops:
        rim = np.concatenate(loops)
        d, _ = cKDTree(skin_h.vertices[rim]).query(skin_h.vertices, workers=worker_count())
        w *= smoothstep(d / SKIN_RIM_MM)
    # the exact distance matters only between the two bounds: the nearest skin vertex is
    # an upper bound of it, that less the longest skin edge a lower one (a point of a
    # triangle lies within its longest edge of a corner); the same weights, ~0.5 s less
    # on a 300k-vertex scan
    corners = head_skin.vertices[np.unique(head_skin.faces)]
    d, _ = cKDTree(corners).query(skin_h.vertices, workers=worker_count())
    ends = head_skin.vertices[head_skin.edges_unique]
    longest = float(np.linalg.norm(ends[:, 1] - ends[:, 0], axis=1).max())
    middle = np.flatnonzero((d > SKIN_EXTRA_MM[0]) & (d - longest < SKIN_EXTRA_MM[1]))
    if len(middle):
        d[middle] = MeshIndex(head_skin).closest_points(skin_h.vertices[middle]).distances
    extra = 1.0 - smoothstep((d - SKIN_EXTRA_MM[0]) / (SKIN_EXTRA_MM[1] - SKIN_EXTRA_MM[0]))
    areas = np.zeros(skin_h.n_vertices)
    np.add.at(areas, skin_h.faces.ravel(), np.repeat(skin_h.face_areas / 3.0, 3))
    return w * extra, float(areas[extra < 0.5].sum() / max(areas.sum(), 1e-12))


def _carry_on(base_mesh: Mesh, new_mesh: Mesh, points: np.ndarray) -> np.ndarray:
    """Points on (or near) ``base_mesh`` moved with it to ``new_mesh`` (same topology)."""
    cp = MeshIndex(base_mesh).closest_points(points)
    tri = new_mesh.vertices[base_mesh.faces[cp.face_ids]]
    return np.einsum("ij,ijk->ik", cp.barycentric, tri) + (points - cp.points)


ABSENT_NOTE = "absent on the target surface: position carried by the warp, not measured"


@dataclass(frozen=True)
class SkinFit:
    """The reference skin registered onto a skin scan (head frame, mm).

    Attributes
    ----------
    registration : Registration
        ``vertices`` (the fitted skin), per-vertex match ``weights`` and distances.
    on_scan : (n_skin,) bool
        Skin vertices the scan supports (weight > :data:`ON_SCAN_WEIGHT`).
    target_weights : (n_scan,)
        Per scan vertex belief (:func:`skin_target_weights`).
    not_head : float
        Area fraction of the scan that is not the head.
    """

    registration: Registration
    on_scan: np.ndarray
    target_weights: np.ndarray
    not_head: float
    warnings: tuple[str, ...] = ()


def scan_in_frame(scan: Mesh, to_head: np.ndarray, mirrored: bool) -> Mesh:
    """``scan`` mapped by ``to_head`` (input → head frame, mm, rigid, a reflection when
    ``mirrored``), wound outward; a rigid copy (:meth:`Mesh.transformed`), so search
    structures built on ``scan`` serve it too."""
    moved = scan.transformed(to_head)  # (winding flipped when to_head reflects)
    if bool(np.linalg.det(np.asarray(to_head, float)[:3, :3]) < 0) != mirrored:
        moved = moved.reversed_winding()
    return moved.outward()


def fit_skin(
    skin: Mesh,
    scan_h: Mesh,
    regions: Mapping[str, np.ndarray],
    *,
    levels: Sequence[Level] = SKIN_LEVELS,
    affine_rounds: int = 0,
    source: str = "skin",
    near: str = "the reference head",
    hint: str | None = None,
    belief: np.ndarray | None = None,
    hard: tuple[np.ndarray, np.ndarray] | None = None,
    ears: bool = False,
    index: MeshIndex | None = None,
) -> SkinFit:
    """Register ``skin`` (the reference skin placed in the head frame) onto ``scan_h``.

    Both in the head frame, mm.  Hole and field-of-view rims of the scan and
    everything far from ``skin`` fade out (:func:`skin_target_weights`), the
    ears (:data:`UNPROJECTED_REGIONS` of ``regions``) do not look for the
    scan unless ``ears`` (a CT's ears are often pressed flat by the head
    holder, a range scan's are usually whole), and skin over no scan keeps
    the reference's shape (membrane).

    ``belief`` (per scan vertex, 0..1) multiplies the scan's weights, e.g.
    0 for walls of a cavity no scanner sees (:mod:`workbench.core.visibility`).
    ``hard`` (skin vertex ids, head-frame points) are pulled onto those points
    (landmarks a user placed).  ``index`` is ``scan_h``'s, when the caller has one
    (building it takes ~1 s for 300k triangles).

    Raises
    ------
    InputError
        (naming ``source``) when no part of the scan lies near ``skin``.
    """
    weights, not_head = skin_target_weights(scan_h, skin)
    if belief is not None:
        weights = weights * np.clip(np.asarray(belief, float), 0.0, 1.0)
    if not (weights > 0.05).any():
        raise InputError(source, f"no part of the skin surface lies near {near}", hint=hint)
    warnings = []
    if not_head > 0.02:
        warnings.append(
            f"{100 * not_head:.0f} % of the skin scan is not the head (shoulders, "
            "head holder, gel, table) and was ignored"
        )
    unprojected = () if ears else UNPROJECTED_REGIONS
    passive = vertex_mask(skin.n_vertices, [regions[r] for r in unprojected if r in regions])
    target = Target(scan_h, weights, pull_stride=max(1, int((weights > 0.05).sum()) // 8000))
    if index is not None:
        target.use_index(index)
    sreg = register(
        skin, target, levels=levels, active=~passive, affine_rounds=affine_rounds, hard=hard
    )
    return SkinFit(sreg, sreg.weights > ON_SCAN_WEIGHT, weights, not_head, tuple(warnings))


def carry_skin_landmarks(
    rest_skin: Mesh, new_skin: Mesh, landmarks: LandmarkSet, on_scan: np.ndarray
) -> tuple[LandmarkSet, list[str]]:
    """Skin ``landmarks`` (on ``rest_skin``) moved with the skin to ``new_skin`` (same
    topology, head frame, mm): same triangle, same barycentric weights.

    Landmarks over skin the scan does not support (``on_scan``) are *absent on
    the target*: they keep the carried position with :data:`ABSENT_NOTE`.
    Returns the set and the absent codes.
    """
    codes = [lm.code for lm in landmarks if lm.is_defined]
    if not codes:
        return landmarks, []
    pos = landmarks.positions_of(codes)
    moved = _carry_on(rest_skin, new_skin, pos)
    support = _carry_on(
        rest_skin, rest_skin.with_vertices(np.column_stack([on_scan.astype(float)] * 3)), pos
    )[:, 0]
    absent = [c for c, s_ in zip(codes, support, strict=True) if s_ < 0.5]
    new_pos = dict(zip(codes, moved, strict=True))
    out = LandmarkSet(
        landmarks.surface,
        tuple(
            Landmark(
                lm.code,
                new_pos[lm.code],
                lm.status,
                lm.confidence,
                ABSENT_NOTE if lm.code in absent else lm.description,
            )
            if lm.code in new_pos
            else lm
            for lm in landmarks
        ),
    )
    return out, absent


#: changes whenever the build method does (a cached pack of another version is rebuilt)
BUILD_VERSION = 2


def eyes_behind_lids(
    carried: TemplateHead, skin_v: np.ndarray, on_scan: np.ndarray
) -> dict[int, np.ndarray]:
    """Moves (mm, along z of the head frame) putting each eyeball behind the scanned lids.

    The eyeballs come with the skull's field, the lids with the skin scan;
    a globe keeps the reference's depth relative to its palpebral opening
    (corneal apex minus the opening's mean z), measured on the carried head.
    Eyes whose opening the scan does not show stay where they are.
    """
    eyes = carried.meshes.get("eyes")
    if eyes is None:
        return {}
    owner = np.linalg.norm(eyes.vertices[:, None] - carried.eye_centres[None], axis=2).argmin(1)
    moves = {}
    for i in range(len(carried.eye_centres)):
        side = "l" if carried.eye_centres[i, 0] > 0 else "r"
        loop = carried.openings.get(f"eye_{side}")
        if loop is None or not (owner == i).any():
            continue
        loop = np.asarray(loop, dtype=np.int64)
        if on_scan[loop].mean() < 0.5:
            continue
        apex = float(eyes.vertices[owner == i, 2].max())
        gap = apex - float(carried.skin.vertices[loop, 2].mean())
        moves[i] = np.array([0.0, 0.0, float(skin_v[loop, 2].mean()) + gap - apex])
    return moves


# ------------------------------------------------------------------ entry points
def build_template(
    skin: Mesh,
    skull: Mesh,
    base: TemplateHead,
    *,
    skin_seeds: LandmarkSet | None = None,
    skull_seeds: LandmarkSet | None = None,
    orientation: tuple | None = None,
    inputs: Sequence[Mapping] = (),
    progress: Progress | None = None,
) -> BuildResult:
    """Adapt ``base`` (head frame) to ``skin`` and ``skull`` (one input frame, mm).

    ``skin``/``skull`` may have holes, a cut field of view and extra
    anatomy; ``skull_seeds`` are skull landmarks placed by hand (input frame,
    hard constraints; ``skin_seeds`` are recorded only); ``orientation`` =
    (anterior, superior[, left]) in the input frame; ``inputs`` =
    ``{"role", "file", "sha256"}`` per input file (recorded in the
    provenance, hashed into the template id).
    """
    from workbench.services.registration.skull_registration import (
        mirror_from_landmarks,
        reference_in_frame,
        register_skull,
    )

    say = progress or (lambda _m: None)
    t0 = time.perf_counter()
    seconds: dict[str, float] = {}
    if skull.n_faces > MAX_WORKING_TRIANGLES:
        from workbench.core.isosurface import decimate

        say(f"decimating the bone {skull.n_faces} -> {WORKING_TRIANGLES} triangles ...")
        skull = Mesh(*decimate(skull.vertices, skull.faces, WORKING_TRIANGLES))
    reg = register_skull(
        skull,
        base,
        hint=orientation,
        seeds=skull_seeds,
        mirror=mirror_from_landmarks(skull_seeds),
        progress=say,
    )
    to_head, mirrored = reg.input_to_head, reg.mirrored
    warnings = list(reg.warnings)
    seconds["skull"] = time.perf_counter() - t0

    t = time.perf_counter()
    say("carrying the reference head and registering its skin onto the scan ...")
    stage = _skin_onto_scan(base, reg, skin)
    warnings += stage.fit.warnings
    carried, on_scan, meshes = stage.carried, stage.fit.on_scan, dict(stage.carried.meshes)
    seconds["skin"] = time.perf_counter() - t

    # landmarks: skull with the registered skull, skin with the registered skin
    absent_skull = [lm.code for lm in reg.landmarks if not lm.is_defined]
    skull_lms = _skull_landmarks(base, reg, absent_skull)
    rest = reference_in_frame(base, reg)
    skin_lms, absent_skin = carry_skin_landmarks(
        rest.skin, meshes["skin"], rest.skin_landmarks, on_scan
    )
    head = replace(carried, meshes=meshes, skin_landmarks=skin_lms, skull_landmarks=skull_lms)

    figures = _build_figures(base, reg, stage)
    seconds["total"] = time.perf_counter() - t0
    figures["seconds"] = {k: round(v, 2) for k, v in seconds.items()}
    digest = hashlib.sha256(
        "".join(str(i.get("sha256", "")) for i in inputs).encode() + base.content_hash.encode()
    ).hexdigest()[:12]
    provenance = {
        "built_from": [dict(i) for i in inputs],
        "base_template": {"template_id": base.template_id, "content_hash": base.content_hash},
        "method": "dense registration of the reference skull onto the bone (per part), the head "
        "carried by the skull's displacement field, the skin registered onto the skin "
        "scan (rims and non-head parts faded out, the reference's shape over holes)",
        "frame": "the target's head frame (Frankfort Horizontal from its registered porions and "
        "orbitales), mm",
        "input_to_head": to_head,
        "mirrored_input": bool(mirrored),
        "skull_parts": {
            p.name: {"present": p.present, "observed_fraction": p.observed_fraction}
            for p in reg.parts
        },
        "absent_landmarks": {"skull": absent_skull, "skin": absent_skin},
        "seeds": {
            "skull": [] if skull_seeds is None else list(skull_seeds.codes),
            "skin": [] if skin_seeds is None else list(skin_seeds.codes),
        },
        "settings": {
            "min_tissue_mm": MIN_TISSUE_MM,
            "skin_extra_mm": list(SKIN_EXTRA_MM),
            "skin_rim_mm": SKIN_RIM_MM,
        },
        "figures": figures,
        "warnings": list(warnings),
        "build_version": BUILD_VERSION,
    }
    head = replace(head, template_id=f"{base.template_id}/built/{digest}", provenance=provenance)
    return BuildResult(head, to_head, bool(mirrored), reg, on_scan, figures, tuple(warnings))


@dataclass(frozen=True)
class _SkinStage:
    """The reference head carried onto the registered skull with its skin on the scan
    (target's head frame, mm)."""

    carried: TemplateHead  # registered skull parts, skin on the scan, eyes behind the lids
    skin_h: Mesh  # the skin scan in the head frame
    fit: SkinFit  # the skin registration
    skin_v: np.ndarray  # the registered skin's vertices after the push out of the skull
    pushed: int  # skin vertices closer than MIN_TISSUE_MM to the skull (pushed out)
    min_tissue: float  # the smallest skin-to-skull distance before the push (mm)
    eye_shift: dict  # per eye: its shift (mm) behind the lids


def _skin_onto_scan(base: TemplateHead, reg: SkullRegistration, skin: Mesh) -> _SkinStage:
    """Carry ``base`` by the skull registration ``reg`` and register its skin onto ``skin``
    (input frame, mm).

    The registered cranium (and mandible, when present) replace the carried
    ones; the registered skin is pushed at least :data:`MIN_TISSUE_MM` out of
    the skull (neck and openings excepted) and the eyes are moved behind the
    lids.
    """
    from workbench.services.registration.skull_registration import carry_head

    carried = carry_head(base, reg)
    skin_h = scan_in_frame(skin, reg.input_to_head, reg.mirrored)
    fit = fit_skin(
        carried.skin,
        skin_h,
        base.regions,
        source="skin",
        near="the head carried onto the skull",
        hint="are skin and skull in the same frame and units?",
    )
    meshes = dict(carried.meshes)
    meshes["cranium"] = reg.meshes["cranium"]
    if reg.part("mandible").present:
        meshes["mandible"] = reg.meshes["mandible"]
    keep = [base.regions[r] for r in NO_CLEARANCE_REGIONS if r in base.regions]
    skin_v, pushed, min_tissue = _push_out(
        carried.skin.with_vertices(fit.registration.vertices),
        concatenate([meshes[p] for p in SKULL_PARTS]),
        vertex_mask(base.skin.n_vertices, keep + list(base.openings.values())),
    )
    meshes["skin"] = carried.skin.with_vertices(skin_v)
    eye_shift = eyes_behind_lids(carried, skin_v, fit.on_scan)
    carried = replace(carried, meshes=meshes).with_eyes_moved(eye_shift)
    return _SkinStage(carried, skin_h, fit, skin_v, pushed, min_tissue, eye_shift)


def _skull_landmarks(
    base: TemplateHead, reg: SkullRegistration, absent_skull: Sequence[str]
) -> LandmarkSet:
    """``base``'s skull landmarks at their registered places (head frame, mm); those absent
    on the bone keep the carried place with :data:`ABSENT_NOTE`."""
    return LandmarkSet(
        "skull",
        tuple(
            Landmark(
                lm.code,
                reg.inferred[lm.code],
                lm.status,
                lm.confidence,
                ABSENT_NOTE if lm.code in absent_skull else lm.description,
            )
            if lm.is_defined and lm.code in reg.inferred
            else lm
            for lm in base.skull_landmarks
        ),
    )


def _build_figures(base: TemplateHead, reg: SkullRegistration, stage: _SkinStage) -> dict:
    """How well the built head matches its scan: fractions on the scan and the bone, the
    face's distances to the skin scan away from its rims (mm), the push and eye shifts."""
    on_scan, skin_h, skin_v = stage.fit.on_scan, stage.skin_h, stage.skin_v
    face = np.asarray(base.regions.get("face", np.arange(base.skin.n_vertices)), dtype=np.int64)
    cp = MeshIndex(skin_h).closest_points(skin_v[face])
    rim = np.zeros(skin_h.n_faces, bool)
    loops = boundary_loops(skin_h)
    if loops:
        on_rim = vertex_mask(skin_h.n_vertices, loops)
        rim = on_rim[skin_h.faces].any(axis=1)
    near = (cp.distances < 10.0) & ~rim[cp.face_ids]
    bone_obs = np.concatenate([reg.observed[p] for p in ("cranium", "mandible")])
    return {
        "skin_on_scan_fraction": float(on_scan.mean()),
        "face_on_scan_fraction": float(on_scan[face].mean()),
        "bone_observed_fraction": float(np.mean(bone_obs > 0.3)),
        "face_vertices_near_target": int(near.sum()),
        "face_within_1_5mm_fraction": float((cp.distances[near] <= 1.5).mean())
        if near.any()
        else 0.0,
        "face_median_distance_mm": float(np.median(cp.distances[near])) if near.any() else None,
        "pushed_out_vertices": stage.pushed,
        "eye_shift_mm": {str(i): round(float(m[2]), 2) for i, m in stage.eye_shift.items()},
        "min_tissue_before_push_mm": stage.min_tissue,
        "scan_not_head_area_fraction": round(stage.fit.not_head, 4),
        "skull_registration": {
            k: reg.figures[k]
            for k in (
                "orientation",
                "observed_fraction",
                "median_observed_distance_mm",
                "jaw",
                "self_check",
            )
            if k in reg.figures
        },
    }


def build_template_pack(
    skin_path: str | PathLike[str],
    skull_path: str | PathLike[str],
    out: str | PathLike[str],
    *,
    sex: str = "male",
    units: str = "auto",
    scale: float | None = None,
    skin_landmarks: str | PathLike[str] | None = None,
    skull_landmarks: str | PathLike[str] | None = None,
    orientation: tuple | None = None,
    base: TemplateHead | None = None,
    progress: Progress | None = None,
    force: bool = False,
    staged: bool = False,
) -> tuple[BuildResult, list[Path]]:
    """Read the inputs, :func:`build_template` on ``base`` (default: the built-in
    head of ``sex``), and write the pack to ``out``.

    Meshes and landmark files share one frame and one unit (``units`` or
    ``scale`` converts both to mm).  Returns the result and the files written.

    ``out`` is written as a whole (:func:`workbench.io.outputs.staged_folder`):
    a folder holding an input is refused, an existing pack is replaced only
    with ``force`` (kept as ``PACK.1``) and a failure leaves it as it was.
    ``staged=True``: ``out`` is a private folder of the caller, written
    straight into.
    """
    from workbench.core.units import check_units_choice, resolve_units
    from workbench.io.catalogue import load_catalogue
    from workbench.io.markups import read_landmarks
    from workbench.io.meshes import read_mesh
    from workbench.io.outputs import check_output_folder, write_folder
    from workbench.io.template_pack import export_template
    from workbench.services.case.input_checks import check_skull_mesh
    from workbench.services.templates.cache import reference_head

    check_units_choice(units, scale)
    sources = [skin_path, skull_path, skin_landmarks, skull_landmarks]
    if not staged:
        check_output_folder(out, sources, force)  # before the build, which takes a while
    meshes, factors, inputs, reads = {}, {}, [], {}
    for role, path, kind in (
        ("skin", Path(skin_path), "head"),
        ("skull", Path(skull_path), "skull"),
    ):
        reads[role] = read = read_mesh(
            path, units=units if scale is None else "auto", scale=scale, kind=kind
        )
        meshes[role], factors[role] = read.mesh, read.scale_applied
        inputs.append({"role": role, "file": path.name, "sha256": file_sha256(path)})
    # one surface given twice, swapped, another person's skin, not one frame: refused in
    # seconds here rather than after the build; swapped before the units (a skin read as a
    # skull is "too large for a skull"), the rest in mm
    check_distinct_inputs(skin_path, skull_path, (inputs[0]["sha256"], inputs[1]["sha256"]))
    measure = measure_pair(meshes["skin"], meshes["skull"])
    check_not_swapped(measure, skin_path, skull_path)
    if scale is None and units == "auto":
        for role, given in (("skin", skin_path), ("skull", skull_path)):
            resolve_units(reads[role].units, "auto", source=str(given))
    check_skin_fits_skull(measure, None, skin_path, skull_path)
    check_skull_mesh(meshes["skull"], Path(skull_path), units_note=reads["skull"].units.confirmed)
    seeds: dict[str, LandmarkSet | None] = {"skin": None, "skull": None}
    for surface, lm_path in (("skin", skin_landmarks), ("skull", skull_landmarks)):
        if lm_path is not None:
            lms = read_landmarks(
                lm_path, surface, catalogue=load_catalogue(), allow_undefined=True
            ).landmarks
            f = factors[surface]
            seeds[surface] = lms.transformed(np.diag([f, f, f, 1.0]))
            inputs.append(
                {
                    "role": f"{surface}_landmarks",
                    "file": Path(lm_path).name,
                    "sha256": file_sha256(Path(lm_path)),
                }
            )
    result = build_template(
        meshes["skin"],
        meshes["skull"],
        base or reference_head(sex),
        skin_seeds=seeds["skin"],
        skull_seeds=seeds["skull"],
        orientation=orientation,
        inputs=inputs,
        progress=progress,
    )
    if staged:
        return result, export_template(result.head, out)
    return result, write_folder(
        out, lambda folder: export_template(result.head, folder), force=force, inputs=sources
    )
