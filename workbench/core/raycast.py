"""First-hit ray casting against a triangle mesh, many rays at once.

Units: origins and hit distances in mm, in the mesh's frame; directions need
not be normalised (they are normalised here, so ``t`` is always in mm).

One small interface, :class:`RayCaster`, with two backends:

``"embree"``
    Intel Embree through the ``embreex`` binding (BVHs over slabs of at
    most :data:`EMBREE_CHUNK` triangles, in single precision,
    robust (watertight) traversal; about 1 µs per ray).  Hits are re-measured
    in double precision on the hit triangle, so reported points lie on the
    triangle's plane to ~1e-12 mm.
``"numpy"``
    Double-precision Möller–Trumbore against the triangles of the leaves of
    :class:`workbench.core.bvh.LeafTree` that the ray passes through (a
    breadth-first slab test of the box tree, vectorised over rays).  An
    independent reference for the Embree backend and the fallback where
    embreex is not installed; roughly 20-100x slower than Embree.

Back-face culling (``cull_backfaces=True``) skips triangles whose outward
normal faces along the ray; used where a ray must not hit the inside of a
surface it starts behind (Kähler 2003, §8.4.3).
"""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np

from workbench.core.bvh import LeafTree
from workbench.core.mesh import Mesh
from workbench.core.threads import worker_count


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


def moller_trumbore(
    origins: np.ndarray, directions: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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


_SHARED_LOCK = threading.Lock()


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
        self._tree = LeafTree(mesh) if backend == "numpy" else None
        self._to_base: np.ndarray | None = None  # set on casters borrowing another's scene

    @staticmethod
    def shared(mesh: Mesh) -> RayCaster:
        """The one caster of ``mesh`` (built on first use, then reused; thread-safe).

        Building the embree scenes of a 100k-triangle skull takes ~110-160 ms
        (in GIL-holding steps of ~25 ms, see :func:`_build_embree`), so callers that cast
        against the same mesh object again and again share one.  The caster
        lives as long as the mesh (kept in the mesh's attribute dictionary).
        """
        return mesh.shared("_shared_ray_caster", _SHARED_LOCK, RayCaster, RayCaster._borrowed)

    @staticmethod
    def _borrowed(mesh: Mesh, base: RayCaster, to_base: np.ndarray) -> RayCaster:
        """A caster of ``mesh`` that casts against ``base``'s structure.

        ``mesh`` is a rigid copy of ``base.mesh`` (:meth:`Mesh.transformed`:
        same faces, same order) and ``to_base`` maps it onto the original.
        Rays are mapped into the original's frame, cast there, and the hits
        re-measured on ``mesh``'s own triangles; a rigid map keeps lengths,
        so distances and face ids carry over unchanged.  Saves rebuilding a
        scene (~110-160 ms, mostly holding the GIL) for every frame-aligned copy of a
        skull.
        """
        caster = object.__new__(RayCaster)
        caster.mesh, caster.backend = mesh, base.backend
        caster._scene, caster._tree = base._scene, base._tree
        caster._to_base = np.asarray(to_base, dtype=np.float64)
        return caster

    def first_hits(
        self,
        origins: np.ndarray,
        directions: np.ndarray,
        *,
        max_distance: float = np.inf,
        cull_backfaces: bool = False,
        max_skips: int = 8,
    ) -> RayHits:
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
            # (a hit farther than max_distance from its ray's own origin is no hit)
            limit = max_distance - float(start[todo].min())
            f_new, t_new = self._cast(o[todo] + start[todo, None] * d[todo], d[todo], limit)
            t_new = t_new + start[todo]
            face[todo], t[todo] = f_new, t_new
            if not cull_backfaces:
                break
            hit = f_new >= 0
            facing = np.einsum("ij,ij->i", self.mesh.face_normals[np.maximum(f_new, 0)], d[todo])
            back = hit & (facing > 0)
            if not back.any():
                break
            # restart just past the back face; Embree works in single
            # precision, so the step must exceed the rounding of the new origin
            rows = todo[back]
            magnitude = np.abs(o[rows]).max(axis=1) + t_new[back] + 1.0
            step = (1e-6 if self.backend == "embree" else 1e-12) * magnitude
            start[rows] = t_new[back] + step
            face[todo[back]], t[todo[back]] = -1, np.inf
            todo = todo[back]
        hit = (face >= 0) & (t <= max_distance)
        face = np.where(hit, face, -1)
        return self._finish(o, d, face, np.where(hit, t, np.inf))

    def _cast(
        self, o: np.ndarray, d: np.ndarray, limit: float = np.inf
    ) -> tuple[np.ndarray, np.ndarray]:
        if self._to_base is not None:
            rot = self._to_base[:3, :3]
            o, d = o @ rot.T + self._to_base[:3, 3], d @ rot.T
        if self.backend == "embree":
            return self._embree(o, d, limit)
        if self._tree is None:
            raise RuntimeError("numpy ray-casting backend without its leaf tree")
        return _tree_cast(self._tree, o, d)

    def _embree(
        self, o: np.ndarray, d: np.ndarray, limit: float = np.inf
    ) -> tuple[np.ndarray, np.ndarray]:
        """Nearest hit over all slabs: each slab is asked only for hits nearer than the
        best so far (Embree's ``tfar``, also capped at ``limit``), so a ray stops early in
        the slabs behind its hit; many rays are split among the worker threads (Embree
        casts with the GIL released; the scenes were committed when built)."""
        if self._scene is None:
            raise RuntimeError("embree ray-casting backend without its scenes")
        o32, d32 = np.ascontiguousarray(o, np.float32), np.ascontiguousarray(d, np.float32)
        # the limit in float32 one step up: rounding never loses a hit within it
        far = np.nextafter(np.float32(min(limit, 3e38)), np.float32(np.inf))
        face = np.full(len(o), -1, np.int64)
        tfar = np.full(len(o), far, np.float32)
        scenes = self._scene

        def cast(lo: int, hi: int) -> None:
            tf = tfar[lo:hi]  # a view: each slab's run lowers it where it hits
            for scene, ids in scenes:
                res = scene.run(o32[lo:hi], d32[lo:hi], dists=tf, output=1)
                hit = res["geomID"] >= 0
                face[lo:hi][hit] = ids[res["primID"][hit]]

        blocks = _blocks(len(o), EMBREE_RAYS_PER_THREAD)
        if len(blocks) == 1:
            cast(*blocks[0])
        else:
            with ThreadPoolExecutor(max_workers=len(blocks)) as pool:
                list(pool.map(lambda b: cast(*b), blocks))
        t = np.where(face >= 0, tfar.astype(np.float64), np.inf)
        return face, t

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
            close = np.abs(t_exact - t[hit]) < 1e-3 * (1 + t[hit])
            good = np.isfinite(t_exact) & (t_exact >= 0) & close
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


def _tree_cast(
    tree: LeafTree, o: np.ndarray, d: np.ndarray, chunk: int = 8192
) -> tuple[np.ndarray, np.ndarray]:
    """First hits (face id or -1, distance) through the leaves of ``tree``."""
    face = np.full(len(o), -1, np.int64)
    best = np.full(len(o), np.inf)
    lo, hi = tree.aabb_lo, tree.aabb_hi
    mask = np.int64(0xFFFFFFFF)
    for s in range(0, len(o), chunk):
        oo, dd = o[s : s + chunk], d[s : s + chunk]
        with np.errstate(divide="ignore"):
            inv = 1.0 / dd
        pairs = (np.arange(len(oo), dtype=np.int64) << 32) | 1
        for level in range(tree.depth + 1):
            q, node = pairs >> 32, pairs & mask
            oq, iq = np.take(oo, q, axis=0), np.take(inv, q, axis=0)
            with np.errstate(invalid="ignore"):
                t1 = (np.take(lo, node, axis=0) - oq) * iq
                t2 = (np.take(hi, node, axis=0) - oq) * iq
            # fmin/fmax skip the NaN of 0 * inf (a ray in a slab's plane)
            near = np.fmax.reduce(np.fmin(t1, t2), axis=1)
            far = np.fmin.reduce(np.fmax(t1, t2), axis=1)
            keep = ~(near > far) & ~(far < 0)
            pairs = np.compress(keep, pairs)
            if level < tree.depth:
                pairs = np.repeat(pairs + np.compress(keep, node), 2)
                pairs[1::2] += 1
        q, leaf = pairs >> 32, (pairs & mask) - tree.n_leaves
        if len(q) == 0:
            continue
        faces = tree.leaf_faces[leaf]  # (k, L)
        tri = tree.triangles[faces]
        k, n_l = faces.shape
        t, _, _ = moller_trumbore(
            np.repeat(oo[q], n_l, axis=0),
            np.repeat(dd[q], n_l, axis=0),
            tri[..., 0, :].reshape(-1, 3),
            tri[..., 1, :].reshape(-1, 3),
            tri[..., 2, :].reshape(-1, 3),
        )
        t = t.reshape(k, n_l)
        j = t.argmin(axis=1)
        tj = t[np.arange(k), j]
        sub_best = best[s : s + chunk]
        np.minimum.at(sub_best, q, tj)
        win = np.isfinite(tj) & (tj <= sub_best[q])
        face[s + q[win]] = faces[np.arange(k), j][win]
    return face, best


def _brute_force(mesh: Mesh, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First hits against every triangle, one ray at a time (reference for tests)."""
    tri = mesh.triangles
    a, b, c = (np.ascontiguousarray(tri[:, i]) for i in range(3))
    face = np.full(len(o), -1, np.int64)
    best = np.full(len(o), np.inf)
    for i in range(len(o)):
        t, _, _ = moller_trumbore(
            np.broadcast_to(o[i], a.shape), np.broadcast_to(d[i], a.shape), a, b, c
        )
        j = int(t.argmin())
        if np.isfinite(t[j]):
            face[i], best[i] = j, t[j]
    return face, best


def _embree_available() -> bool:
    try:
        import embreex  # noqa: F401
    except ImportError:
        return False
    return True


#: rays per thread below which one cast is not shared out among threads
EMBREE_RAYS_PER_THREAD = 20_000


def _blocks(n: int, least: int) -> list[tuple[int, int]]:
    """``[(start, stop)]`` of ``n`` rays in one block per worker thread, each ≥ ``least``."""
    parts = max(1, min(worker_count(), n // max(least, 1)))
    edges = np.linspace(0, n, parts + 1).astype(int)
    return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:], strict=True)]


#: triangles per Embree scene (see :func:`_build_embree`)
EMBREE_CHUNK = 25_000


def _build_embree(mesh: Mesh) -> list[tuple[Any, np.ndarray]]:
    """Embree scenes over slabs of the mesh: ``[(scene, face ids of its triangles)]``.

    Building one scene keeps the GIL for its whole length (~110 ms for
    100k triangles, plus ~30 ms committing it on the first query), which
    freezes the window's GUI thread even when a worker thread builds it.
    Slabs of at most :data:`EMBREE_CHUNK` triangles along the mesh's longest
    axis build in ~25 ms each, with the GIL free in between; each is
    committed here by one query.  A cast asks every slab and keeps the
    nearest hit (a few µs per ray more).
    """
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    tri = mesh.triangles.astype(np.float32)
    centres = tri.mean(axis=1)
    axis = int(np.argmax(np.ptp(centres, axis=0)))
    order = np.argsort(centres[:, axis], kind="stable")
    chunks = np.array_split(order, max(1, -(-len(order) // EMBREE_CHUNK)))
    probe = (np.zeros((1, 3), np.float32), np.array([[0.0, 0.0, 1.0]], np.float32))
    scenes = []
    for ids in chunks:
        scene = rtcore_scene.EmbreeScene(robust=True)  # watertight at shared edges
        TriangleMesh(scene=scene, vertices=tri[ids])
        scene.run(*probe, output=1)  # commit (build the BVH) now, not in a query
        scenes.append((scene, ids.astype(np.int64)))
    return scenes
