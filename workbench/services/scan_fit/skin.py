"""Step 2 of the scan fit: the scaled reference skin registered onto the oriented scan.

:func:`_fit_skin_to_scan` registers the reference skin onto the scan
(:func:`workbench.services.templates.build.fit_skin`: per-part affine stage,
then coarse to fine; the skin landmarks the user placed as hard constraints:
:func:`_user_constraints`), smooths away the crossings and fold-overs it made
(:func:`workbench.core.untangle.untangle`), finds the skin the scan supports
(:func:`_scan_support`), refuses a scan that is not (enough of) a face
(:func:`_face_shown`), and carries the skin landmarks onto the fitted skin with
confidences (:func:`_fitted_skin_landmarks`, :func:`_with_confidences`).

Units mm; the head frame of the fitted person before it is settled in its
Frankfort frame (x to the subject's left, y up, z toward the face).  The
user's landmarks are in the scan file's frame.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from workbench.core.errors import InputError
from workbench.core.frame import apply_transform
from workbench.core.landmarks import LandmarkSet
from workbench.core.limits import MIN_SCAN_FACE_COVERAGE
from workbench.core.mesh import Mesh
from workbench.core.nonrigid import AFFINE_ROUNDS
from workbench.core.self_intersection import SelfIntersections, self_intersections
from workbench.core.spatial import MeshIndex
from workbench.core.untangle import Untangled, untangle
from workbench.model.template import TemplateHead
from workbench.services.scan_fit.placement import _placed_on, _uncovered
from workbench.services.scan_fit.settings import (
    CONFIDENCE_MM,
    CUT_EAR_SHARE,
    EAR_REGIONS,
    HEAD_WEIGHT,
    HOLE_CONFIDENCE,
    MIN_FACE_SUPPORT,
    MIN_PARTIAL_SUPPORT,
    NOSE_TIP,
    ON_SCAN_COS,
    ON_SCAN_MM,
    SCAN_LEVELS,
    WHOLE_FACE_COVERAGE,
)

if TYPE_CHECKING:
    from workbench.services.templates.build import SkinFit


@dataclass(frozen=True)
class _Skin:
    """Step 2's result (:func:`_fit_skin_to_scan`): the fitted skin (the person's head
    frame before settling, mm).

    Attributes
    ----------
    index : MeshIndex
        The scan's (in that frame).
    cut_ears : list of str
        Ears the scan's rim cuts through, held to the reference's shape.
    fit : SkinFit
        The registration (its ``target_weights`` per scan vertex, ``not_head``).
    ref_cross : SelfIntersections
        The scaled reference skin's own crossings (the lips' seam).
    untangled : Untangled
        The registered skin with the crossings it added smoothed away.
    skin : Mesh
        The fitted skin (``untangled.mesh``).
    facing, to_scan : (n_skin,)
        Per skin vertex: its closest scan point is believed and faces the same
        side; its distance to the scan (mm).
    on_scan : (n_skin,) bool
        Skin vertices the scan supports.
    face : (n_skin,) bool
        The face region.
    shown_share : float
        The share of the face the scan shows (the rest lies beyond its rim).
    partial : bool
        A partial face (``shown_share`` below :data:`WHOLE_FACE_COVERAGE`).
    landmarks : LandmarkSet
        The fitted skin landmarks, with confidences.
    absent : list of str
        Skin landmarks over no scan.
    """

    index: MeshIndex
    cut_ears: list[str]
    fit: SkinFit
    ref_cross: SelfIntersections
    untangled: Untangled
    skin: Mesh
    facing: np.ndarray
    to_scan: np.ndarray
    on_scan: np.ndarray
    face: np.ndarray
    shown_share: float
    partial: bool
    landmarks: LandmarkSet
    absent: list[str]


def _fit_skin_to_scan(
    rest: TemplateHead,
    scan_h: Mesh,
    caps: np.ndarray,
    belief: np.ndarray,
    rigid: np.ndarray,
    face_ids: np.ndarray,
    base: TemplateHead,
    landmarks: LandmarkSet | None,
    source: str,
    warnings: list[str],
) -> _Skin:
    """Step 2, the skin: the reference ``rest`` (scaled to the person) registered onto
    the scan ``scan_h`` (in the head frame, with its field-of-view lids ``caps`` and its
    ``belief``; ``rigid`` maps the scan file's frame there) by
    :func:`workbench.services.templates.build.fit_skin`, the crossings it made
    untangled, the skin the scan supports found; a scan that is not a face (or too little
    of one) is refused (:func:`_face_shown`); the skin landmarks carried
    (:func:`_fitted_skin_landmarks`).  The registration's notes go to ``warnings``."""
    from workbench.services.templates.build import fit_skin

    scan_index = MeshIndex.shared(scan_h)  # the file-frame scan's, when the placement built it
    hard = _user_constraints(landmarks, rest, rigid)
    # an ear the scan's rim cuts through (a CT that ends below the nose) is held to the
    # reference's shape: half an ear pulled onto the scan's and half inferred folds over
    # (the headsq skin cut at the subnasale: 7 fold-overs at the right ear)
    ears_at = {r: rest.skin.vertices[base.regions[r]] for r in EAR_REGIONS if r in base.regions}
    cut_ears = [
        r for r, at in ears_at.items() if _uncovered(scan_index, caps, at).mean() > CUT_EAR_SHARE
    ]
    fit = fit_skin(
        rest.skin,
        scan_h,
        # (held passive: the regions fit_skin holds when its ears do not follow the scan)
        {k: v for k, v in base.regions.items() if k not in EAR_REGIONS or k in cut_ears},
        levels=SCAN_LEVELS,
        affine_rounds=AFFINE_ROUNDS,
        source=source,
        near="the reference head placed on it",
        hint="check the orientation (--anterior/--superior or 3+ --landmarks) and the units",
        belief=belief,
        hard=hard,
        # the ears look for the scan's too: held passive they stay the reference's, a few
        # mm to a centimetre beside the scan's, whose vertices then counted as misses of the
        # cheek; following, 1 mm figures rise 0.3-4 points on every case, no fold-over added
        ears=not cut_ears,
        index=scan_index,
    )
    warnings += list(fit.warnings)
    # the reference skin's own crossings (sliver triangles of the lips' seam at the mouth
    # corners) are its design; any other the fit made is smoothed away where it is
    ref_cross = self_intersections(rest.skin)
    untangled = untangle(
        rest.skin.with_vertices(fit.registration.vertices),
        reference=rest.skin,
        allowed=map(tuple, ref_cross.pairs.tolist()),
        fixed=None if hard is None else _mask(rest.skin.n_vertices, [hard[0]]),
    )
    skin = untangled.mesh
    facing, to_scan = _scan_support(
        skin.vertices, rest.skin.faces, scan_h, fit.target_weights, scan_index
    )
    on_scan = facing & (to_scan <= ON_SCAN_MM)
    face = _mask(rest.skin.n_vertices, [face_ids])
    shown_share, partial = _face_shown(scan_index, caps, skin, on_scan, face, source)
    skin_lms, absent_skin = _fitted_skin_landmarks(
        rest, skin, on_scan, partial, shown_share, scan_index, caps, landmarks, source
    )
    return _Skin(
        scan_index,
        cut_ears,
        fit,
        ref_cross,
        untangled,
        skin,
        facing,
        to_scan,
        on_scan,
        face,
        shown_share,
        partial,
        skin_lms,
        absent_skin,
    )


def _face_shown(
    scan_index: MeshIndex,
    caps: np.ndarray,
    skin: Mesh,
    on_scan: np.ndarray,
    face: np.ndarray,
    source: str,
) -> tuple[float, bool]:
    """The share of the ``face`` the scan shows and whether it is a partial face; refuse a
    fitted skin whose face (or the part the scan shows) found too little scan surface of
    its shape (:data:`MIN_FACE_SUPPORT`, :data:`MIN_PARTIAL_SUPPORT`)."""
    # the face the scan shows: on a partial face (a CT that ends at the upper teeth) the
    # skin beyond the scan's rim follows the reference's shape and is inferred, not missed
    shown = face & ~_uncovered(scan_index, caps, skin.vertices)
    shown_share = float(shown.sum() / max(int(face.sum()), 1))
    partial = shown_share < WHOLE_FACE_COVERAGE
    support = float(on_scan[shown if partial else face].mean()) if shown.any() else 0.0
    need = MIN_PARTIAL_SUPPORT if partial else MIN_FACE_SUPPORT
    if shown_share < MIN_SCAN_FACE_COVERAGE or support < need:
        # a hand, an object, the back of a head: the skin was bent onto it, but most of
        # the face found no surface of its shape near it; that is not a fitted face
        of_it = (
            f" of the {100 * shown_share:.0f} % of the reference face the scan shows"
            if partial
            else " of the reference face"
        )
        raise InputError(
            source,
            f"does not look like a face: only {100 * support:.0f} %{of_it} found scan "
            f"surface of its shape near it (a face scan gives over "
            f"{100 * MIN_FACE_SUPPORT:.0f} %, a part of a face over {100 * MIN_PARTIAL_SUPPORT:.0f} "
            f"% of at least {100 * MIN_SCAN_FACE_COVERAGE:.0f} % of the face)",
            "is this a scan of a face? check the orientation (--anterior/--superior or 3+ "
            "--landmarks) and the units",
        )
    return shown_share, partial


def _fitted_skin_landmarks(
    rest: TemplateHead,
    skin: Mesh,
    on_scan: np.ndarray,
    partial: bool,
    shown_share: float,
    scan_index: MeshIndex,
    caps: np.ndarray,
    landmarks: LandmarkSet | None,
    source: str,
) -> tuple[LandmarkSet, list[str]]:
    """The skin landmarks carried onto the fitted ``skin`` with confidences
    (:func:`_with_confidences`), and those over no scan; refuse a partial face without
    its nose tip over the scan."""
    from workbench.services.templates.build import carry_skin_landmarks

    skin_lms, absent_skin = carry_skin_landmarks(rest.skin, skin, rest.skin_landmarks, on_scan)
    tip = skin_lms.as_dict().get(NOSE_TIP)
    if partial and tip is not None and _uncovered(scan_index, caps, tip[None])[0]:
        # a band of brow and orbits can take the reference's nose and mouth (the headsq
        # skin cut 40 mm below the vault's top: the face laid 75 mm low, its nose tip
        # beyond the scan's rim); a part of a face fixes the pose only with its nose tip
        # over the scan
        raise InputError(
            source,
            f"shows too little of the face to fit it: {100 * shown_share:.0f} % of the "
            "reference face lies over the scan, but not the nose tip (pronasale); a "
            "partial face scan must show the nose with the eyes or the mouth",
            "give a scan that shows the middle of the face, or place 3+ skin landmarks "
            "(--landmarks)",
        )
    skin_lms = _with_confidences(skin_lms, absent_skin, scan_index, landmarks)
    return skin_lms, absent_skin


def _with_confidences(
    lms: LandmarkSet, absent: Sequence[str], scan_index: MeshIndex, placed: LandmarkSet | None
) -> LandmarkSet:
    """The fitted skin landmarks as a first guess with confidences (head frame, mm).

    Those the user placed stay ``placed`` with confidence 1; the others are
    ``suggested`` with ``exp(-d / CONFIDENCE_MM)`` for their distance ``d`` to
    the scan, capped at :data:`HOLE_CONFIDENCE` over a hole (in empty space:
    their description says so).
    """
    from workbench.core.landmarks import Landmark

    user = set() if placed is None else {lm.code for lm in placed if lm.is_defined}
    codes = [lm.code for lm in lms if lm.is_defined]
    if not codes:
        return lms
    dist = scan_index.closest_points(lms.positions_of(codes)).distances
    d = dict(zip(codes, dist, strict=True))
    out = []
    for lm in lms:
        if not lm.is_defined:
            out.append(lm)
            continue
        if lm.code in user:
            out.append(Landmark(lm.code, lm.position, "placed", 1.0, lm.description))
            continue
        conf = float(np.exp(-d[lm.code] / CONFIDENCE_MM))
        if lm.code in absent:
            conf = min(conf, HOLE_CONFIDENCE)
        out.append(Landmark(lm.code, lm.position, "suggested", round(conf, 3), lm.description))
    return LandmarkSet(lms.surface, tuple(out))


def _user_constraints(
    landmarks: LandmarkSet | None, rest: TemplateHead, to_head: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """Skin landmarks the user placed as hard constraints of the skin fit.

    Each placed landmark (scan frame) is mapped into the head frame; the three
    vertices of the reference skin triangle holding that landmark are pulled to
    where the triangle would sit with the landmark on the user's point (the
    triangle moved by the landmark's offset), so the fitted landmark lands on
    it whether or not the scan has surface there ("in empty space").
    """
    ref = rest.skin_landmarks.as_dict()
    placed = _placed_on(landmarks, ref)
    if not placed:
        return None
    codes = sorted(placed)
    user = apply_transform(to_head, np.array([placed[c] for c in codes]))
    at = np.array([ref[c] for c in codes])
    tri = rest.skin.faces[MeshIndex(rest.skin).closest_points(at).face_ids]  # (k, 3)
    targets = rest.skin.vertices[tri] + (user - at)[:, None, :]
    ids, first = np.unique(tri.ravel(), return_index=True)  # a vertex shared: first wins
    return ids, targets.reshape(-1, 3)[first]


def _mask(n: int, groups: Sequence) -> np.ndarray:
    m = np.zeros(n, dtype=bool)
    for ids in groups:
        m[np.asarray(ids, dtype=np.int64)] = True
    return m


def _scan_support(
    skin_v: np.ndarray,
    faces: np.ndarray,
    scan_h: Mesh,
    scan_weights: np.ndarray,
    index: MeshIndex,
) -> tuple[np.ndarray, np.ndarray]:
    """Per fitted skin vertex: is its closest scan point believed (not a hole rim, not a
    cavity wall, not the shoulders) and facing the same side; and its distance (mm).

    Measured to the scan's *surface* (not its vertices), so a coarse scan (5 mm
    edges) supports the skin as well as a dense one.  A vertex is on the scan
    when supported within :data:`ON_SCAN_MM`.  ``index`` is ``scan_h``'s.
    """
    from workbench.core.normals import vertex_normals

    cp = index.closest_points(skin_v)
    w = np.einsum("ij,ij->i", cp.barycentric, scan_weights[scan_h.faces[cp.face_ids]])
    n = vertex_normals(Mesh(skin_v, faces))
    # (the closest feature's normal: a face's would depend on which face a tie returned)
    cos = np.einsum("ij,ij->i", n, index.pseudo_normals(cp.face_ids, cp.barycentric))
    return (w > HEAD_WEIGHT) & (cos > ON_SCAN_COS), cp.distances
