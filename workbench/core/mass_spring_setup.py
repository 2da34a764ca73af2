"""Rest-state construction of the mass-spring skin (:mod:`workbench.core.mass_spring`).

Mesh topology and areas, the bone each node goes with, and the per-node
muscle weights, computed once when a
:class:`~workbench.core.mass_spring.SkinSimulation` is built.  Units and
frame: millimetres in the head frame (x to the subject's left, y up, z
toward the face).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def edge_topology(
    faces: np.ndarray, n: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Edges of a triangle mesh and the bending pairs across them.

    Returns ``edges`` ``(e, 2)`` (unique, low id first), ``bend`` ``(b, 2)``
    (the two vertices opposite each interior edge), ``bend_edge`` ``(b,)``
    (the edge each bending pair crosses) and ``edge_face`` ``(3f, 2)``
    (edge id, face id) incidences.
    """
    f = np.asarray(faces, dtype=np.int64)
    a = f.reshape(-1)
    b = f[:, [1, 2, 0]].reshape(-1)
    opp = f[:, [2, 0, 1]].reshape(-1)
    face_of = np.repeat(np.arange(len(f)), 3)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    key = lo * n + hi
    order = np.argsort(key, kind="stable")
    ks = key[order]
    first = np.r_[True, ks[1:] != ks[:-1]]
    edge_id_sorted = np.cumsum(first) - 1
    edge_id = np.empty_like(edge_id_sorted)
    edge_id[order] = edge_id_sorted
    uniq = order[first]
    edges = np.stack([lo[uniq], hi[uniq]], axis=1)
    # interior edges: consecutive equal keys in sorted order
    pair = np.nonzero(ks[1:] == ks[:-1])[0]
    bend = np.stack([opp[order[pair]], opp[order[pair + 1]]], axis=1)
    bend_edge = edge_id_sorted[pair]
    ok = bend[:, 0] != bend[:, 1]
    edge_face = np.stack([edge_id, face_of], axis=1)
    return edges, bend[ok], bend_edge[ok], edge_face


def triangle_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """``(f,)`` triangle areas in mm²."""
    v = vertices[faces]
    return 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)


@dataclass(frozen=True)
class BoneContact:
    """Each rest skin node's nearest point on the bone it goes with (mm, head frame).

    ``distance`` is the rest skin-bone distance (mm) and ``nearer_jaw`` marks
    lower-face nodes closer to the mandible than to the cranium.
    """

    points: np.ndarray
    distance: np.ndarray
    nearer_jaw: np.ndarray


def muscle_weights_per_node(
    n: int, nodes: np.ndarray | None, weights: np.ndarray | None, sim: np.ndarray
) -> np.ndarray:
    """``(n,)`` muscle weight per node, clipped to [0, 1]; 0 on kinematic nodes."""
    mw = np.zeros(n)
    if nodes is not None and len(nodes):
        mw[np.asarray(nodes, np.int64)] = np.clip(np.asarray(weights, float), 0, 1)
    mw[~sim] = 0.0
    return mw


def kinematic_jaw_share(bone: BoneContact, kinematic: np.ndarray, bone_max_mm: float) -> np.ndarray:
    """``(k, 1)`` share of the jaw's motion each kinematic node follows (0 = with the skull).

    Kinematic nodes nearer the mandible than the cranium follow the jaw fully
    within ``bone_max_mm`` of it and fade to the skull (as Breton's jaw region
    fades toward the neck, digest §12) over three more, so the opening jaw
    never cuts the neck skin.
    """
    near = bone.nearer_jaw[kinematic]
    fade = np.clip(1.0 - (bone.distance[kinematic] - bone_max_mm) / (3.0 * bone_max_mm), 0.0, 1.0)
    return np.where(near, fade, 0.0)[:, None]
