"""First-hit ray casting against a triangle mesh, many rays at once.

Units: origins and hit distances in mm, in the mesh's frame; directions need
not be normalised (they are normalised here, so ``t`` is always in mm).

One small interface, :class:`RayCaster`, with two backends:

``"embree"``
    Intel Embree through the ``embreex`` binding (a BVH in single precision;
    about 1 µs per ray).  Hits are re-measured in double precision on the hit
    triangle, so reported points lie on the triangle to ~1e-12 mm.
``"numpy"``
    Exact Möller–Trumbore against every triangle, in chunks.  Only sensible
    for small meshes or few rays; it exists as a reference implementation and
    as the fallback where embreex is not installed.

Back-face culling (``cull_backfaces=True``) skips triangles whose outward
normal faces along the ray; used where a ray must not hit the inside of a
surface it starts behind (Kähler 2003, §8.4.3).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from workbench.core.mesh import Mesh


@dataclass(frozen=True)
class RayHits:
    """First hits of ``k`` rays.

    Attributes
    ----------
    hit : (k,) bool
    distance : (k,) float64 mm along the unit direction (inf where no hit)
    points : (k, 3) float64 hit points (NaN where no hit)
    face_ids : (k,) int64 (-1 where no hit)
    barycentric : (k, 3) float64 (weights of the face's three corners)
    """

    hit: np.ndarray
    distance: np.ndarray
    points: np.ndarray
    face_ids: np.ndarray
    barycentric: np.ndarray


def _unit(directions: np.ndarray) -> np.ndarray:
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    n = np.linalg.norm(d, axis=1, keepdims=True)
    if (n == 0).any() or not np.isfinite(n).all():
        raise ValueError("ray directions must be finite and non-zero")
    return d / n


def moller_trumbore(origins: np.ndarray, directions: np.ndarray, a: np.ndarray, b: np.ndarray,
                    c: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ray/triangle intersection, element-wise over ``(k, 3)`` arrays.

    Returns ``t`` (inf where the ray misses the triangle's interior or hits
    behind the origin), and the barycentric ``u``, ``v`` of corners b and c.
    """
    e1, e2 = b - a, c - a
    pvec = np.cross(directions, e2)
    det = np.einsum("ij,ij->i", e1, pvec)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        tvec = origins - a
        u = np.einsum("ij,ij->i", tvec, pvec) * inv
        qvec = np.cross(tvec, e1)
        v = np.einsum("ij,ij->i", directions, qvec) * inv
        t = np.einsum("ij,ij->i", e2, qvec) * inv
    eps = 1e-12
    ok = (np.abs(det) > 1e-300) & (u >= -eps) & (v >= -eps) & (u + v <= 1 + eps) & (t >= 0)
    return np.where(ok, t, np.inf), u, v


class RayCaster:
    """Reusable ray-casting structure for one mesh."""

    def __init__(self, mesh: Mesh, backend: str = "auto"):
        if mesh.n_faces == 0:
            raise ValueError("cannot cast rays against a mesh without triangles")
        self.mesh = mesh
        if backend == "auto":
            backend = "embree" if _embree_available() else "numpy"
        if backend not in ("embree", "numpy"):
            raise ValueError(f"unknown ray-casting backend {backend!r}")
        self.backend = backend
        self._scene = _build_embree(mesh) if backend == "embree" else None

    def first_hits(self, origins: np.ndarray, directions: np.ndarray, *,
                   max_distance: float = np.inf, cull_backfaces: bool = False,
                   max_skips: int = 8) -> RayHits:
        """Nearest intersection of each ray ``origin + t·direction``, ``0 ≤ t ≤ max_distance``."""
        o = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
        d = _unit(directions)
        if len(o) != len(d):
            if len(o) == 1:
                o = np.repeat(o, len(d), axis=0)
            else:
                raise ValueError(f"{len(o)} origins but {len(d)} directions")
        face = np.full(len(o), -1, np.int64)
        t = np.full(len(o), np.inf)
        start = np.zeros(len(o))
        todo = np.arange(len(o))
        for _ in range(max_skips + 1):
            f_new, t_new = self._cast(o[todo] + start[todo, None] * d[todo], d[todo])
            t_new = t_new + start[todo]
            face[todo], t[todo] = f_new, t_new
            if not cull_backfaces:
                break
            hit = f_new >= 0
            facing = np.einsum("ij,ij->i", self.mesh.face_normals[np.maximum(f_new, 0)], d[todo])
            back = hit & (facing > 0)
            if not back.any():
                break
            # restart just past the back face
            start[todo[back]] = t_new[back] + 1e-7 * (1.0 + t_new[back])
            face[todo[back]], t[todo[back]] = -1, np.inf
            todo = todo[back]
        hit = (face >= 0) & (t <= max_distance)
        face = np.where(hit, face, -1)
        return self._finish(o, d, face, np.where(hit, t, np.inf))

    def _cast(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self.backend == "embree":
            face, t = self._embree(o, d)
            miss = np.flatnonzero(face < 0)
            if len(miss):
                # Embree's single-precision traversal is not watertight: a ray
                # through a shared edge or vertex can slip between the two
                # triangles.  Retry misses once with a tiny direction jitter;
                # _finish re-measures the hit along the original ray.
                jitter = np.random.default_rng(len(miss)).normal(size=(len(miss), 3)) * 1e-5
                f2, t2 = self._embree(o[miss], d[miss] + jitter)
                face[miss], t[miss] = f2, t2
            return face, t
        return _brute_force(self.mesh, o, d)

    def _embree(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        res = self._scene.run(o.astype(np.float32), d.astype(np.float32), output=1)
        face = res["primID"].astype(np.int64)
        face[res["geomID"] < 0] = -1
        return face, np.where(face >= 0, res["tfar"].astype(np.float64), np.inf)

    def _finish(self, o: np.ndarray, d: np.ndarray, face: np.ndarray, t: np.ndarray) -> RayHits:
        hit = face >= 0
        points = np.full((len(o), 3), np.nan)
        bary = np.full((len(o), 3), np.nan)
        if hit.any():
            tri = self.mesh.triangles[face[hit]]
            # re-measure in double precision against the hit triangle's plane
            n = self.mesh.face_cross[face[hit]]
            denom = np.einsum("ij,ij->i", n, d[hit])
            with np.errstate(divide="ignore", invalid="ignore"):
                t_exact = np.einsum("ij,ij->i", n, tri[:, 0] - o[hit]) / denom
            good = np.isfinite(t_exact) & (t_exact >= 0) & (np.abs(t_exact - t[hit]) < 1e-3 * (1 + t[hit]))
            t[hit] = np.where(good, t_exact, t[hit])
            p = o[hit] + t[hit, None] * d[hit]
            points[hit] = p
            bary[hit] = _barycentric(p, tri)
        return RayHits(hit, t, points, face, bary)


def _barycentric(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    v0, v1, v2 = b - a, c - a, p - a
    d00 = np.einsum("ij,ij->i", v0, v0)
    d01 = np.einsum("ij,ij->i", v0, v1)
    d11 = np.einsum("ij,ij->i", v1, v1)
    d20 = np.einsum("ij,ij->i", v2, v0)
    d21 = np.einsum("ij,ij->i", v2, v1)
    den = d00 * d11 - d01 * d01
    with np.errstate(divide="ignore", invalid="ignore"):
        v = (d11 * d20 - d01 * d21) / den
        w = (d00 * d21 - d01 * d20) / den
    return np.stack([1 - v - w, v, w], axis=1)


def _brute_force(mesh: Mesh, o: np.ndarray, d: np.ndarray,
                 budget: int = 2_000_000) -> tuple[np.ndarray, np.ndarray]:
    tri = mesh.triangles
    m = len(tri)
    face = np.full(len(o), -1, np.int64)
    best = np.full(len(o), np.inf)
    rays_per_chunk = max(1, budget // m)
    for s in range(0, len(o), rays_per_chunk):
        oo, dd = o[s:s + rays_per_chunk], d[s:s + rays_per_chunk]
        k = len(oo)
        t, _, _ = moller_trumbore(
            np.repeat(oo, m, axis=0), np.repeat(dd, m, axis=0),
            np.tile(tri[:, 0], (k, 1)), np.tile(tri[:, 1], (k, 1)), np.tile(tri[:, 2], (k, 1)),
        )
        t = t.reshape(k, m)
        j = t.argmin(axis=1)
        tj = t[np.arange(k), j]
        found = np.isfinite(tj)
        face[s:s + k] = np.where(found, j, -1)
        best[s:s + k] = tj
    return face, best


def _embree_available() -> bool:
    try:
        import embreex  # noqa: F401
    except ImportError:
        return False
    return True


def _build_embree(mesh: Mesh):  # noqa: ANN202 - embreex has no type stubs
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    scene = rtcore_scene.EmbreeScene()
    TriangleMesh(scene=scene, vertices=mesh.triangles.astype(np.float32))
    return scene
