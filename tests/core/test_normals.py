"""Surface normals (workbench.core.normals)."""

from __future__ import annotations

import numpy as np
import pytest
import pyvista as pv

from workbench.core.mesh import Mesh
from workbench.core.normals import (
    angle_weighted_vertex_normals,
    normals_within_radius,
    vertex_normals,
)
from workbench.core.spatial import MeshIndex
from workbench.io.meshes import read_mesh


def sphere_mesh(radius: float = 50.0, resolution: int = 60) -> Mesh:
    s = pv.Sphere(radius=radius, theta_resolution=resolution, phi_resolution=resolution)
    return Mesh(np.asarray(s.points, float), s.regular_faces)


def angle_deg(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    cos = np.einsum("ij,ij->i", u, v) / (np.linalg.norm(u, axis=1) * np.linalg.norm(v, axis=1))
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


@pytest.fixture(scope="module")
def skull(skull_obj) -> Mesh:
    return read_mesh(skull_obj, units="cm").mesh


def test_sphere_normals_point_radially_outward():
    mesh = sphere_mesh()
    radial = mesh.vertices / np.linalg.norm(mesh.vertices, axis=1, keepdims=True)
    for normals in (vertex_normals(mesh), angle_weighted_vertex_normals(mesh)):
        np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-12)
        assert angle_deg(normals, radial).max() < 1.0
    rng = np.random.default_rng(0)
    u = rng.normal(size=(300, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    averaged = normals_within_radius(mesh, 50.0 * u, radius_mm=8.0)
    np.testing.assert_allclose(np.linalg.norm(averaged, axis=1), 1.0, atol=1e-12)
    assert angle_deg(averaged, u).max() < 1.0
    # points a little off the surface get the same answer
    assert angle_deg(normals_within_radius(mesh, 51.0 * u, radius_mm=8.0), u).max() < 1.0


def test_face_normals_follow_the_winding():
    mesh = Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    np.testing.assert_allclose(mesh.face_normals, [[0, 0, 1]])
    np.testing.assert_allclose(vertex_normals(mesh), [[0, 0, 1]] * 3)
    flipped = Mesh(mesh.vertices, mesh.faces[:, ::-1])
    np.testing.assert_allclose(angle_weighted_vertex_normals(flipped), [[0, 0, -1]] * 3)


def test_isolated_vertices_get_zero_normals():
    mesh = Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 5, 5]], [[0, 1, 2]])
    for normals in (vertex_normals(mesh), angle_weighted_vertex_normals(mesh)):
        np.testing.assert_array_equal(normals[3], 0.0)
        np.testing.assert_allclose(normals[:3], [[0, 0, 1]] * 3)


def test_averaging_radius_smooths_normals_on_real_skull(skull):
    rng = np.random.default_rng(1)
    f = rng.integers(0, skull.n_faces, 400)
    start = skull.triangles[f].mean(axis=1)
    # neighbouring samples: a second point ~1 mm away, projected back onto the surface
    step = rng.normal(size=(400, 3))
    step -= np.einsum("ij,ij->i", step, skull.face_normals[f])[:, None] * skull.face_normals[f]
    step /= np.linalg.norm(step, axis=1, keepdims=True)
    index = MeshIndex(skull)
    neighbour = index.closest_points(start + 1.0 * step).points
    # 0 mm: the normal of the face under the point
    raw_a = skull.face_normals[index.closest_points(start).face_ids]
    raw_b = skull.face_normals[index.closest_points(neighbour).face_ids]
    raw = angle_deg(raw_a, raw_b)
    smooth = angle_deg(
        normals_within_radius(skull, start, 10.0, tree=index.centroid_tree),
        normals_within_radius(skull, neighbour, 10.0, tree=index.centroid_tree),
    )
    assert np.median(smooth) < 0.5 * np.median(raw)
    assert smooth.mean() < raw.mean()
    # smoothing over 10 mm still points the same way as the local surface
    local = normals_within_radius(skull, start, 10.0)
    assert np.median(angle_deg(local, raw_a)) < 30.0


def test_points_far_from_the_surface_fall_back():
    mesh = sphere_mesh(resolution=20)
    far = np.array([[500.0, 0.0, 0.0]])
    n = normals_within_radius(mesh, far, radius_mm=1.0)
    assert angle_deg(n, np.array([[1.0, 0.0, 0.0]]))[0] < 15.0
    given = normals_within_radius(mesh, far, radius_mm=1.0, fallback=np.array([[0.0, 0.0, 2.0]]))
    np.testing.assert_allclose(given, [[0.0, 0.0, 1.0]])
    with pytest.raises(ValueError):
        normals_within_radius(mesh, far, radius_mm=0.0)
