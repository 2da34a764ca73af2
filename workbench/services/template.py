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
landmarks stop moving.  Skull regions that come closer to the skin than
:data:`MIN_CLEARANCE_MM` are then pushed inward by extra correspondences, so
the skin never intersects the skull.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from workbench.core.landmarks import Landmark, LandmarkSet
from workbench.core.mesh import Mesh
from workbench.core.normals import normals_within_radius, vertex_normals
from workbench.core.spatial import MeshIndex
from workbench.core.tps import fit_warp
from workbench.io.tables import load_depth_table
from workbench.model.template import TemplateHead

TEMPLATE_NAME = "workbench-reference-head"
TEMPLATE_VERSION = "1"
DOWEL_RADIUS_MM = 5.0
MIN_CLEARANCE_MM = 2.0
BONE_PARTS = ("cranium", "mandible", "upper_teeth", "lower_teeth", "tongue")

#: Landmarks of the mouth region whose dowels run parallel to the Frankfort
#: plane.  At the alveolar margins (prosthion, infradentale, ectomolare ...)
#: the bone normal points up or down along the tooth row, while the tissue
#: depth is measured through the lips and cheeks; Kähler (2003, Fig. 8.17)
#: notes that skull-skin correspondence there is not orthogonal to the skull.
HORIZONTAL_DOWELS = frozenset({
    "ss", "mp", "pr", "id", "sm",
    "sC_l", "sC_r", "iC_l", "iC_r", "ecm2s_l", "ecm2s_r", "ecm2i_l", "ecm2i_r",
})


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


def paired_depths(skull_codes: set[str], skin_codes: set[str], table_id: str = "ttable_2023",
                  group: str | None = None) -> dict[str, tuple[str, float]]:
    """``{skull code: (skin code, depth mm)}`` for table rows present on both surfaces."""
    table = load_depth_table(table_id)
    depths = table.lookup(group)
    out = {}
    for code, skin_code in zip(table.codes, table.skin_codes, strict=True):
        if code in depths and code in skull_codes and skin_code in skin_codes:
            out[code] = (skin_code, depths[code][0])
    return out


def dowel_directions(parts: dict[str, Mesh], points: np.ndarray, part_of: list[str],
                     codes: list[str]) -> np.ndarray:
    """Unit dowel directions: bone normal averaged over :data:`DOWEL_RADIUS_MM`.

    For :data:`HORIZONTAL_DOWELS` the vertical (y) component is removed, so
    those dowels run parallel to the Frankfort plane.
    """
    normals = np.zeros_like(points)
    for part in set(part_of):
        idx = [i for i, p in enumerate(part_of) if p == part]
        mesh = parts[part if part in parts else "cranium"]
        normals[idx] = normals_within_radius(mesh, points[idx], DOWEL_RADIUS_MM)
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
    max_iterations: int = 16,
) -> tuple[dict[str, Mesh], LandmarkSet, dict[str, np.ndarray], SkullFitReport]:
    """Warp every bone part so paired landmarks sit one table depth under the skin.

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
        Other points carried through the same warps (e.g. the TMJ axis).
    openings : (m, 3), optional
        Skin points on the borders of openings (eyes, mouth, neck); near them
        the inside/outside test of the open skin is unreliable, so no
        clearance constraints are placed there.

    Returns
    -------
    warped parts, warped skull landmarks, warped extra points, report
    """
    codes = sorted(depths)
    p_skin = skin_landmarks.positions_of([depths[c][0] for c in codes])
    d = np.array([depths[c][1] for c in codes])
    parts = dict(parts)
    extra = {k: np.asarray(v, float) for k, v in (extra_points or {}).items()}
    lms = skull_landmarks
    skin_index = MeshIndex(skin)
    skin_normals = vertex_normals(skin)
    fixed_src = np.zeros((0, 3))
    iterations = 0

    def warp_all(src: np.ndarray, dst: np.ndarray) -> None:
        nonlocal lms
        w = fit_warp(src, dst)
        # update in place: _push_inward holds the same dicts
        parts.update({k: m.with_vertices(w(m.vertices)) for k, m in parts.items()})
        extra.update({k: w(v) for k, v in extra.items()})
        moved = [Landmark(lm.code, w(lm.position[None])[0], lm.status, lm.confidence,
                          lm.description) if lm.is_defined else lm for lm in lms]
        lms = LandmarkSet(lms.surface, tuple(moved))

    # the skull's own Frankfort landmarks stay on the FH plane (y = 0)
    fh_codes = [c for c in ("po_l", "po_r", "or_l", "or_r") if c in lms.as_dict()]
    for iterations in range(1, max_iterations + 1):  # noqa: B007 - reported below
        s = lms.positions_of(codes)
        n = dowel_directions(parts, s, [part_of.get(c, "cranium") for c in codes], codes)
        target = p_skin - d[:, None] * n
        fh = lms.positions_of(fh_codes)
        fh_target = fh * [1.0, 0.0, 1.0]
        if max(np.abs(target - s).max(), np.abs(fh[:, 1]).max(initial=0)) < 0.02 and iterations > 1:
            break
        warp_all(np.vstack([s, fh, fixed_src]), np.vstack([target, fh_target, fixed_src]))
        if np.abs(target - s).max() > 0.5:
            continue  # settle the dowel landmarks before adding clearance constraints
        fixed_src = _push_inward(parts, lms.positions_of([*codes, *fh_codes]), skin_index,
                                 skin_normals, fixed_src, warp_all, openings)
    s = lms.positions_of(codes)
    n = dowel_directions(parts, s, [part_of.get(c, "cranium") for c in codes], codes)
    along = np.einsum("ij,ij->i", p_skin - s, n)
    off_axis = np.linalg.norm(p_skin - s - along[:, None] * n, axis=1)
    report = SkullFitReport(
        depth_error_mm={c: float(np.hypot(a - di, o))
                        for c, a, o, di in zip(codes, along, off_axis, d, strict=True)},
        min_clearance_mm=_min_clearance(parts, skin_index, openings),
        iterations=iterations,
        extra_constraints=len(fixed_src),
    )
    return parts, lms, extra, report


def _clearance(mesh: Mesh, skin_index: MeshIndex) -> np.ndarray:
    """Signed depth of each vertex under the skin (positive = inside)."""
    return -skin_index.signed_distance(mesh.vertices)


def _min_clearance(parts: dict[str, Mesh], skin_index: MeshIndex,
                   openings: np.ndarray | None, margin_mm: float = 12.0) -> float:
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


def _push_inward(parts: dict[str, Mesh], landmarks: np.ndarray, skin_index: MeshIndex,
                 skin_normals: np.ndarray, fixed: np.ndarray,
                 warp_all: Callable[[np.ndarray, np.ndarray], None],
                 openings: np.ndarray | None = None,
                 spacing_mm: float = 12.0, rounds: int = 4) -> np.ndarray:
    """Add correspondences pulling bone that is too close to the skin inward.

    Returns all fixed correspondences (their warped positions), which later
    fits keep in place so the clearance is not lost again.  Every constraint
    is mirrored across x = 0 so the skull stays symmetric.
    """
    from scipy.spatial import cKDTree

    near_opening = cKDTree(openings) if openings is not None and len(openings) else None
    for _ in range(rounds):
        pts, moves = [], []
        for name in ("cranium", "mandible"):
            mesh = parts[name]
            depth = _clearance(mesh, skin_index)
            bad = np.flatnonzero(depth < MIN_CLEARANCE_MM)
            if len(bad) == 0:
                continue
            # keep the worst vertex per spacing-sized cell, away from the landmarks
            order = bad[np.argsort(depth[bad])]
            chosen: list[int] = []
            taken = np.vstack([landmarks, fixed, *moves])
            for v in order:
                p = mesh.vertices[v]
                if np.linalg.norm(taken - p, axis=1).min() < spacing_mm:
                    continue
                if all(np.linalg.norm(mesh.vertices[c] - p) >= spacing_mm for c in chosen):
                    chosen.append(int(v))
                if len(chosen) >= 60:
                    break
            if not chosen:
                continue
            cl = skin_index.closest_points(mesh.vertices[chosen])
            keep = np.ones(len(chosen), bool)
            if near_opening is not None:
                keep = near_opening.query(cl.points)[0] > spacing_mm
            if not keep.any():
                continue
            chosen_v = mesh.vertices[np.asarray(chosen)[keep]]
            normal = skin_normals[skin_index.mesh.faces[cl.face_ids[keep], 0]]
            shift = (MIN_CLEARANCE_MM + 0.5 - depth[np.asarray(chosen)[keep]])[:, None] * normal
            moved = chosen_v - shift
            lateral = np.abs(chosen_v[:, 0]) > spacing_mm / 2
            mirror = np.array([-1.0, 1.0, 1.0])
            moved[~lateral, 0] = chosen_v[~lateral, 0]  # midline points stay on the midline
            pts.append(np.vstack([chosen_v, chosen_v[lateral] * mirror]))
            moves.append(np.vstack([moved, moved[lateral] * mirror]))
        if not pts:
            break
        src = np.vstack([landmarks, fixed, *pts])
        dst = np.vstack([landmarks, fixed, *moves])
        warp_all(src, dst)
        fixed = np.vstack([fixed, *moves])
    return fixed


def build_reference_head(sex: str = "male", table_id: str = "ttable_2023") -> TemplateHead:
    """The reference head for ``sex``: authored skin, procedural skull fitted under it."""
    from workbench.core.headgen.skin import build_skin
    from workbench.core.headgen.skull import build_skull

    skin = build_skin(sex)
    skull = build_skull(sex)
    depths = paired_depths(set(skull.landmarks.codes), set(skin.landmarks.codes), table_id)
    bones = {name: getattr(skull, name) for name in BONE_PARTS}
    axis_point, axis_dir = skull.tmj_axis
    extra = {"tmj": np.vstack([axis_point, axis_point + axis_dir]),
             "condyles": np.asarray(skull.condyle_centres)}
    bones, skull_lms, extra, report = fit_skull_to_skin(
        bones, skull.landmarks, dict(skull.landmark_part), skin.mesh, skin.landmarks, depths,
        extra_points=extra,
        openings=skin.mesh.vertices[np.concatenate(list(skin.openings.values()))])
    eye_centres = np.vstack([skin.eyeballs["l"][0], skin.eyeballs["r"][0]])
    eye_radius = float(skin.eyeballs["l"][1])
    meshes = {"skin": skin.mesh, **bones, "eyes": _globes(skull.eyes, skull.eye_centres,
                                                          skull.eye_radius, eye_centres, eye_radius)}
    tmj_dir = extra["tmj"][1] - extra["tmj"][0]
    return TemplateHead(
        template_id=f"{TEMPLATE_NAME}/{TEMPLATE_VERSION}/{sex}",
        sex=sex,
        meshes=meshes,
        skin_landmarks=skin.landmarks,
        skull_landmarks=skull_lms,
        skull_landmark_part=dict(skull.landmark_part),
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


def _globes(eyes: Mesh, centres: np.ndarray, radius: float, new_centres: np.ndarray,
            new_radius: float) -> Mesh:
    """Move and scale each globe (a rigid part: only position and size follow, §8.3.2)."""
    v = eyes.vertices.copy()
    owner = np.linalg.norm(v[:, None, :] - np.asarray(centres)[None], axis=2).argmin(axis=1)
    for k in range(2):
        sel = owner == k
        v[sel] = new_centres[k] + (v[sel] - centres[k]) * (new_radius / radius)
    return eyes.with_vertices(v)
