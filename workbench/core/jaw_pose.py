"""Pose of the mandible on a target skull whose cranium is already in place (issue 28).

Units mm, degrees at this interface; everything in the head frame (x to the
subject's left, y up, z toward the face).  The reference mandible (with its
lower teeth) sits in occlusion in its rest layout; a CT's jaw comes open
(0–45°), pushed forward or sideways by a few mm, as its own piece (a
separate mesh component, or one that only touches the skull at the joints
and teeth), or not at all.  So:

1. **The jaw's bone**: target vertices that the cranium cannot explain
   (farther than :data:`OWN_MM` from the posed reference cranium) in reach of
   any jaw pose.  When one connected piece of the target holds most of that
   bone and little else, the jaw is its own piece and only that piece is
   matched (``JawPose.piece``).
2. **Search**: the mandible is turned about the condylar axis over the
   openings a real jaw takes (:data:`OPENINGS_DEG`) and shifted over
   :data:`SHIFTS_MM` (protrusion, lateral, vertical); every pose is scored by
   the robust share of mandible samples that find the jaw's bone with
   agreeing normals.  The best distinct poses are refined by a rigid ICP on
   pairs in both directions (the mandible on the bone and the bone on the
   mandible), bounded to plausible joints (:data:`MAX_JOINT_SHIFT_MM`,
   :data:`OPENING_LIMITS_DEG`).
3. **Presence**: the jaw is there when enough of the posed mandible lies on
   bone of its own (:data:`PRESENT_SUPPORT`) *and* that bone is a jaw's worth
   of area (:data:`PRESENT_AREA`), so a hyoid or a C-spine cannot pass for one.

The pose is reported as the opening about the axis and the shift of the
axis point; :func:`occlusion` undoes it for a face reconstructed with the
teeth together.  Deterministic (seeded samples).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial import cKDTree

from workbench.core.mesh import Mesh
from workbench.core.rigid_search import nearest_agreeing, rigid_motion
from workbench.core.threads import query_workers

#: bone farther than this from the posed reference cranium can belong to the jaw (mm)
OWN_MM = 4.0
#: jaw bone is looked for within this distance of any searched jaw pose (mm)
REACH_MM = 15.0
#: openings tried (degrees about the condylar axis; positive opens the mouth)
OPENINGS_DEG = tuple(float(a) for a in np.arange(-5.0, 46.0, 5.0))
#: axis-point shifts tried: (lateral x, vertical y, protrusion z) in mm
SHIFTS_MM = tuple(itertools.product((-4.0, 0.0, 4.0), (-4.0, 0.0, 4.0), (-4.0, 0.0, 4.0, 8.0)))
#: a pose may open the jaw this far (degrees) and move the joint this far (mm)
OPENING_LIMITS_DEG = (-12.0, 50.0)
MAX_JOINT_SHIFT_MM = 14.0
#: robust σ of the search score and of the final support (mm)
SEARCH_SIGMA_MM = 5.0
SUPPORT_MM = 4.0
#: the condyles stay in their fossae: a pose whose axis point strays from its rest place is
#: held back with σ = JOINT_SIGMA_MM (a robust term, so a jaw really pushed forward or
#: gliding onto the eminence still wins on its bone), so the reference's differently shaped
#: mandible cannot trade its opening for a joint pushed out of the fossa (VHP male, teeth
#: together: 12° open with the joint 6 mm up and 10 mm forward without it, 5° with it)
JOINT_SIGMA_MM = 4.0
#: weight of the joint term beside the mean surface loss (0..1 each)
JOINT_WEIGHT = 0.25
#: ICP σ, first round to last (mm), and rounds
ICP_SIGMA_MM = (8.0, 3.0)
ICP_ROUNDS = 12
#: poses of the search refined by ICP, and the jaw-bone points that look for the mandible
REFINED = 4
BACK_SAMPLES = 3000
#: a mandible is present when this share of its samples lies on bone of its own ...
PRESENT_SUPPORT = 0.3
#: ... and that bone covers this share of the mandible's area
PRESENT_AREA = 0.25
#: a target piece is the jaw's own when it holds this share of the jaw's bone and lies
#: mostly (this share) in the jaw's reach
PIECE_SHARE = 0.6
PIECE_INSIDE = 0.8
SAMPLES = 1500


@dataclass(frozen=True)
class JawPose:
    """The mandible's pose found on a target (head frame, mm).

    Attributes
    ----------
    matrix : (4, 4)
        Rigid map of the reference mandible from its rest layout (occlusion) to the target.
    opening_deg : float
        Turn about the condylar axis (positive: mouth open).
    shift_mm : (3,)
        Displacement of the axis point: x lateral (to the subject's left),
        y vertical, z protrusion.
    support : float
        Share of mandible samples within :data:`SUPPORT_MM` of bone of its own
        with agreeing normals (0..1).
    bone_area : float
        Area of the jaw's bone (own bone in reach) over the mandible's area.
    piece : bool
        The jaw was matched to a separate piece of the target.
    present : bool
    """

    matrix: np.ndarray
    opening_deg: float
    shift_mm: np.ndarray
    support: float
    bone_area: float
    piece: bool
    present: bool

    def transformed(self, m: np.ndarray) -> JawPose:
        """The same pose seen in another frame: ``m`` (4 x 4, rigid) maps this frame to it."""
        return replace(
            self,
            matrix=m @ self.matrix @ np.linalg.inv(m),
            shift_mm=m[:3, :3] @ self.shift_mm,
        )

    def figures(self) -> dict:
        return {
            "present": self.present,
            "opening_deg": round(self.opening_deg, 2),
            "shift_mm": [round(float(x), 2) for x in self.shift_mm],
            "support": round(self.support, 4),
            "bone_area": round(self.bone_area, 4),
            "own_piece": self.piece,
        }


def _axis_rotation(point: np.ndarray, direction: np.ndarray, deg: float) -> np.ndarray:
    k = direction / np.linalg.norm(direction)
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    th = np.radians(deg)
    r = np.eye(3) + np.sin(th) * kx + (1.0 - np.cos(th)) * (kx @ kx)
    m = np.eye(4)
    m[:3, :3] = r
    m[:3, 3] = point - r @ point
    return m


def decompose(
    matrix: np.ndarray, point: np.ndarray, direction: np.ndarray
) -> tuple[float, np.ndarray]:
    """Opening (degrees about ``direction``) and axis-point shift (mm) of a rigid jaw pose."""
    d = direction / np.linalg.norm(direction)
    r = matrix[:3, :3]
    # the turn about d: angle of r's action on a vector perpendicular to d
    e = np.cross(d, [0.0, 1.0, 0.0] if abs(d[1]) < 0.9 else [0.0, 0.0, 1.0])
    e /= np.linalg.norm(e)
    f = np.cross(d, e)
    re = r @ e
    opening = float(np.degrees(np.arctan2(re @ f, re @ e)))
    shift = matrix[:3, :3] @ point + matrix[:3, 3] - point
    return opening, shift


def joint_loss(shift: np.ndarray) -> float:
    """Robust 0..1 loss of a jaw whose axis point moved by ``shift`` (mm) from its rest."""
    d = float(np.linalg.norm(shift))
    return 1.0 - float(np.exp(-0.5 * (d / JOINT_SIGMA_MM) ** 2))


#: closing turns tried from the reference's occlusion, about the jaw axis (degrees)
CLOSE_SCAN_DEG = tuple(float(a) for a in np.arange(12.0, -12.01, -0.25))
#: the teeth meet when this share of the lower teeth's points lies within CONTACT_MM of
#: the upper teeth
CONTACT_SHARE = 0.02
CONTACT_MM = 1.0


@dataclass(frozen=True)
class Occlusion:
    """How a found jaw was brought into occlusion (head frame, mm, degrees).

    Attributes
    ----------
    matrix : (4, 4)
        Rigid map of the jaw as found (CT pose) into occlusion.
    method : str
        ``"teeth in contact"`` (closed about the condylar axis until the
        lower teeth meet the upper ones), ``"reference vertical dimension, no
        teeth"`` (the jaw takes the reference head's closed relation to the
        cranium, i.e. its teeth's vertical dimension) or ``"reference vertical
        dimension, the teeth did not meet"`` (teeth or ridges were seen but
        never came together on closing: a toothless jaw's ridges, broken teeth).
    contact_turn_deg : float
        Turn about the axis from the reference's occlusion to the contact
        (positive: more open than the reference).
    """

    matrix: np.ndarray
    method: str
    contact_turn_deg: float = 0.0

    def figures(self) -> dict:
        return {"method": self.method, "contact_turn_deg": round(self.contact_turn_deg, 2)}


def occlusion(
    pose: JawPose,
    axis: np.ndarray,
    lower: np.ndarray | None = None,
    upper: np.ndarray | None = None,
) -> Occlusion:
    """The rigid map that closes a found jaw (see :class:`Occlusion`).

    ``pose`` is the jaw's pose (:func:`pose_jaw`); ``axis`` its ``(2, 3)``
    condylar axis in the rest layout; ``lower`` and ``upper`` the target's
    lower and upper tooth points in the CT pose (head frame), or None when
    the skull has no teeth to meet.  From the reference's occlusion (the
    inverse of the pose) the jaw is turned about the axis, from open to
    closed, until :data:`CONTACT_SHARE` of the lower teeth come within
    :data:`CONTACT_MM` of the upper ones.
    """
    back = np.linalg.inv(pose.matrix)
    if lower is None or upper is None or len(lower) < 10 or len(upper) < 10:
        return Occlusion(back, "reference vertical dimension, no teeth")
    point = np.asarray(axis[0], float)
    direction = np.asarray(axis[1], float)
    direction = direction / np.linalg.norm(direction) * (1.0 if direction[0] >= 0 else -1.0)
    tree = cKDTree(upper)
    rest = lower @ back[:3, :3].T + back[:3, 3]
    for i, deg in enumerate(CLOSE_SCAN_DEG):
        m = _axis_rotation(point, direction, deg)
        d, _ = tree.query(rest @ m[:3, :3].T + m[:3, 3], workers=query_workers(len(rest)))
        if np.mean(d < CONTACT_MM) >= CONTACT_SHARE:
            if i == 0:  # touching even wide open: these are not two rows of teeth
                break
            return Occlusion(m @ back, "teeth in contact", deg)
    return Occlusion(back, "reference vertical dimension, the teeth did not meet")


def _samples(mesh: Mesh, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    areas = mesh.face_areas
    faces = rng.choice(len(areas), size=n, p=areas / areas.sum())
    r1, r2 = rng.random(n), rng.random(n)
    s = np.sqrt(r1)
    w = np.stack([1 - s, s * (1 - r2), s * r2], axis=1)
    pts = np.einsum("ij,ijk->ik", w, mesh.vertices[mesh.faces[faces]])
    return pts, mesh.face_normals[faces]


def _rigid(src: np.ndarray, dst: np.ndarray, w: np.ndarray) -> np.ndarray:
    """:func:`~workbench.core.rigid_search.rigid_motion` as a 4×4 matrix."""
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = rigid_motion(src, dst, w)
    return m


def _face_pieces(mesh: Mesh) -> np.ndarray:
    from workbench.core.isosurface import face_component_labels

    return face_component_labels(mesh.faces, mesh.n_vertices)


def pose_jaw(
    mandible: Mesh,
    cranium: Mesh,
    axis: np.ndarray,
    target: Mesh,
    weights: np.ndarray,
    *,
    seed: int = 0,
) -> JawPose:
    """Find the mandible's pose on ``target`` (see the module docstring).

    ``mandible`` (with its lower teeth) and ``cranium`` (with the upper
    teeth) are the reference parts laid out in the head frame over the
    target; ``axis`` the ``(2, 3)`` condylar axis point and direction (any
    sign); ``target`` the bone, outward, in the head frame; ``weights`` its
    per-vertex belief (0 on hole rims and far debris).
    """
    rng = np.random.default_rng(seed)
    point = np.asarray(axis[0], float)
    direction = np.asarray(axis[1], float)
    direction = direction / np.linalg.norm(direction) * (1.0 if direction[0] >= 0 else -1.0)
    m_pts, m_nrm = _samples(mandible, SAMPLES, rng)
    mand_area = float(mandible.area)
    poses = [
        _translation(np.array(s)) @ _axis_rotation(point, direction, a)
        for a in OPENINGS_DEG
        for s in SHIFTS_MM
    ]
    # the jaw's bone: target vertices the cranium leaves unexplained, in reach of a pose
    tv = target.vertices
    believed = weights > 0.05
    own = cKDTree(cranium.vertices).query(tv, workers=query_workers(len(tv)))[0] > OWN_MM
    swept = np.vstack([m_pts[::6] @ p[:3, :3].T + p[:3, 3] for p in poses[:: len(SHIFTS_MM)]])
    reach = cKDTree(swept).query(tv, workers=query_workers(len(tv)))[0] < REACH_MM
    jaw = believed & own & reach
    varea = np.zeros(target.n_vertices)
    np.add.at(varea, target.faces.ravel(), np.repeat(target.face_areas / 3.0, 3))
    piece = False
    pieces = _face_pieces(target)
    vpiece = np.zeros(target.n_vertices, np.int64)
    vpiece[target.faces.ravel()] = np.repeat(pieces, 3)
    if jaw.any():
        per = np.bincount(vpiece[jaw], weights=varea[jaw], minlength=pieces.max() + 1)
        best = int(np.argmax(per))
        whole = np.bincount(vpiece, weights=varea, minlength=pieces.max() + 1)[best]
        if per[best] >= PIECE_SHARE * varea[jaw].sum() and per[best] >= PIECE_INSIDE * whole:
            # the jaw came as its own piece: match that piece (all of it, the joints included)
            jaw = (vpiece == best) & believed
            piece = True
    bone_area = float(varea[jaw].sum() / max(mand_area, 1e-9))
    if jaw.sum() < 20:
        return JawPose(np.eye(4), 0.0, np.zeros(3), 0.0, bone_area, piece, False)
    normals = target.vertex_normals
    jp, jn = tv[jaw], normals[jaw]
    tree = cKDTree(jp)
    sub = slice(None, None, 5)
    # every pose's samples in one query
    q = np.stack([m_pts[sub] @ p[:3, :3].T + p[:3, 3] for p in poses])
    qn = np.stack([m_nrm[sub] @ p[:3, :3].T for p in poses])
    d, _, ok = nearest_agreeing(tree, jn, q.reshape(-1, 3), qn.reshape(-1, 3), k=4)
    losses = np.where(ok, 1.0 - np.exp(-0.5 * (d / SEARCH_SIGMA_MM) ** 2), 1.0)
    losses = losses.reshape(len(poses), -1).mean(axis=1)
    scored = [
        (float(loss) + JOINT_WEIGHT * joint_loss(decompose(p, point, direction)[1]), p)
        for loss, p in zip(losses, poses, strict=True)
    ]
    scored.sort(key=lambda x: x[0])
    starts: list[np.ndarray] = []
    for _, p in scored:
        if all(
            np.linalg.norm(_apply(p, point) - _apply(q, point)) > 3.0
            or abs(decompose(p, point, direction)[0] - decompose(q, point, direction)[0]) > 7.0
            for q in starts
        ):
            starts.append(p)
        if len(starts) == REFINED:
            break
    best_pose, best_support = None, -1.0
    for p in starts:
        p = _refine(p, m_pts, m_nrm, jp, jn, tree, point, direction)
        opening, shift = decompose(p, point, direction)
        if not (OPENING_LIMITS_DEG[0] <= opening <= OPENING_LIMITS_DEG[1]):
            continue
        if np.linalg.norm(shift) > MAX_JOINT_SHIFT_MM:
            continue
        q = m_pts @ p[:3, :3].T + p[:3, 3]
        d, _, ok = nearest_agreeing(tree, jn, q, m_nrm @ p[:3, :3].T)
        support = float(np.mean(ok & (d < SUPPORT_MM)))
        if support > best_support:
            best_pose, best_support = p, support
    if best_pose is None:
        return JawPose(np.eye(4), 0.0, np.zeros(3), 0.0, bone_area, piece, False)
    opening, shift = decompose(best_pose, point, direction)
    present = best_support >= PRESENT_SUPPORT and bone_area >= PRESENT_AREA
    return JawPose(best_pose, opening, shift, best_support, bone_area, piece, present)


def _apply(m: np.ndarray, p: np.ndarray) -> np.ndarray:
    return m[:3, :3] @ p + m[:3, 3]


def _translation(t: np.ndarray) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = t
    return m


def _refine(
    pose: np.ndarray,
    m_pts: np.ndarray,
    m_nrm: np.ndarray,
    jp: np.ndarray,
    jn: np.ndarray,
    tree: cKDTree,
    point: np.ndarray,
    direction: np.ndarray,
) -> np.ndarray:
    """Rigid ICP of the mandible samples on the jaw's bone, pairs in both directions, both
    condyles held toward their rest places (:data:`JOINT_SIGMA_MM`)."""
    stride = max(1, len(jp) // BACK_SAMPLES)
    back, back_n = jp[::stride], jn[::stride]
    for sigma in np.geomspace(*ICP_SIGMA_MM, ICP_ROUNDS):
        q = m_pts @ pose[:3, :3].T + pose[:3, 3]
        qn = m_nrm @ pose[:3, :3].T
        d, j, ok = nearest_agreeing(tree, jn, q, qn)
        wf = np.where(ok, np.exp(-0.5 * (d / sigma) ** 2), 0.0)
        # the jaw's bone looks for the posed mandible too (a spread subset of it; bone far
        # from the mandible gets no weight from the kernel)
        bd, bj, bok = nearest_agreeing(cKDTree(q), qn, back, back_n)
        wb = np.where(bok, np.exp(-0.5 * (bd / sigma) ** 2), 0.0)
        if wf.sum() < 1e-6:
            break
        wf = wf / wf.sum()
        wb = wb / max(wb.sum(), 1e-9) if wb.sum() > 1e-6 else wb
        # the joint: both condyles (the axis point ± 50 mm along the axis) toward their place
        ends = np.array([point - 50.0 * direction, point + 50.0 * direction])
        src = np.vstack([q, q[bj], ends @ pose[:3, :3].T + pose[:3, 3]])
        dst = np.vstack([jp[j], back, ends])
        wj = np.full(2, JOINT_WEIGHT * (sigma / JOINT_SIGMA_MM) ** 2 / 2.0)
        step = _rigid(src, dst, np.concatenate([wf, wb, wj]))
        pose = step @ pose
    return pose
