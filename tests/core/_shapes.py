"""Small exactly known meshes shared by the core tests."""

from __future__ import annotations

import numpy as np

from workbench.core.mesh import Mesh

OCTA_V = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
OCTA_F = np.array(
    [[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]]
)


def octahedron() -> Mesh:
    return Mesh(OCTA_V, OCTA_F)


def subdivided_octahedron(levels: int) -> Mesh:
    """Closed, consistently wound sphere-like mesh by midpoint subdivision."""
    v, f = OCTA_V.copy(), OCTA_F.copy()
    for _ in range(levels):
        edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
        uniq, inv = np.unique(edges, axis=0, return_inverse=True)
        mid = len(v) + inv.reshape(3, -1)
        v = np.vstack([v, 0.5 * (v[uniq[:, 0]] + v[uniq[:, 1]])])
        a, b, c = f.T
        ab, bc, ca = mid
        f = np.concatenate(
            [np.stack(x, 1) for x in ([a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca])]
        )
    return Mesh(v / np.linalg.norm(v, axis=1, keepdims=True), f)
