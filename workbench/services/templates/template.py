"""Assemble the reference head: skin over a skull fitted at published tissue depths.

Units and frame: mm, head frame (x to the subject's left, y up, z forward,
Frankfort Horizontal at y = 0).

The skin (:func:`workbench.core.headgen.skin.build_skin`) is authored to
adult facial norms; the skull (:func:`workbench.core.headgen.skull.build_skull`)
is procedural.  As in Kähler (2003, §5.1.1: "the generic skull is fitted to
the reference skin by the same landmark warp"), the skull is then warped so
that every skull landmark paired with a skin landmark sits exactly one
tissue depth below it, measured along the dowel direction (the skull normal
averaged over :data:`DOWEL_RADIUS_MM`):

    s_i = p_i − d_i n_i,

with ``d_i`` the adult mean of the depth table (default the 2023 T-Table).
Because ``n_i`` depends on the warped skull, the fit is repeated until the
dowel directions stop changing; each round re-solves one warp of the
original skull with all constraints, and the directions are damped per
landmark (harder where they oscillate).  Left/right dowels are kept mirror
images and midline dowels lie in the mid-sagittal plane, so the fitted skull
is symmetric.  Skull regions that come closer to the skin than
:data:`MIN_CLEARANCE_MM` are pushed inward by extra (mirrored)
correspondences that ride on the landmark warp, so the skin never
intersects the skull away from its openings.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from workbench.core.data_paths import DEFAULT_DEPTH_TABLE
from workbench.core.landmarks import Landmark, LandmarkSet
from workbench.core.mesh import Mesh
from workbench.core.normals import normals_within_radius
from workbench.core.spatial import MeshIndex
from workbench.core.tps import fit_warp
from workbench.io.tables import load_depth_table
from workbench.model.template import TemplateHead
from workbench.services.templates.muscles import layout_muscles

TEMPLATE_NAME = "workbench-reference-head"
TEMPLATE_VERSION = "1"
DOWEL_RADIUS_MM = 5.0
MIN_CLEARANCE_MM = 2.0
#: Clearance constraints aim this far beyond MIN_CLEARANCE_MM, and lie this far apart.
CLEARANCE_SLACK_MM = 0.5
CLEARANCE_SPACING_MM = 10.0
#: No clearance constraint closer than this to a fitted skull landmark.
LANDMARK_GAP_MM = 4.0
BONE_PARTS = ("cranium", "mandible", "upper_teeth", "lower_teeth", "tongue")

#: Landmarks of the mouth region whose dowels run parallel to the Frankfort
#: plane.  At the alveolar margins (prosthion, infradentale, ectomolare ...)
#: the bone normal points up or down along the tooth row, while the tissue
#: depth is measured through the lips and cheeks; Kähler (2003, Fig. 8.17)
#: notes that skull-skin correspondence there is not orthogonal to the skull.
HORIZONTAL_DOWELS = frozenset(
    {
        "ss",
        "mp",
        "pr",
        "id",
        "sm",
        "sC_l",
        "sC_r",
        "iC_l",
        "iC_r",
        "ecm2s_l",
        "ecm2s_r",
        "ecm2i_l",
        "ecm2i_r",
    }
)


@dataclass(frozen=True)
class SkullFitReport:
    """How well the skull sits under the skin.

    Attributes
    ----------
    depth_error_mm : dict
        Skull code → distance between the skin landmark and the dowel tip
        (skull landmark + table depth × dowel direction), in mm.
    min_clearance_mm : float
        Smallest skin-to-bone distance over all bone vertices (positive = under the skin).
    iterations : int
    extra_constraints : int
        Correspondences added to keep bone under the skin.
    """

    depth_error_mm: dict[str, float]
    min_clearance_mm: float
    iterations: int
    extra_constraints: int


def paired_depths(
    skull_codes: set[str],
    skin_codes: set[str],
    table_id: str = DEFAULT_DEPTH_TABLE,
    group: str | None = None,
    k: float = 0.0,
) -> dict[str, tuple[str, float]]:
    """``{skull code: (skin code, depth mm)}`` for table rows present on both surfaces.

    The depth is the group's mean + ``k`` SD (``k`` = 0: the mean).
    """
    table = load_depth_table(table_id)
    depths = table.lookup(group)
    out = {}
    for code, skin_code in zip(table.codes, table.skin_codes, strict=True):
        if code in depths and code in skull_codes and skin_code in skin_codes:
            mean, sd = depths[code]
            out[code] = (skin_code, mean + k * sd if k else mean)
    return out


def dowel_directions(
    parts: dict[str, Mesh], points: np.ndarray, part_of: list[str], codes: list[str]
) -> np.ndarray:
    """Unit dowel directions: bone normal averaged over :data:`DOWEL_RADIUS_MM`.

    For :data:`HORIZONTAL_DOWELS` the vertical (y) component is removed, so
    those dowels run parallel to the Frankfort plane.
    """
    normals = np.zeros_like(points)
    for part in set(part_of):
        idx = [i for i, p in enumerate(part_of) if p == part]
        mesh = parts[part if part in parts else "cranium"]
        normals[idx] = normals_within_radius(mesh, points[idx], DOWEL_RADIUS_MM)
    # midline landmarks: the dowel lies in the mid-sagittal plane (the
    # procedural bone mesh is not vertex-symmetric, so its averaged normal
    # there has a small, spurious x component)
    midline = np.array([not c.endswith(("_l", "_r")) for c in codes])
    if midline.any():
        normals[midline, 0] = 0.0
        normals[midline] /= np.maximum(
            np.linalg.norm(normals[midline], axis=1, keepdims=True), 1e-12
        )
    flat = np.array([c in HORIZONTAL_DOWELS for c in codes])
    if flat.any():
        h = normals[flat].copy()
        h[:, 1] = 0.0
        length = np.linalg.norm(h, axis=1, keepdims=True)
        h = np.where(length > 0.2, h / np.maximum(length, 1e-12), [0.0, 0.0, 1.0])
        normals[flat] = h
    return normals


def fit_skull_to_skin(
    parts: dict[str, Mesh],
    skull_landmarks: LandmarkSet,
    part_of: dict[str, str],
    skin: Mesh,
    skin_landmarks: LandmarkSet,
    depths: dict[str, tuple[str, float]],
    *,
    extra_points: dict[str, np.ndarray] | None = None,
    openings: np.ndarray | None = None,
    max_iterations: int = 40,
    damping: float = 0.5,
    tolerance_mm: float = 0.02,
) -> tuple[dict[str, Mesh], LandmarkSet, dict[str, np.ndarray], SkullFitReport]:
    """Warp every bone part so paired landmarks sit one table depth under the skin.

    Every round solves *one* warp of the original skull with all constraints
    together: the paired landmarks at ``p_i − d_i n_i``, the skull's Frankfort
    landmarks on y = 0, and the clearance constraints.  The dowel directions
    ``n_i`` are re-measured on the warped skull and moved part of the way
    (``damping``) towards the new measurement, which stops the oscillation of
    the plain fixed-point iteration; the loop ends when the dowel tips move
    less than ``tolerance_mm`` and no bone is left too close to the skin.

    Clearance constraints are bone points (mirrored across x = 0) with an
    inward offset along the skin normal, *relative to the landmark-only warp*:
    their target is ``W_landmarks(q) + offset``, so they follow the landmark
    moves instead of freezing bone where an earlier round left it.  Offsets
    grow while the point (or its mirror image) is shallower than
    :data:`MIN_CLEARANCE_MM`; new points are added where bone is still too
    close to the skin.

    Parameters
    ----------
    parts : {name: Mesh}
        Bone meshes (cranium, mandible, teeth, tongue), mm, head frame.
    skull_landmarks : LandmarkSet
    part_of : {skull code: part name}
    skin : Mesh
    skin_landmarks : LandmarkSet
    depths : {skull code: (skin code, depth mm)}
    extra_points : {name: (k, 3)}, optional
        Other points carried through the same warp (e.g. the TMJ axis).
    openings : (m, 3), optional
        Skin points on the borders of openings (eyes, mouth, neck); near them
        the inside/outside test of the open skin is unreliable, so no
        clearance constraints are placed there.

    Returns
    -------
    warped parts, warped skull landmarks, warped extra points, report
    """
    from scipy.spatial import cKDTree

    codes = sorted(depths)
    orig = dict(parts)
    extra0 = {k: np.asarray(v, float) for k, v in (extra_points or {}).items()}
    lms0 = skull_landmarks
    skin_index = MeshIndex(skin)
    fn = np.cross(
        skin.vertices[skin.faces[:, 1]] - skin.vertices[skin.faces[:, 0]],
        skin.vertices[skin.faces[:, 2]] - skin.vertices[skin.faces[:, 0]],
    )
    skin_face_normals = fn / np.maximum(np.linalg.norm(fn, axis=1, keepdims=True), 1e-12)
    near_opening = cKDTree(openings) if openings is not None and len(openings) else None
    part_names = [part_of.get(c, "cranium") for c in codes]

    # the skull's own Frankfort landmarks stay on the FH plane (y = 0)
    fh_codes = [c for c in ("po_l", "po_r", "or_l", "or_r") if c in lms0.as_dict()]
    s0 = lms0.positions_of(codes)
    fh0 = lms0.positions_of(fh_codes).reshape(-1, 3)
    targets = _DowelTargets(
        lm_src=np.vstack([s0, fh0]),
        fh_dst=fh0 * [1.0, 0.0, 1.0],
        p_skin=skin_landmarks.positions_of([depths[c][0] for c in codes]),
        d=np.array([depths[c][1] for c in codes]),
        pairs=_mirror_pairs(codes),
    )
    keep_away = np.vstack([s0, fh0])  # no clearance constraints right at the landmarks

    # clearance constraints: primary source points (x >= 0 or midline) and offsets
    c_src = np.zeros((0, 3))
    c_off = np.zeros((0, 3))
    n = targets.symmetric(dowel_directions(orig, s0, part_names, codes))
    iterations = 0
    alpha = np.full(len(codes), damping)
    last_step = np.zeros_like(n)
    for iterations in range(1, max_iterations + 1):  # noqa: B007 - reported below
        w = targets.solve(n, c_src, c_off)
        current = _warped_parts(orig, w)
        s = targets.p_skin - targets.d[:, None] * n
        n_new = targets.symmetric(dowel_directions(current, s, part_names, codes))
        tip_move = float((targets.d * np.linalg.norm(n_new - n, axis=1)).max())
        step = n_new - n
        # a landmark whose direction update flips sign oscillates: damp it harder
        flip = np.einsum("ij,ij->i", step, last_step) < 0
        alpha = np.where(flip, np.maximum(alpha * 0.5, 0.05), np.minimum(alpha * 1.25, damping))
        last_step = step
        n = targets.symmetric(n + alpha[:, None] * step)
        added, grown = 0, 0.0
        if tip_move < 1.0:  # settle the dowel landmarks before adding clearance constraints
            c_src, c_off, added, grown = _update_clearance(
                current,
                orig,
                w,
                c_src,
                c_off,
                keep_away,
                skin_index,
                skin_face_normals,
                near_opening,
            )
        if tip_move < tolerance_mm and added == 0 and grown < tolerance_mm:
            break
    w = targets.solve(n, c_src, c_off)
    parts = _warped_parts(orig, w)
    extra = {k: w(v) for k, v in extra0.items()}
    lms = LandmarkSet(
        lms0.surface,
        tuple(
            Landmark(lm.code, w(lm.position[None])[0], lm.status, lm.confidence, lm.description)
            if lm.is_defined
            else lm
            for lm in lms0
        ),
    )
    s = lms.positions_of(codes)
    n = dowel_directions(parts, s, part_names, codes)
    p_skin, d = targets.p_skin, targets.d
    along = np.einsum("ij,ij->i", p_skin - s, n)
    off_axis = np.linalg.norm(p_skin - s - along[:, None] * n, axis=1)
    report = SkullFitReport(
        depth_error_mm={
            c: float(np.hypot(a - di, o))
            for c, a, o, di in zip(codes, along, off_axis, d, strict=True)
        },
        min_clearance_mm=_min_clearance(parts, skin_index, openings),
        iterations=iterations,
        extra_constraints=len(_with_mirror_images(c_src, c_off)[0]),
    )
    return parts, lms, extra, report


#: x -> -x: the mirror image across the midsagittal plane (head frame)
_MIRROR = np.array([-1.0, 1.0, 1.0])


def _with_mirror_images(src: np.ndarray, off: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Clearance constraints (bone points, head frame, and their inward offsets, mm) with
    the mirror image of every point off the midline x = 0 added.

    Points within half :data:`CLEARANCE_SPACING_MM` of the midline move
    parallel to it (no x offset); they get their image too: one left of it
    without its image made the fitted skull lopsided (dacryon 0.9 mm off).
    """
    near_midline = np.abs(src[:, 0]) <= 0.5 * CLEARANCE_SPACING_MM
    off = off.copy()
    off[near_midline, 0] = 0.0
    side = np.abs(src[:, 0]) > 1e-6
    return (np.vstack([src, src[side] * _MIRROR]), np.vstack([off, off[side] * _MIRROR]))


def _mirror_pairs(codes: Sequence[str]) -> list[tuple[int, int]]:
    """Index pairs (left, right) of the ``_l``/``_r`` landmarks among ``codes``."""
    index = {c: i for i, c in enumerate(codes)}
    return [
        (i, index[c[:-2] + "_r"])
        for i, c in enumerate(codes)
        if c.endswith("_l") and c[:-2] + "_r" in index
    ]


def _warped_parts(orig: Mapping[str, Mesh], w: Any) -> dict[str, Mesh]:
    """Every bone part of ``orig`` moved by the warp ``w`` (head frame, mm)."""
    return {k: m.with_vertices(w(m.vertices)) for k, m in orig.items()}


@dataclass(frozen=True)
class _DowelTargets:
    """The landmark constraints of :func:`fit_skull_to_skin` (head frame, mm).

    ``lm_src`` are the skull's paired landmarks then its Frankfort landmarks;
    the paired ones go to ``p_skin − d n`` (skin landmark minus the table
    depth along the dowel direction), the Frankfort ones to ``fh_dst`` (on
    y = 0).  ``pairs`` index left/right landmarks, whose dowels are kept
    mirror images so the targets are symmetric.
    """

    lm_src: np.ndarray
    fh_dst: np.ndarray
    p_skin: np.ndarray
    d: np.ndarray
    pairs: list[tuple[int, int]]

    def solve(self, n: np.ndarray, c_src: np.ndarray, c_off: np.ndarray) -> Any:
        """One warp of the original skull meeting every constraint for dowel directions
        ``n``; the clearance points' targets follow the landmark-only warp plus their
        offsets."""
        lm_dst = np.vstack([self.p_skin - self.d[:, None] * n, self.fh_dst])
        if not len(c_src):
            return fit_warp(self.lm_src, lm_dst)
        src, off = _with_mirror_images(c_src, c_off)
        base = fit_warp(self.lm_src, lm_dst)
        return fit_warp(np.vstack([self.lm_src, src]), np.vstack([lm_dst, base(src) + off]))

    def symmetric(self, n: np.ndarray) -> np.ndarray:
        """Unit dowel directions ``n`` with each left/right pair made mirror images."""
        n = n.copy()
        for i, j in self.pairs:
            n[i] = 0.5 * (n[i] + n[j] * _MIRROR)
            n[j] = n[i] * _MIRROR
        return n / np.linalg.norm(n, axis=1, keepdims=True)


def _clearance(mesh: Mesh, skin_index: MeshIndex) -> np.ndarray:
    """Signed depth of each vertex under the skin (positive = inside)."""
    return -skin_index.signed_distance(mesh.vertices)


def _min_clearance(
    parts: dict[str, Mesh],
    skin_index: MeshIndex,
    openings: np.ndarray | None,
    margin_mm: float = 12.0,
) -> float:
    """Smallest depth of bone under the skin, away from the skin's openings.

    Near the eye, mouth and neck openings the open skin has no inside, so
    bone there (e.g. the skull base above the neck opening) is not counted.
    """
    from scipy.spatial import cKDTree

    worst = np.inf
    tree = cKDTree(openings) if openings is not None and len(openings) else None
    for p in ("cranium", "mandible"):
        mesh = parts[p]
        depth = _clearance(mesh, skin_index)
        if tree is not None:
            closest = skin_index.closest_points(mesh.vertices).points
            depth = depth[tree.query(closest)[0] > margin_mm]
        if len(depth):
            worst = min(worst, float(depth.min()))
    return worst


def _update_clearance(
    current: dict[str, Mesh],
    orig: dict[str, Mesh],
    warp,
    c_src: np.ndarray,
    c_off: np.ndarray,
    keep_away: np.ndarray,
    skin_index: MeshIndex,
    skin_face_normals: np.ndarray,
    near_opening,
    spacing_mm: float = CLEARANCE_SPACING_MM,
) -> tuple[np.ndarray, np.ndarray, int, float]:
    """Grow the clearance offsets and add clearance points where bone is too shallow.

    ``c_src`` are primary source points on the original skull (x >= 0, or on
    the midline); each also acts mirrored.  Returns the updated points,
    offsets, how many points were added and the largest offset growth (mm).
    """
    goal = MIN_CLEARANCE_MM + CLEARANCE_SLACK_MM
    mirror = np.array([-1.0, 1.0, 1.0])

    def inward_push(points: np.ndarray) -> np.ndarray:
        """Offset that brings ``points`` (warped) to ``goal`` under the skin, or 0."""
        cl = skin_index.closest_points(points)
        depth = -skin_index.signed_distance(points)
        need = np.clip(goal - depth, 0.0, None)
        return -need[:, None] * skin_face_normals[cl.face_ids]

    c_off = c_off.copy()
    grown = 0.0
    if len(c_src):
        # a primary point and its mirror image: grow the offset by the larger deficit
        own = inward_push(warp(c_src))
        mir = inward_push(warp(c_src * mirror)) * mirror
        pick = np.linalg.norm(mir, axis=1) > np.linalg.norm(own, axis=1)
        growth = np.where(pick[:, None], mir, own)
        c_off += growth
        grown = float(np.linalg.norm(growth, axis=1).max())
    new_src, new_off = [], []
    # spacing is measured on the original skull, between mirror-canonical (x >= 0) points
    taken = np.abs(c_src) * [1.0, 0.0, 0.0] + c_src * [0.0, 1.0, 1.0]
    for name in ("cranium", "mandible"):
        mesh = current[name]
        depth = _clearance(mesh, skin_index)
        bad = np.flatnonzero(depth < MIN_CLEARANCE_MM)
        if not len(bad):
            continue
        cl = skin_index.closest_points(mesh.vertices[bad])
        if near_opening is not None:
            ok = near_opening.query(cl.points)[0] > spacing_mm
            bad = bad[ok]
        order = bad[np.argsort(depth[bad], kind="stable")]
        home = orig[name].vertices
        chosen: list[int] = []
        chosen_c: list[np.ndarray] = []
        for v in order:
            p = home[v]
            pc = np.array([abs(p[0]), p[1], p[2]])
            if len(taken) and np.linalg.norm(taken - pc, axis=1).min() < 0.5 * spacing_mm:
                continue
            if np.linalg.norm(keep_away - p, axis=1).min() < LANDMARK_GAP_MM:
                continue
            if chosen_c and np.linalg.norm(np.asarray(chosen_c) - pc, axis=1).min() < spacing_mm:
                continue
            chosen.append(int(v))
            chosen_c.append(pc)
        if not chosen:
            continue
        src = home[chosen].copy()
        off = inward_push(mesh.vertices[chosen])
        left = src[:, 0] < -0.5 * spacing_mm
        src[left] *= mirror
        off[left] *= mirror
        new_src.append(src)
        new_off.append(off)
        taken = np.vstack([taken, chosen_c])
    added = sum(len(s) for s in new_src)
    if added:
        c_src = np.vstack([c_src, *new_src])
        c_off = np.vstack([c_off, *new_off])
    return c_src, c_off, added, grown


def build_reference_head(sex: str = "male", table_id: str = DEFAULT_DEPTH_TABLE) -> TemplateHead:
    """The reference head for ``sex``: authored skin, procedural skull fitted under it."""
    from workbench.core.headgen.skin import build_skin
    from workbench.core.headgen.skull import build_skull

    skin = build_skin(sex)
    skull = build_skull(sex)
    depths = paired_depths(set(skull.landmarks.codes), set(skin.landmarks.codes), table_id)
    bones = {name: getattr(skull, name) for name in BONE_PARTS}
    axis_point, axis_dir = skull.tmj_axis
    extra = {
        "tmj": np.vstack([axis_point, axis_point + axis_dir]),
        "condyles": np.asarray(skull.condyle_centres),
    }
    bones, skull_lms, extra, report = fit_skull_to_skin(
        bones,
        skull.landmarks,
        dict(skull.landmark_part),
        skin.mesh,
        skin.landmarks,
        depths,
        extra_points=extra,
        openings=skin.mesh.vertices[np.concatenate(list(skin.openings.values()))],
    )
    eye_centres = np.vstack([skin.eyeballs["l"][0], skin.eyeballs["r"][0]])
    eye_radius = float(skin.eyeballs["l"][1])
    meshes = {
        "skin": skin.mesh,
        **bones,
        "eyes": _globes(skull.eyes, skull.eye_centres, skull.eye_radius, eye_centres, eye_radius),
    }
    tmj_dir = extra["tmj"][1] - extra["tmj"][0]
    return TemplateHead(
        template_id=f"{TEMPLATE_NAME}/{TEMPLATE_VERSION}/{sex}",
        sex=sex,
        meshes=meshes,
        skin_landmarks=skin.landmarks,
        skull_landmarks=skull_lms,
        skull_landmark_part=dict(skull.landmark_part),
        muscles=layout_muscles(skin),
        regions=dict(skin.regions),
        openings=dict(skin.openings),
        eye_centres=eye_centres,
        eye_radius=eye_radius,
        tmj_axis=np.vstack([extra["tmj"][0], tmj_dir / np.linalg.norm(tmj_dir)]),
        provenance={
            "depth_table": table_id,
            "dowel_radius_mm": DOWEL_RADIUS_MM,
            "min_clearance_mm": report.min_clearance_mm,
            "depth_error_mm": report.depth_error_mm,
            "fit_iterations": report.iterations,
            "extra_constraints": report.extra_constraints,
            "not_representable": dict(skull.not_representable),
        },
    )


def _globes(
    eyes: Mesh, centres: np.ndarray, radius: float, new_centres: np.ndarray, new_radius: float
) -> Mesh:
    """Move and scale each globe (a rigid part: only position and size follow, §8.3.2)."""
    v = eyes.vertices.copy()
    owner = np.linalg.norm(v[:, None, :] - np.asarray(centres)[None], axis=2).argmin(axis=1)
    for k in range(2):
        sel = owner == k
        v[sel] = new_centres[k] + (v[sel] - centres[k]) * (new_radius / radius)
    return eyes.with_vertices(v)
