"""Step 3 of the scan fit: the inside follows the fitted skin at the table's tissue depths.

At each paired skin/skull landmark of the depth table (chosen sex and build,
:func:`_depth_pairs`) the skull landmark's target is the fitted skin landmark
moved *inward* along the skin normal (:func:`_inward_normals`) by the table
depth (Kähler §8.3.2).  A regularised thin-plate spline from the carried skull
landmarks to these targets moves cranium, mandible, teeth, tongue and eyes
(:func:`_place_inside`); bone that then reaches through the face skin is moved
back under it (:func:`_bone_under_skin`), and the eyes are set behind the
fitted lids.

Units mm; the head frame of the fitted person before it is settled in its
Frankfort frame (x to the subject's left, y up, z toward the face).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial import cKDTree

from workbench.core.errors import InputError
from workbench.core.landmarks import LandmarkSet
from workbench.core.mesh import Mesh, concatenate
from workbench.core.normals import normals_within_radius
from workbench.core.spatial import MeshIndex
from workbench.core.tps import fit_warp
from workbench.model.template import TemplateHead
from workbench.services.scan_fit.settings import (
    BONE_CLEARANCE_MM,
    BONE_PUSH_RADIUS_MM,
    INNER_SMOOTHING,
    NORMAL_RADIUS_MM,
)


@dataclass(frozen=True)
class _Inside:
    """The head with its inside placed under the fitted skin (:func:`_place_inside`).

    Attributes
    ----------
    head : TemplateHead
        The fitted skin, its landmarks, and the warped inner parts (mm).
    codes : list of str
        The skull landmarks of the depth table's pairs that were placed.
    depth : (len(codes),) float
        The table's tissue depth at each (mm).
    eye_shift : dict
        Per eye, its move behind the fitted lids (:func:`eyes_behind_lids`).
    """

    head: TemplateHead
    codes: list[str]
    depth: np.ndarray
    eye_shift: dict[int, np.ndarray]


def _place_inside(
    rest: TemplateHead,
    skin: Mesh,
    skin_lms: LandmarkSet,
    on_scan: np.ndarray,
    pairs: Mapping[str, tuple[str, float]],
    table: str,
) -> _Inside:
    """The reference ``rest`` (scaled to the person) with ``skin`` fitted and its skull,
    teeth, tongue and eyes warped so the paired skull landmarks lie at the table's
    ``pairs`` depths inward of the fitted ``skin_lms``; ``table`` names the table in
    the refusal of too few pairs."""
    from workbench.services.templates.build import eyes_behind_lids

    skin_at = skin_lms.as_dict()
    skull_at = rest.skull_landmarks.as_dict()
    codes = [c for c in pairs if c in skull_at and pairs[c][0] in skin_at]
    if len(codes) < 4:
        raise InputError(
            table, f"only {len(codes)} skin/skull landmark pairs: the skull cannot be placed"
        )
    skin_pts = np.array([skin_at[pairs[c][0]] for c in codes])
    depth = np.array([pairs[c][1] for c in codes])
    inward = _inward_normals(skin, skin_pts, codes)
    targets = skin_pts + depth[:, None] * inward
    src = np.array([skull_at[c] for c in codes])
    warp = fit_warp(src, targets, smoothing=INNER_SMOOTHING)
    warped = rest.warped(warp)
    meshes = dict(warped.meshes)
    meshes.update(_bone_under_skin(meshes, skin, np.asarray(rest.regions["face"])))
    meshes["skin"] = skin
    eye_shift = eyes_behind_lids(warped, skin.vertices, on_scan)
    head = replace(warped, meshes=meshes, skin_landmarks=skin_lms).with_eyes_moved(eye_shift)
    return _Inside(head, codes, depth, eye_shift)


def _depth_pairs(
    head: TemplateHead, table: str, sex: str, build: str | float
) -> tuple[dict[str, tuple[str, float]], str, list[str]]:
    from workbench.io.tables import load_depth_table
    from workbench.services.templates.template import paired_depths
    from workbench.services.tissue.dowel_sites import choose_depth_group
    from workbench.services.tissue.dowels import build_score

    tab = load_depth_table(table)
    model, z, by_model = build_score(tab, build)
    group, k, label, notes = choose_depth_group(tab, None, sex, "normal" if by_model else build)
    pairs = paired_depths(
        set(head.skull_landmarks.as_dict()), set(head.skin_landmarks.as_dict()), table, group, k
    )
    if model is not None and z:
        # the build model's regional depths (mean + r SD z) for a named build or a BMI
        sds = {c: sd for c, (_, sd) in tab.lookup(group).items()}
        pairs = {
            c: (skin, d + model.loading(c) * sds[c] * z if np.isfinite(sds[c]) else d)
            for c, (skin, d) in pairs.items()
        }
        label = f"{label.removesuffix(', mean')}, {by_model}"
    return pairs, label, notes


def _inward_normals(skin: Mesh, points: np.ndarray, codes: Sequence[str]) -> np.ndarray:
    """Inward unit skin normals at ``points`` (midline landmarks kept in the midsagittal plane)."""
    n = normals_within_radius(skin, points, NORMAL_RADIUS_MM)
    mid = np.array([not c.endswith(("_l", "_r")) for c in codes])
    if mid.any():
        n[mid, 0] = 0.0
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    return -n


def _bone_under_skin(
    meshes: Mapping[str, Mesh], skin: Mesh, face: np.ndarray, rounds: int = 6
) -> dict[str, Mesh]:
    """Cranium and mandible moved back under ``face`` skin vertices they reach through (mm).

    The skin is the scan's and the skull only an estimate placed by a smooth
    warp at the paired landmarks, so between the pairs (the thin skin of the
    lateral orbit rims, the nasal dorsum) bone can come through: there
    the bone is pushed in along the skin's normal, with a Gaussian falloff
    (:data:`BONE_PUSH_RADIUS_MM`), until the skin is at least
    :data:`BONE_CLEARANCE_MM` outside it.  Returns the moved parts; the skull
    landmarks are not moved.
    """
    parts = {p: meshes[p] for p in ("cranium", "mandible") if p in meshes}
    if len(parts) < 2:
        return {}
    normals = skin.vertex_normals
    for _ in range(rounds):
        bone = MeshIndex(concatenate(list(parts.values())))
        signed = bone.signed_distance(skin.vertices[face])
        hit = signed < 0
        if not hit.any():
            break
        where = skin.vertices[face[hit]]
        need = BONE_CLEARANCE_MM - signed[hit]
        push = need[:, None] * normals[face[hit]]
        tree = cKDTree(where)
        for name, mesh in parts.items():
            v = mesh.vertices
            dist, j = tree.query(v, distance_upper_bound=3.0 * BONE_PUSH_RADIUS_MM)
            near = np.isfinite(dist)
            w = np.exp(-((dist[near] / BONE_PUSH_RADIUS_MM) ** 2))
            moved = v.copy()
            moved[near] -= w[:, None] * push[j[near]]
            parts[name] = mesh.with_vertices(moved)
    return parts
