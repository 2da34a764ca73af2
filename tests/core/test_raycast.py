"""Ray casting (workbench.core.raycast): Embree against the double-precision backend."""

from __future__ import annotations

import os

import numpy as np
import pytest
import pyvista as pv

from workbench.core.mesh import Mesh
from workbench.core.raycast import RayCaster, _brute_force, _unit
from workbench.core.spatial import MeshIndex
from workbench.io.meshes import read_mesh


@pytest.fixture(scope="module")
def skull(skull_obj) -> Mesh:
    return read_mesh(skull_obj, units="cm").mesh


@pytest.fixture(scope="module")
def casters(skull) -> tuple[RayCaster, RayCaster]:
    return RayCaster(skull, "embree"), RayCaster(skull, "numpy")


def sphere_mesh(radius: float = 50.0, resolution: int = 40) -> Mesh:
    s = pv.Sphere(radius=radius, theta_resolution=resolution, phi_resolution=resolution)
    return Mesh(np.asarray(s.points, float), s.regular_faces)


def skull_rays(skull: Mesh, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Half from a surrounding sphere toward the skull, half from near the surface, inward."""
    lo, hi = skull.bounds
    centre = 0.5 * (lo + hi)
    u = rng.normal(size=(n // 2, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    o1 = centre + u * np.linalg.norm(hi - lo)
    d1 = rng.uniform(lo, hi, (n // 2, 3)) - o1
    f = rng.integers(0, skull.n_faces, n - n // 2)
    base = skull.triangles[f].mean(axis=1)
    o2 = base + 3.0 * skull.face_normals[f]
    d2 = -skull.face_normals[f] + 0.3 * rng.normal(size=(len(f), 3))
    return np.vstack([o1, o2]), np.vstack([d1, d2])


def test_embree_and_numpy_backends_agree_on_real_skull(skull, casters):
    embree, reference = casters
    assert embree.backend == "embree"
    o, d = skull_rays(skull, 3000, np.random.default_rng(0))
    a = embree.first_hits(o, d)
    b = reference.first_hits(o, d)
    np.testing.assert_array_equal(a.hit, b.hit)
    assert 0.3 < a.hit.mean() < 1.0
    np.testing.assert_allclose(a.distance[a.hit], b.distance[b.hit], rtol=0, atol=1e-6)
    differ = a.face_ids != b.face_ids
    # different faces only at near-ties: shared edges or corners of the two faces
    assert differ.mean() < 0.01
    np.testing.assert_allclose(a.points[differ], b.points[differ], atol=1e-6)
    assert (a.face_ids[~a.hit] == -1).all() and np.isinf(a.distance[~a.hit]).all()
    assert np.isnan(a.points[~a.hit]).all()


def test_numpy_backend_matches_every_triangle_brute_force(skull, casters):
    _, reference = casters
    o, d = skull_rays(skull, 60, np.random.default_rng(1))
    hits = reference.first_hits(o, d)
    face, t = _brute_force(skull, o, _unit(d))
    np.testing.assert_array_equal(hits.face_ids >= 0, face >= 0)
    np.testing.assert_allclose(hits.distance[face >= 0], t[face >= 0], atol=1e-9)


def test_hit_points_lie_on_the_surface(skull, casters):
    index = MeshIndex(skull)
    o, d = skull_rays(skull, 3000, np.random.default_rng(2))
    for caster in casters:
        hits = caster.first_hits(o, d)
        assert index.closest_points(hits.points[hits.hit]).distances.max() < 1e-6
        # barycentric coordinates reproduce the point on the reported face
        tri = skull.triangles[hits.face_ids[hits.hit]]
        p = np.einsum("ij,ijk->ik", hits.barycentric[hits.hit], tri)
        np.testing.assert_allclose(p, hits.points[hits.hit], atol=1e-6)
        assert (hits.barycentric[hits.hit] > -1e-6).all()


@pytest.mark.parametrize("backend", ["embree", "numpy"])
def test_back_face_culling_on_a_closed_sphere(backend):
    radius = 50.0
    caster = RayCaster(sphere_mesh(radius), backend)
    rng = np.random.default_rng(3)
    d = rng.normal(size=(500, 3))
    inside = rng.uniform(-20, 20, (500, 3))
    # from inside every ray meets only back faces
    culled = caster.first_hits(inside, d, cull_backfaces=True)
    assert not culled.hit.any()
    plain = caster.first_hits(inside, d)
    assert plain.hit.all()
    # from outside, aimed through the centre, the front (near) side is hit
    u = d / np.linalg.norm(d, axis=1, keepdims=True)
    outside = 3 * radius * u
    front = caster.first_hits(outside, -u, cull_backfaces=True)
    assert front.hit.all()
    assert np.abs(front.distance - 2 * radius).max() < 0.5  # faceting error only
    facing = np.einsum("ij,ij->i", caster.mesh.face_normals[front.face_ids], -u)
    assert (facing < 0).all()
    # from outside, aimed away, nothing is hit
    assert not caster.first_hits(outside, u, cull_backfaces=True).hit.any()


@pytest.mark.parametrize("backend", ["embree", "numpy"])
def test_culling_skips_back_faces_to_reach_a_front_face(backend):
    # two nested spheres: from between them, outward rays see the outer
    # sphere's inside (a back face); inward rays see the inner sphere's front
    outer, inner = sphere_mesh(60.0), sphere_mesh(20.0)
    both = Mesh(
        np.vstack([outer.vertices, inner.vertices]),
        np.vstack([outer.faces, inner.faces + outer.n_vertices]),
    )
    caster = RayCaster(both, backend)
    o = np.array([[40.0, 0.0, 0.0]])
    hits = caster.first_hits(o, [[-1.0, 0.0, 0.0]], cull_backfaces=True)
    assert hits.hit[0] and abs(hits.distance[0] - 20.0) < 0.5
    assert not caster.first_hits(o, [[1.0, 0.0, 0.0]], cull_backfaces=True).hit[0]


@pytest.mark.parametrize("backend", ["embree", "numpy"])
def test_max_distance_is_respected(backend):
    caster = RayCaster(sphere_mesh(50.0), backend)
    o = np.zeros((3, 3))
    d = np.eye(3)
    free = caster.first_hits(o, d)
    assert free.hit.all()
    t = free.distance
    short = caster.first_hits(o, d, max_distance=float(t.min()) - 0.01)
    assert not short.hit.any()
    assert np.isinf(short.distance).all() and (short.face_ids == -1).all()
    long = caster.first_hits(o, d, max_distance=float(t.max()) + 0.01)
    np.testing.assert_allclose(long.distance, t)


@pytest.mark.parametrize("backend", ["embree", "numpy"])
def test_rays_through_shared_edges_and_corners_do_not_slip_through(backend):
    # octahedron: aim exactly at corners and edge midpoints
    v = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
    f = [[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]]
    caster = RayCaster(Mesh(v, f), backend)
    targets = np.vstack([v, 0.5 * (v[[0, 2, 1, 3]] + v[4]), 0.5 * (v[0] + v[2])[None]])
    origins = 3.0 * targets / np.linalg.norm(targets, axis=1, keepdims=True)
    hits = caster.first_hits(origins, targets - origins)
    assert hits.hit.all()
    np.testing.assert_allclose(hits.points, targets, atol=1e-6)


def test_directions_are_normalised_and_validated():
    caster = RayCaster(sphere_mesh(50.0), "numpy")
    hits = caster.first_hits([[0.0, 0.0, 0.0]], [[0.0, 0.0, 7.0]])
    assert abs(hits.distance[0] - 50.0) < 0.5  # t in mm, not in units of |d|
    with pytest.raises(ValueError):
        caster.first_hits([[0.0, 0.0, 0.0]], [[0.0, 0.0, 0.0]])
    with pytest.raises(ValueError):
        caster.first_hits(np.zeros((2, 3)), np.ones((3, 3)))
    with pytest.raises(ValueError):
        RayCaster(sphere_mesh(), "optix")


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


@pytest.mark.parametrize("mirror", [False, True])
def test_a_rigid_copy_casts_on_the_originals_scene_with_the_same_hits(skull, mirror):
    """Frame-aligned copies of a skull (a fit makes two) borrow the skull's
    scene; hits, distances and culling equal those of a scene of their own."""
    m = np.eye(4)
    m[:3, :3] = _rotation([0.3, 1.0, -0.2], 0.7) @ (np.diag([-1.0, 1, 1]) if mirror else np.eye(3))
    m[:3, 3] = [12.0, -40.0, 7.5]
    copy = skull.transformed(m)
    again = copy.transformed(np.linalg.inv(m))  # chains back to the first mesh
    assert copy.rigid_source[0] is skull and again.rigid_source[0] is skull
    np.testing.assert_allclose(again.rigid_source[1], np.eye(4), atol=1e-12)
    assert skull.scaled(2.0).rigid_source is None
    assert skull.transformed(np.diag([2.0, 2.0, 2.0, 1.0])).rigid_source is None

    borrowed = RayCaster.shared(copy)
    assert borrowed._scene is RayCaster.shared(skull)._scene  # no scene of its own
    own = RayCaster(copy, "embree")
    o, d = skull_rays(copy, 2000, np.random.default_rng(3))
    for cull in (False, True):
        a = borrowed.first_hits(o, d, cull_backfaces=cull)
        b = own.first_hits(o, d, cull_backfaces=cull)
        assert 0.3 < a.hit.mean() < 1.0
        same = a.hit == b.hit
        assert same.mean() > 0.998  # single-precision ties at edges aside
        both = a.hit & b.hit
        np.testing.assert_allclose(a.distance[both], b.distance[both], atol=1e-4)
        np.testing.assert_allclose(a.points[both], b.points[both], atol=1e-4)
    # rays from inside the bone leave it through back faces first: culling
    # must skip those on the borrowed scene exactly as on an own one
    f = np.random.default_rng(4).integers(0, copy.n_faces, 500)
    o = copy.triangles[f].mean(axis=1) - 0.2 * copy.face_normals[f]
    d = -copy.face_normals[f]
    a = borrowed.first_hits(o, d, cull_backfaces=True)
    b = own.first_hits(o, d, cull_backfaces=True)
    plain = borrowed.first_hits(o, d)
    assert (a.face_ids != plain.face_ids).mean() > 0.5
    assert (a.face_ids == b.face_ids).mean() > 0.99


@pytest.mark.parametrize("per_thread", [20_000, 100])
def test_embree_slabs_are_watertight_and_agree_with_one_scene(
    skull, casters, monkeypatch, per_thread
):
    """Many small scenes (slabs) give the hits of one: no ray slips through a
    seam between slabs, the nearest slab's hit wins (each slab is asked only for
    hits nearer than the last), face ids are global; also with the rays shared
    out among threads (``per_thread`` 100) and within a ``max_distance``."""
    import workbench.core.raycast as rc

    monkeypatch.setattr(rc, "EMBREE_CHUNK", 7_000)
    monkeypatch.setattr(rc, "EMBREE_RAYS_PER_THREAD", per_thread)
    monkeypatch.setenv("WORKBENCH_THREADS", "2")
    want = max(1, min(2, os.cpu_count() or 1, 4000 // per_thread))
    assert len(rc._blocks(4000, per_thread)) == want
    sliced = RayCaster(skull, "embree")
    assert len(sliced._scene) == -(-skull.n_faces // 7_000)
    reference = casters[1]
    o, d = skull_rays(skull, 3000, np.random.default_rng(5))
    # plus rays aimed at vertices and edge midpoints (seams of slabs run along edges)
    f = np.random.default_rng(6).integers(0, skull.n_faces, 500)
    tri = skull.triangles[f]
    aims = np.vstack([tri[:, 0], 0.5 * (tri[:, 0] + tri[:, 1])])
    normals = np.vstack([skull.face_normals[f]] * 2)
    o = np.vstack([o, aims + 20.0 * normals])
    d = np.vstack([d, -normals])
    for cull in (False, True):
        a = sliced.first_hits(o, d, cull_backfaces=cull)
        b = reference.first_hits(o, d, cull_backfaces=cull)
        np.testing.assert_array_equal(a.hit, b.hit)
        np.testing.assert_allclose(a.distance[a.hit], b.distance[b.hit], atol=1e-5)
        differ = a.face_ids != b.face_ids
        assert differ[:3000].mean() < 0.01  # random rays: rare ties
        # rays aimed at vertices and edges: either face of the tie, same point
        np.testing.assert_allclose(a.points[differ & a.hit], b.points[differ & a.hit], atol=1e-5)
    # (not near 20 mm, where all the aimed rays hit: float32 ties at the bound)
    near = 0.8 * float(np.median(b.distance[:3000][b.hit[:3000]]))
    a = sliced.first_hits(o, d, max_distance=near)
    b = reference.first_hits(o, d, max_distance=near)
    np.testing.assert_array_equal(a.hit, b.hit)
    assert 0.02 < a.hit.mean() < 0.5  # the bound cuts many hits, not all
    np.testing.assert_allclose(a.distance[a.hit], b.distance[b.hit], atol=1e-5)
