"""Step 1 of the scan fit: the reference face laid on the scan (orientation and size).

* :func:`_seed_pairs`: three or more skin landmarks the user placed seed the
  pose search (their handedness decides a mirrored scan).
* :func:`_place_face`: from the search's pose (and its runners-up) the
  reference *face* is laid on the scan
  (:func:`workbench.core.face_pose.place_face`); a scan on which it finds too
  little of a face's shape is refused.  A *partial* face (a CT that ends at
  the upper teeth) is laid with the part the scan covers alone
  (:func:`_place_partial`, :func:`_uncovered`).
* :func:`_uncovered` / :func:`_beyond_rim`: which points lie beyond the scan's
  rim (a hole's edge, the scanned field's edge, a field-of-view lid).

Units mm.  Poses map the scan file's frame (after units) to the reference's
head frame (x to the subject's left, y up, z toward the face); :func:`_uncovered`
takes points in the scan's frame.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace

import numpy as np

from workbench.core.errors import InputError
from workbench.core.face_pose import FacePlacement, place_face
from workbench.core.frame import apply_transform
from workbench.core.landmarks import LandmarkSet
from workbench.core.limits import MIN_SCAN_FACE_COVERAGE, MIN_SCAN_NOSE_COVERAGE
from workbench.core.mesh import Mesh
from workbench.core.rigid_search import PoseResult
from workbench.core.spatial import MeshIndex
from workbench.model.template import TemplateHead
from workbench.services.scan_fit.settings import (
    CLEAR_FACE_LOSS,
    COVER_MM,
    MIN_PLACED_FACE,
    MIN_PLACED_NOSE,
    NOSE_DOUBT_FACE,
    PARTIAL_STARTS,
    UNCOVERED_COST,
    WHOLE_FACE_COVERAGE,
)


def _placed_on(landmarks: LandmarkSet | None, ref: Mapping[str, np.ndarray]) -> dict:
    """``{code: position}`` of the user's defined landmarks the reference also has."""
    if landmarks is None:
        return {}
    return {lm.code: lm.position for lm in landmarks if lm.is_defined and lm.code in ref}


def _seed_pairs(
    landmarks: LandmarkSet | None, base: TemplateHead
) -> tuple[np.ndarray, np.ndarray] | None:
    ref = base.skin_landmarks.as_dict()
    placed = _placed_on(landmarks, ref)
    if len(placed) < 3:
        return None
    codes = sorted(placed)
    return np.array([placed[c] for c in codes], float), np.array([ref[c] for c in codes])


def _uncovered(index: MeshIndex, caps: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Per point (the scan's frame, mm): does the scan end before it?

    Its closest scan point lies on an open rim (the edge of a hole or of the
    scanned field) or on a field-of-view lid (``caps``: per scan vertex), more
    than :data:`COVER_MM` away: the scan does not show that part (a partial
    face), which is not a mismatch of its shape.  A closed surface (a ball)
    covers every point.
    """
    cp = index.closest_points(points)
    scan = index.mesh
    ended = _beyond_rim(scan, cp.face_ids, cp.barycentric)
    if caps.any():
        ended |= caps[scan.faces[cp.face_ids]].any(axis=1)
    return ended & (cp.distances > COVER_MM)


def _place_partial(
    index: MeshIndex,
    caps: np.ndarray,
    base: TemplateHead,
    face_ids: np.ndarray,
    groups: Mapping[str, np.ndarray],
    starts: Sequence[PoseResult],
) -> tuple[FacePlacement, np.ndarray] | None:
    """The reference face laid on a scan that shows only part of it, or None when the
    scan covers (nearly) all of the face under every start.

    From each start the face vertices the scan covers (:func:`_uncovered`) are
    laid on it alone (:func:`~workbench.core.face_pose.place_face`: the missing
    part neither pulls nor costs), and the coverage is found again at the pose
    reached.  The pose whose covered loss plus :data:`UNCOVERED_COST` per
    uncovered vertex is lowest wins.  Returns its placement (fractions and
    ``near_by_group`` over the covered vertices) and the covered mask (per face
    vertex, at that pose).
    """
    from workbench.core.rigid_search import SCALE_RANGE

    pts = base.skin.vertices[face_ids]
    nrm = base.skin.vertex_normals[face_ids]
    best: tuple[float, FacePlacement, np.ndarray] | None = None
    for start in starts[:PARTIAL_STARTS]:
        matrix = start.matrix
        covered = ~_uncovered(index, caps, apply_transform(np.linalg.inv(matrix), pts))
        if covered.mean() >= WHOLE_FACE_COVERAGE or covered.mean() < 0.5 * MIN_SCAN_FACE_COVERAGE:
            continue
        slot = np.cumsum(covered) - 1
        sub = {k: slot[np.asarray(g)[covered[g]]] for k, g in groups.items()}
        placed = place_face(
            index, pts[covered], nrm[covered], matrix, scale_range=SCALE_RANGE, groups=sub
        )
        now = ~_uncovered(index, caps, apply_transform(np.linalg.inv(placed.matrix), pts))
        score = (placed.loss * covered.sum() + UNCOVERED_COST * (~covered).sum()) / len(pts)
        if best is None or score < best[0]:
            best = (score, placed, now)
    return None if best is None else (best[1], best[2])


def _place_face(
    scan: Mesh,
    base: TemplateHead,
    pose: PoseResult,
    regions: Mapping[str, np.ndarray],
    source: str,
    caps: np.ndarray,
) -> tuple[PoseResult, FacePlacement, np.ndarray | None]:
    """The search's pose improved by laying the reference face on the scan; refuse a
    scan the face does not find its shape on (:func:`workbench.core.face_pose.place_face`).

    The search scores the whole scan; on a bust the crown, hair and shoulders outweigh
    the face.  The face is laid from the search's winner and from its next-best
    distinct poses (a crown or shoulders can tilt the winner: Nefertiti without a hint
    came out nodded by 24°, a runner-up by 11°); the lowest face loss wins.
    """
    from workbench.core.rigid_search import SCALE_RANGE

    face_ids = np.concatenate(list(regions.values()))
    offsets = np.cumsum([0] + [len(v) for v in regions.values()])
    groups = {
        k: np.arange(a, b) for k, a, b in zip(regions, offsets[:-1], offsets[1:], strict=True)
    }
    index = MeshIndex.shared(scan)  # the head-frame copy of the scan borrows it
    searched = (pose, *pose.alternatives)
    placements: list[FacePlacement] = []
    for start in searched:
        if placements and placements[0].loss < CLEAR_FACE_LOSS:
            break  # the winner's face sits well: the runners-up need not be tried
        placements.append(
            place_face(
                index,
                base.skin.vertices[face_ids],
                base.skin.vertex_normals[face_ids],
                start.matrix,
                scale_range=SCALE_RANGE,
                groups=groups,
            )
        )
    placement = min(placements, key=lambda p: p.loss)
    placement = replace(placement, start_loss=placements[0].start_loss)
    if placement.loss < placement.start_loss:
        # the search's cost and matched fraction described the pose left behind
        pose = replace(
            pose,
            matrix=placement.matrix,
            scale=placement.scale,
            method=f"{pose.method} + face placement",
            cost=placement.loss,
            matched_fraction=placement.matched_fraction,
        )
    nose = placement.near_by_group.get("nose", 1.0)
    if _face_like(placement.near_fraction, nose):
        return pose, placement, None
    # a part of a face (a CT that ends at the upper teeth, a scan without its chin): the
    # reference face beyond the scan's rim finds nothing there, and laid whole it slides
    # up or down to cover more (the headsq skin cut at the upper teeth: its mouth on the
    # scan's nose, 46 % of the face within 5 mm); laid with the covered part alone
    partial = _place_partial(index, caps, base, face_ids, groups, searched)
    shown = ""
    if partial is not None:
        part, covered = partial
        share = float(covered.mean())
        nose_share = float(covered[groups["nose"]].mean()) if "nose" in groups else 1.0
        part_nose = part.near_by_group.get("nose", 1.0)
        if (
            share >= MIN_SCAN_FACE_COVERAGE
            and nose_share >= MIN_SCAN_NOSE_COVERAGE
            and _face_like(part.near_fraction, part_nose)
        ):
            pose = replace(
                searched[0],
                matrix=part.matrix,
                scale=part.scale,
                method=f"{searched[0].method} + partial face placement",
                cost=part.loss,
                matched_fraction=part.matched_fraction,
            )
            return pose, replace(part, start_loss=placement.start_loss), covered
        shown = (
            f"; the scan shows {100 * share:.0f} % of the face and {100 * nose_share:.0f} % "
            f"of its nose, of which {100 * part.near_fraction:.0f} and "
            f"{100 * part_nose:.0f} % find their shape (a partial face needs "
            f"{100 * MIN_SCAN_FACE_COVERAGE:.0f} % of the face shown with "
            f"{100 * MIN_SCAN_NOSE_COVERAGE:.0f} % of the nose, and the shares above)"
        )
    # a ball, a hand, a smooth crown: convex enough for forehead and cheeks, but the
    # nose finds nothing of its shape (ball 42 % of the face / 29 % of the nose, a
    # cylinder 54 / 32 %; real scans 64-99 / 61-100 %: the VHP female's nose tip is
    # cut off by the CT's field of view).  A face placed well but turned ~10° (Nefertiti
    # with its axes searched: 72 / 37 %) misses with its nose alone: not refused
    raise InputError(
        source,
        "does not look like a face: laid on it as well as it goes, "
        f"{100 * placement.near_fraction:.0f} % of the reference face and "
        f"{100 * nose:.0f} % of its nose find scan surface of their shape within 5 mm "
        f"(a face scan gives over {100 * MIN_PLACED_FACE:.0f} and "
        f"{100 * MIN_PLACED_NOSE:.0f} %){shown}",
        "is this a scan of a face? check the orientation (--anterior/--superior or "
        "3+ --landmarks) and the units",
    )


def _face_like(face: float, nose: float) -> bool:
    """Does a placed face with these shares within 5 mm (of the face, of its nose) find
    a face's shape (:data:`MIN_PLACED_FACE`, :data:`MIN_PLACED_NOSE`)?"""
    weak_nose = nose < MIN_PLACED_NOSE and face < NOSE_DOUBT_FACE
    return face >= MIN_PLACED_FACE and not weak_nose


def _beyond_rim(mesh: Mesh, face_ids: np.ndarray, bary: np.ndarray) -> np.ndarray:
    """Closest points (face, barycentric) that lie on a boundary edge of ``mesh``: the
    query point is beyond the rim of one of its openings, not over its surface."""
    # edge h of a face (0: corners 0-1, 1: 1-2, 2: 2-0) holds the points whose weight on
    # the opposite corner is zero
    on_edge = np.asarray(bary)[:, [2, 0, 1]] < 1e-6
    return (mesh.open_face_edges[face_ids] & on_edge).any(axis=1)
