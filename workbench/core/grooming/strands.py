"""Hair strands grown over a skin surface, and the ribbons (hair cards) drawn for them.

A strand starts at a root on the skin and is grown in equal steps.  Each
step bends it towards the ground by its ``gravity`` (a curvature in 1/mm,
so long hair falls and short hair keeps its combed direction), and a point
that would sink below the strand's layer height above the skin is lifted
back onto that layer along the skin normal (closest points from the skin's
spatial index).  Strands therefore lie on the head, pass over the ears and
fall down the neck instead of through them.  The layer height rises from 0
at the root to the strand's ``lift`` over the first :data:`LIFT_RAMP_MM`,
which gives the hair its volume.

A ribbon is a flat strip two vertices wide along a strand, lying in the
surface's tangent plane and narrowing towards the tip.  Ribbons are drawn
two-sided; many thin ribbons read as hair in a portrait and are what game
engines and Blender call hair cards.

Units: millimetres; ``up`` is the head's up direction in the skin's frame.
"""

from __future__ import annotations

import numpy as np

from workbench.core.grooming.shell import _unit, surface_frames
from workbench.core.mesh import Mesh
from workbench.core.spatial import MeshIndex

#: length over which a strand rises from the skin to its layer height, mm
LIFT_RAMP_MM = 8.0
#: how far a ribbon's shading normals lean to its two edges (a fraction of the normal)
ROUND = 0.5
#: what is kept of a hanging strand's horizontal direction at each step
HANG_DAMPING = 0.8


def grow_strands(
    skin: Mesh,
    roots: np.ndarray,
    directions: np.ndarray,
    lengths: np.ndarray,
    lift: np.ndarray,
    gravity: np.ndarray,
    up: np.ndarray,
    segments: int,
    hug: np.ndarray | None = None,
    hang_level: float = -np.inf,
    hang_gravity: float = 0.0,
    front: tuple[np.ndarray, float] | None = None,
) -> np.ndarray:
    """``(k, segments + 1, 3)`` strand points grown from ``roots`` ``(k, 3)``.

    ``directions`` ``(k, 3)`` are the first steps' directions (any length),
    ``lengths``, ``lift`` (mm) and ``gravity`` (1/mm) are per strand.  Where
    ``hug`` (mm, per strand) is given, a point is also held at most that far
    above its layer, so combed hair lies along the head, as long as the
    point is above ``hang_level`` (mm along ``up`` from the frame's origin);
    below it hair hangs free and bends down faster, by ``hang_gravity`` (1/mm)
    more, and loses its sideways swing (:data:`HANG_DAMPING`).  ``front``,
    a unit vector and a level along it, is a plane hanging hair stays
    behind (so long hair frames the face instead of covering it).
    """
    roots = np.asarray(roots, float).reshape(-1, 3)
    k = len(roots)
    out = np.zeros((k, segments + 1, 3))
    out[:, 0] = roots
    if k == 0:
        return out
    index = MeshIndex.shared(skin)
    normals = skin.vertex_normals
    step = np.asarray(lengths, float) / segments
    lift = np.asarray(lift, float)
    gravity = np.asarray(gravity, float)
    up_unit = _unit(np.asarray(up, float))
    down = -up_unit
    d = _unit(np.asarray(directions, float))
    p = roots.copy()
    for i in range(1, segments + 1):
        free = p @ up_unit <= hang_level
        g = gravity + np.where(free, hang_gravity, 0.0)
        d = _unit(d + (g * step)[:, None] * down)
        if hang_gravity > 0.0 and free.any():  # hanging hair loses its sideways swing
            vertical = (d[free] @ up_unit)[:, None] * up_unit
            d[free] = _unit(vertical + HANG_DAMPING * (d[free] - vertical))
        q = p + step[:, None] * d
        found = index.closest_points(q)
        base, frame = surface_frames(
            skin.vertices, skin.faces, found.face_ids, found.barycentric, normals
        )
        n = frame[:, 2]
        h = np.einsum("kd,kd->k", q - base, n)
        floor = lift * np.clip(i * step / LIFT_RAMP_MM, 0.0, 1.0)
        low = h < floor
        q[low] += (floor - h)[low, None] * n[low]
        if front is not None:
            ahead = q @ front[0] - front[1]
            over = (ahead > 0) & (q @ up_unit <= hang_level)
            q[over] -= ahead[over, None] * front[0]
        if hug is not None:
            roof = floor + hug
            high = (h > roof) & (q @ up_unit > hang_level)
            q[high] -= (h - roof)[high, None] * n[high]
        moved = q - p
        d = np.where(np.linalg.norm(moved, axis=1, keepdims=True) > 1e-9, _unit(moved), d)
        out[:, i] = q
        p = q
    return out


def ribbons(
    strands: np.ndarray,
    normals: np.ndarray,
    widths: np.ndarray,
    tip_width: float = 0.3,
    tilt: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Ribbon vertices ``(k * m * 2, 3)``, triangles (their normals face the way the skin
    ``normals`` do), each vertex's place along its strand (0 root, 1 tip) and its shading
    normal, for strands ``(k, m, 3)`` over skin ``normals`` ``(k, m, 3)``.

    ``widths`` ``(k,)`` in mm at the root; the tip is ``tip_width`` of it.  The
    shading normals lean out to either edge by :data:`ROUND` (so a flat ribbon
    is lit as a round strand) and by the strand's ``tilt`` (``(k,)``, a
    fraction; strands lit a little differently from their neighbours).
    """
    k, m, _ = strands.shape
    tangent = np.gradient(strands, axis=1) if m > 1 else np.zeros_like(strands)
    side = np.cross(_unit(tangent), np.asarray(normals, float))
    # where the strand runs along the normal (a hair standing up) use any perpendicular
    weak = np.linalg.norm(side, axis=-1) < 1e-6
    if weak.any():
        side[weak] = np.cross(_unit(tangent[weak]), np.array([0.0, 0.0, 1.0]))
    side = _unit(side)
    t = np.linspace(0.0, 1.0, m)
    half = 0.5 * np.asarray(widths, float)[:, None] * (1.0 - (1.0 - tip_width) * t)[None, :]
    left = strands - side * half[..., None]
    right = strands + side * half[..., None]
    verts = np.stack([left, right], axis=2).reshape(-1, 3)  # (k, m, 2) order
    base = (np.arange(k) * m * 2)[:, None] + (np.arange(m - 1) * 2)[None, :]
    a, b, c, d = base, base + 1, base + 2, base + 3
    faces = np.concatenate(
        [np.stack([a, b, d], -1).reshape(-1, 3), np.stack([a, d, c], -1).reshape(-1, 3)]
    )
    along = np.repeat(np.tile(t, k), 2)
    lean = np.zeros(k) if tilt is None else np.asarray(tilt, float)
    n = np.asarray(normals, float)
    edge = np.stack(
        [n + side * (lean[:, None, None] - ROUND), n + side * (lean[:, None, None] + ROUND)],
        axis=2,
    )
    return verts, faces.astype(np.int64), along, _unit(edge.reshape(-1, 3))


__all__ = ["HANG_DAMPING", "LIFT_RAMP_MM", "ROUND", "grow_strands", "ribbons"]
