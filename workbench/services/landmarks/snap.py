"""Snap a skull landmark to the anatomical feature its definition names.

Every landmark position is already on the surface (the closest point, see
:mod:`workbench.services.landmarks.placement`).  *Snapping* goes one step
further, as a forensic artist means it: "put glabella on the most forward
point of the brow, near where I clicked".  The feature comes from the
landmark's catalogue definition, restated as a rule in
``data_tables/landmarks/snap_rules.csv`` (:mod:`workbench.io.snap_rules`).

Algorithm (per call; vectorised, no loop over vertices)
-------------------------------------------------------
1. The head frame (Frankfort Horizontal + midsagittal plane) from the case's
   skull landmarks, as the reconstruction builds it
   (:func:`workbench.services.landmarks.frame.input_frame`); without porions and
   an orbitale a :class:`LandmarkError` names what is missing.
2. The patch: vertices within ``radius_mm`` of the position that are
   connected (through edges inside that ball) to the vertex nearest it, so
   the search cannot jump across a gap to the inner table or another bone.
3. Candidates: the patch's vertices; for a midline landmark instead the
   points where the patch's edges cross the midsagittal plane (head x = 0):
   the exact midline profile, on the surface and on the plane (stricter
   than a slab of vertices near the plane, and it needs no widening).
4. Only candidates on the outer surface facing the rule's direction count
   (outward normal · direction > 0).  ``extremum``: the largest projection
   onto the direction; near-ties (:data:`TIE_MM`, e.g. the flat top of the
   vault or the arch) go to the candidate nearest the start, so the
   landmark stays where the user put it unless the feature is clearly
   elsewhere.  The search repeats from the winner until it stays put (at
   most :data:`MAX_CLIMBS` more times): a feature beyond the first ball is
   followed, and a second snap does not move the landmark again.
   ``deepest``: along the midline profile, between the two landmarks that
   bound the concavity in the definition when they have positions (the
   ball then reaches both), the depth of each point below the profile's
   upper convex hull (the line touching it on both sides), measured along
   the direction.  Only the profile seen from the direction counts
   (:meth:`~workbench.core.surface_patch.PatchIndex.seen_from`,
   :func:`~workbench.core.surface_patch.front_profile`): a CT bone's section
   also holds inner walls (sinuses, the nasal floor, the inner table), which
   lie far below the hull.  No concavity deeper than :data:`MIN_DEPTH_MM`, or
   one deeper than :data:`MAX_DEPTH_MM` (a gap in the surface): not moved.

Landmarks with no rule (sutures, midpoints, constructions): a midline one is
only moved onto the midsagittal plane (the nearest point of the surface's
midline profile); a bilateral one is not moved.  An extremum search that
has not settled after its repeats is flagged: the feature may lie farther.

The geometry (patch, plane section, hull depth) is in
:mod:`workbench.core.surface_patch`; its per-mesh structures (vertex k-d
tree, edge adjacency, outward vertex normals) are built once per mesh object
and cached here (weakly, by identity).

Units and frames: mm.  Positions in and out are in the mesh's (the specimen's
input) frame; the rule directions are head-frame axes (x toward the subject's
left, y up, z forward).
"""

from __future__ import annotations

import weakref
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from workbench.core.errors import LandmarkError
from workbench.core.landmarks import LandmarkSet
from workbench.core.mesh import Mesh
from workbench.core.surface_patch import (
    PatchIndex,
    depth_below_upper_hull,
    front_profile,
    plane_section,
)
from workbench.io.catalogue import LandmarkCatalogue, load_catalogue
from workbench.io.snap_rules import SnapRule, load_snap_rules

#: a profile concavity shallower than this (mm) is not a feature
MIN_DEPTH_MM = 0.3
#: a profile "concavity" deeper than this (mm) is a gap in the surface (bone the iso level
#: lost), not a feature: subspinale and supramentale lie a few mm deep
MAX_DEPTH_MM = 20.0
#: extremum heights within this of the top (mm) count as ties; the one nearest the start wins
TIE_MM = 0.25
#: extra searches from the winner until it stays put (see :func:`_climb`)
MAX_CLIMBS = 5
#: a search whose winner moves less than this (mm) has settled
SETTLED_MM = 1e-3
#: search radius (mm) for moving a midline landmark without a rule onto the midline
MIDLINE_RADIUS_MM = 10.0
#: a snap that moves a landmark less than this (mm) changes nothing (no command)
MOVE_EPS_MM = 0.01


@dataclass(frozen=True)
class SnapResult:
    """What a snap would do (positions in mm, mesh/input frame).

    Attributes
    ----------
    code : str
    start, position : (3,) float64
        Before and after; ``position`` lies on the surface.
    moved_mm : float
    feature : str
        What the landmark was snapped to, e.g. ``"most anterior midline point"``,
        ``"the midsagittal plane"`` (no rule, midline) or ``""`` (not moved).
    rule : SnapRule or None
    settled : bool
        False when the extremum search was still moving after its repeats:
        the feature may lie farther away.
    explanation : str
        One line for the user, e.g. ``"g → most anterior midline point
        within 8 mm: moved 2.3 mm"``.
    """

    code: str
    start: np.ndarray
    position: np.ndarray
    moved_mm: float
    feature: str
    rule: SnapRule | None
    settled: bool
    explanation: str

    @property
    def moves(self) -> bool:
        """True when applying the snap would change the position (by >= MOVE_EPS_MM)."""
        return self.moved_mm >= MOVE_EPS_MM

    @property
    def label(self) -> str:
        """Undo-menu text, e.g. ``"Snap g to most anterior midline point"``."""
        return f"Snap {self.code} to {self.feature or 'its feature'}"


_INDEXES: weakref.WeakKeyDictionary[Mesh, PatchIndex] = weakref.WeakKeyDictionary()


def snap_index(mesh: Mesh) -> PatchIndex:
    """The cached :class:`~workbench.core.surface_patch.PatchIndex` of ``mesh`` (per object).

    Call ``snap_index(mesh).warm()`` in a worker to spare the first snap the
    build (~0.1 s for 100k triangles).
    """
    index = _INDEXES.get(mesh)
    if index is None:
        index = _INDEXES[mesh] = PatchIndex(mesh)
    return index


def snap_frame(landmarks: LandmarkSet) -> np.ndarray:
    """4x4 input → head transform of skull landmarks; LandmarkError naming what is missing."""
    from workbench.services.landmarks.frame import input_frame

    try:
        return input_frame(landmarks)[0]
    except LandmarkError as exc:
        raise LandmarkError(
            f"Snap works in the head frame (place or suggest po_l, po_r and "
            f"or_l or or_r first): {exc}"
        ) from None
    except ValueError as exc:
        raise LandmarkError(
            f"Snap cannot build the head frame from these landmarks ({exc}); "
            "check po_l, po_r, or_l and or_r"
        ) from None


def snap_landmark(
    mesh: Mesh,
    landmarks: LandmarkSet,
    code: str,
    position: np.ndarray | None = None,
    *,
    rules: dict[str, SnapRule] | None = None,
    catalogue: LandmarkCatalogue | None = None,
    to_head: np.ndarray | None = None,
) -> SnapResult:
    """Where skull landmark ``code`` snaps to from ``position``; changes nothing.

    Parameters
    ----------
    mesh : Mesh
        The skull surface (mm, input frame).  Pass the same object on every
        call to reuse its cached search structures.
    landmarks : LandmarkSet
        The case's skull landmarks (input frame, mm); they define the head frame.
    code : str
        Catalogue code or label of the landmark.
    position : (3,) float, optional
        Where to search from (input frame, mm; default: the landmark's position).
    rules : dict, optional
        ``{code: SnapRule}``; default :func:`workbench.io.snap_rules.load_snap_rules`.
    to_head : (4, 4) float, optional
        The input → head transform to search in; default :func:`snap_frame` of
        ``landmarks``.

    Returns
    -------
    SnapResult
        Apply it with a ``MoveLandmark`` (see ``SurfacePlacement.snap_to_feature``).

    Raises
    ------
    LandmarkError
        Unknown code, a landmark without a position, or no head frame.
    """
    catalogue = catalogue or load_catalogue()
    code = catalogue.normalise(code, "skull")
    rules = load_snap_rules() if rules is None else rules
    start = _start(landmarks, code, position)
    rule = rules.get(code)
    if rule is None and catalogue.entry(code, "skull").side != "midline":
        return SnapResult(
            code,
            start,
            start,
            0.0,
            "",
            None,
            True,
            f"{code} has no snap rule (its definition names no extremum); not moved",
        )
    to_head = snap_frame(landmarks) if to_head is None else np.asarray(to_head, np.float64)
    index = snap_index(mesh)
    if rule is None:
        return _onto_midline(index, to_head, start, code)
    limits = _limits(landmarks, rule, to_head)
    ends = np.array([landmarks[c].position for c in rule.between]) if limits is not None else None

    def radius_at(point: np.ndarray) -> float:
        if ends is None:
            return rule.radius_mm
        # reach both bounding landmarks from here: the whole concavity
        return max(rule.radius_mm, float(np.linalg.norm(ends - point, axis=1).max()) + 1.0)

    radius = radius_at(start)
    found, settled = _climb(index, to_head, start, rule, radius_at, code, limits)
    if isinstance(found, str):
        return SnapResult(code, start, start, 0.0, "", rule, True, found)
    moved = float(np.linalg.norm(found - start))
    text = f"{code} → {rule.feature} within {radius:.0f} mm: moved {moved:.1f} mm"
    if not settled:
        text += " (still moving after several searches: the feature may lie farther; check it)"
    return SnapResult(code, start, found, moved, rule.feature, rule, settled, text)


def _start(landmarks: LandmarkSet, code: str, position: np.ndarray | None) -> np.ndarray:
    if position is None:
        lm = landmarks.get(code)
        if lm is None or not lm.is_defined:
            status = "missing" if lm is None else lm.status
            raise LandmarkError(f"skull landmark {code!r} is {status}; place it before snapping")
        position = lm.position
    start = np.array(position, dtype=np.float64).reshape(3)
    if not np.isfinite(start).all():
        raise LandmarkError(f"cannot snap {code!r} from a non-finite position")
    return start


def _candidates(
    index: PatchIndex, to_head: np.ndarray, start: np.ndarray, radius_mm: float, midline: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(input points, head points, head normals)``, each ``(k, 3)``, of the patch.

    Its vertices, or for ``midline`` the points where its edges cross head x = 0.
    """
    ids, edges = index.patch(start, radius_mm)
    rot = to_head[:3, :3]
    pts, nrm = index.vertices[ids], index.normals[ids]
    if midline:
        pts, nrm = plane_section(pts, nrm, edges, pts @ rot[0] + to_head[0, 3])
    return pts, pts @ rot.T + to_head[:3, 3], nrm @ rot.T


def _limits(
    landmarks: LandmarkSet, rule: SnapRule, to_head: np.ndarray
) -> tuple[float, float] | None:
    """Profile coordinates (head frame, mm) of a ``deepest`` rule's bounding landmarks."""
    defined = landmarks.as_dict()
    if len(rule.between) != 2 or any(c not in defined for c in rule.between):
        return None
    along = _along(rule)
    ends = sorted(
        float((to_head[:3, :3] @ defined[c] + to_head[:3, 3])[along]) for c in rule.between
    )
    return (ends[0], ends[1]) if ends[1] - ends[0] > 1.0 else None


def _along(rule: SnapRule) -> int:
    """Head axis along the midline profile of a ``deepest`` rule (y for a z depth, else z)."""
    return 1 if abs(rule.axis[2]) > 0 else 2


def _climb(
    index: PatchIndex,
    to_head: np.ndarray,
    start: np.ndarray,
    rule: SnapRule,
    radius_at: Callable[[np.ndarray], float],
    code: str,
    limits: tuple[float, float] | None,
) -> tuple[np.ndarray | str, bool]:
    """``(position, settled)`` of the feature, or ``(why not, True)``.

    Every search repeats from its winner until the winner stays put, so the
    result is a fixed point and snapping it again does not move it.  This
    holds for ``deepest`` rules too: their search ball is centred on the start
    and, without both bounding landmarks, does not cover the same profile
    from every start (a single search moved sm by a further 1.36 mm when
    snapped twice on another machine's reference head).
    """
    point = start
    for _ in range(1 + MAX_CLIMBS):
        found = _search(index, to_head, point, rule, radius_at(point), code, limits)
        if isinstance(found, str):
            return (found, True) if point is start else (point, True)
        if np.linalg.norm(found - point) < SETTLED_MM:
            return found, True
        point = found
    return point, False


def _search(
    index: PatchIndex,
    to_head: np.ndarray,
    start: np.ndarray,
    rule: SnapRule,
    radius_mm: float,
    code: str,
    limits: tuple[float, float] | None,
) -> np.ndarray | str:
    """The feature's position in one ball (input frame), or a sentence saying why none."""
    pts, head, nrm = _candidates(index, to_head, start, radius_mm, rule.midline)
    axis = rule.axis
    keep = nrm @ axis > 0.0  # outer surface facing the direction
    if limits is not None:
        along = head[:, _along(rule)]
        keep &= (along > limits[0]) & (along < limits[1])
    if rule.rule == "deepest" and keep.any():
        # the outer profile only, what a view along the direction sees: a CT section also
        # holds inner walls (sinuses, the nasal floor), which face forward too
        idx = np.flatnonzero(keep)
        idx = idx[index.seen_from(pts[idx], to_head[:3, :3].T @ axis)]
        idx = idx[front_profile(head[idx, _along(rule)], head[idx] @ axis)]
        keep[:] = False
        keep[idx] = True
    if not keep.any():
        where = " on the midline profile" if rule.midline else ""
        if limits is not None:
            where += f" between {rule.between[0]} and {rule.between[1]}"
        return (
            f"{code}: no outer surface facing {rule.direction} (head frame){where} within "
            f"{radius_mm:.0f} mm; move it nearer the feature and snap again; not moved"
        )
    pts, head = pts[keep], head[keep]
    height = head @ axis
    if rule.rule == "extremum":
        near = np.flatnonzero(height >= height.max() - TIE_MM)
        return pts[near[np.argmin(np.linalg.norm(pts[near] - start, axis=1))]]
    depth = depth_below_upper_hull(head[:, _along(rule)], height)
    if depth is None or depth.max() < MIN_DEPTH_MM:
        return (
            f"{code}: no concavity deeper than {MIN_DEPTH_MM:g} mm in the midline profile "
            f"within {radius_mm:.0f} mm; not moved"
        )
    if depth.max() > MAX_DEPTH_MM:  # a gap in the outer profile (bone lost at the iso level)
        return (
            f"{code}: the midline profile within {radius_mm:.0f} mm has a gap "
            f"{depth.max():.0f} mm deep (bone missing from the surface?); not moved"
        )
    return pts[np.argmax(depth)]


def _onto_midline(
    index: PatchIndex, to_head: np.ndarray, start: np.ndarray, code: str
) -> SnapResult:
    """A midline landmark without a rule: the nearest point of the surface's midline profile."""
    pts, _, _ = _candidates(index, to_head, start, MIDLINE_RADIUS_MM, midline=True)
    if not len(pts):
        return SnapResult(
            code,
            start,
            start,
            0.0,
            "",
            None,
            True,
            f"{code} has no snap rule, and no surface within "
            f"{MIDLINE_RADIUS_MM:g} mm crosses the midsagittal plane; not moved",
        )
    end = pts[np.argmin(np.linalg.norm(pts - start, axis=1))]
    moved = float(np.linalg.norm(end - start))
    return SnapResult(
        code,
        start,
        end,
        moved,
        "the midsagittal plane",
        None,
        True,
        f"{code} has no snap rule (its definition names no extremum): moved onto "
        f"the midsagittal plane, {moved:.1f} mm",
    )


def snap_suggested(
    mesh: Mesh,
    landmarks: LandmarkSet,
    *,
    catalogue: LandmarkCatalogue | None = None,
    fallback_frame: np.ndarray | None = None,
) -> tuple[LandmarkSet, list[str]]:
    """Every *suggested* landmark with a snap rule moved to its feature, and every other
    suggested midline landmark onto the midsagittal plane (input frame, mm).

    Used after the dense registration: the registration puts a landmark
    where the reference's landmark lands, the rule then puts it on the
    feature its definition names (most anterior, lowest, deepest ...);
    extremum features go first, so a concavity (ss between ans and pr) is
    bounded by landmarks already on their features.  A midline landmark
    without a rule (rhi, pr, ...) goes to the nearest point of the surface's
    midline profile: the dense registration left the VHP male's nasion up to
    3.8 mm to one side of the midline on the robustness corpus, and a midline
    landmark lies on that plane by its definition.  Placed landmarks are the
    user's and never move.  The head frame is the landmarks' own
    (:func:`snap_frame`); when they cannot make one
    (the registration marked a porion absent: too little bone seen there)
    ``fallback_frame`` (the registration's input → head transform) is used, and
    without it nothing moves and the note says why.  Returns the new set and
    one note per moved landmark.
    """
    catalogue = catalogue or load_catalogue()
    rules = load_snap_rules()

    def snaps(code: str) -> bool:
        entry = catalogue.get(code, "skull")
        return code in rules or (entry is not None and entry.side == "midline")

    todo = [lm.code for lm in landmarks if lm.status == "suggested" and snaps(lm.code)]
    # extremum features first: a concavity is then bounded by its snapped landmarks (ss by
    # ans on the spine's most anterior point, not where the registration left it)
    todo.sort(key=lambda c: 0 if c in rules and rules[c].rule == "extremum" else 1)
    if not todo:
        return landmarks, []
    try:
        frame = snap_frame(landmarks)
    except LandmarkError as exc:
        if fallback_frame is None:
            return landmarks, [f"landmarks not snapped to their features: {exc}"]
        frame = np.asarray(fallback_frame, np.float64)
    out, notes = landmarks, []
    for code in todo:
        try:
            result = snap_landmark(mesh, out, code, rules=rules, catalogue=catalogue, to_head=frame)
        except LandmarkError as exc:
            notes.append(f"{code} not snapped: {exc}")
            continue
        if result.moves and result.settled:
            lm = out[code]
            out = out.with_landmark(lm.moved(result.position, "suggested"))
            notes.append(result.explanation)
    return out, notes
