"""Closest points, signed distance and inside tests (workbench.core.spatial, core.bvh).

Every fast answer is checked against an independent slow one: closest points
against ``closest_on_triangles`` over *all* faces, the inside test against
ray parity (counting surface crossings with the ray caster).
"""

from __future__ import annotations

import numpy as np
import pytest
import pyvista as pv
from hypothesis import given, settings
from hypothesis import strategies as st

from workbench.core import spatial
from workbench.core.bvh import LeafTree
from workbench.core.mesh import Mesh
from workbench.core.raycast import RayCaster
from workbench.core.spatial import FIN_STRENGTH, MeshIndex, closest_on_triangles, winding_numbers
from workbench.io.meshes import read_mesh


@pytest.fixture(scope="module")
def skull(skull_obj) -> Mesh:
    return read_mesh(skull_obj, units="cm").mesh


@pytest.fixture(scope="module")
def skull_index(skull) -> MeshIndex:
    return MeshIndex(skull)


def sphere_mesh(radius: float = 50.0, resolution: int = 48) -> Mesh:
    s = pv.Sphere(radius=radius, theta_resolution=resolution, phi_resolution=resolution)
    return Mesh(np.asarray(s.points, float), s.regular_faces)


def brute_force(mesh: Mesh, points: np.ndarray, budget: int = 16_384):
    """Closest distance and face over every triangle, a few points at a time."""
    tri = mesh.triangles
    dist = np.full(len(points), np.inf)
    face = np.zeros(len(points), np.int64)
    for i, p in enumerate(points):
        for s in range(0, len(tri), budget):
            t = tri[s : s + budget]
            cp, _ = closest_on_triangles(np.broadcast_to(p, (len(t), 3)), t[:, 0], t[:, 1], t[:, 2])
            d = np.linalg.norm(cp - p, axis=1)
            j = int(d.argmin())
            if d[j] < dist[i]:
                dist[i], face[i] = d[j], s + j
    return dist, face


def surface_samples(mesh: Mesh, n: int, rng: np.random.Generator) -> np.ndarray:
    f = rng.integers(0, mesh.n_faces, n)
    w = rng.dirichlet(np.ones(3), n)
    return np.einsum("ij,ijk->ik", w, mesh.triangles[f])


def check_against_brute_force(mesh: Mesh, index: MeshIndex, points: np.ndarray) -> None:
    got = index.closest_points(points)
    dist, face = brute_force(mesh, points)
    scale = float(np.abs(mesh.vertices).max())
    np.testing.assert_allclose(got.distances, dist, rtol=0, atol=1e-12 * scale)
    # the reported face attains the minimum (ties between neighbours are allowed)
    tri = mesh.triangles[got.face_ids]
    cp, _ = closest_on_triangles(points, tri[:, 0], tri[:, 1], tri[:, 2])
    np.testing.assert_allclose(np.linalg.norm(cp - points, axis=1), dist, atol=1e-12 * scale)
    np.testing.assert_allclose(got.points, cp, atol=1e-12 * scale)
    # barycentric coordinates reproduce the point and lie in the triangle
    np.testing.assert_allclose(
        np.einsum("ij,ijk->ik", got.barycentric, tri), got.points, atol=1e-9 * scale
    )
    assert (got.barycentric >= -1e-12).all()
    np.testing.assert_allclose(got.barycentric.sum(axis=1), 1.0, atol=1e-12)


def test_closest_points_match_brute_force_on_real_skull(skull, skull_index):
    rng = np.random.default_rng(1)
    near = surface_samples(skull, 50, rng) + rng.normal(0, 2.0, (50, 3))
    lo, hi = skull.bounds
    far = rng.uniform(lo - 40, hi + 40, (30, 3))
    offset = surface_samples(skull, 20, rng) + 10 * rng.normal(size=(20, 3))
    check_against_brute_force(skull, skull_index, np.vstack([near, far, offset]))


def test_closest_points_match_brute_force_on_sphere():
    mesh = sphere_mesh(resolution=40)
    index = MeshIndex(mesh)
    rng = np.random.default_rng(2)
    pts = np.vstack(
        [
            rng.normal(size=(150, 3)) * 30,  # inside, near the centre (many near-ties)
            surface_samples(mesh, 150, rng) * rng.uniform(0.8, 1.2, (150, 1)),
            rng.uniform(-200, 200, (100, 3)),
        ]
    )
    check_against_brute_force(mesh, index, pts)


def test_points_on_the_surface_have_zero_distance(skull, skull_index):
    pts = surface_samples(skull, 3000, np.random.default_rng(3))
    got = skull_index.closest_points(pts)
    assert got.distances.max() < 1e-9
    np.testing.assert_allclose(got.points, pts, atol=1e-9)
    # the corners themselves, too
    assert skull_index.closest_points(skull.vertices[::50]).distances.max() < 1e-12


def test_results_do_not_depend_on_threads_or_order(skull, skull_index):
    rng = np.random.default_rng(4)
    pts = surface_samples(skull, 20_000, rng) + rng.normal(0, 3.0, (20_000, 3))
    a = skull_index.closest_points(pts)
    b = skull_index.closest_points(pts, workers=1)
    perm = rng.permutation(len(pts))
    c = skull_index.closest_points(pts[perm])
    np.testing.assert_array_equal(a.face_ids, b.face_ids)
    np.testing.assert_array_equal(a.distances, b.distances)
    np.testing.assert_allclose(c.distances, a.distances[perm], rtol=0, atol=1e-12)


def test_signed_distance_of_a_closed_sphere():
    radius = 50.0
    mesh = sphere_mesh(radius, 64)
    index = MeshIndex(mesh)
    rng = np.random.default_rng(5)
    u = rng.normal(size=(4000, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    r = rng.uniform(0.0, 2.0 * radius, 4000)
    r = r[np.abs(r - radius) > 1.0]  # further than the faceting error from the surface
    pts = u[: len(r)] * r[:, None]
    sd = index.signed_distance(pts)
    np.testing.assert_array_equal(sd < 0, r < radius)
    # magnitude: distance to the polyhedron lies within the faceting error of |r - R|
    assert np.abs(np.abs(sd) - np.abs(r - radius)).max() < 0.2
    np.testing.assert_array_equal(index.contains(pts), r < radius)


def test_winding_numbers_of_a_closed_sphere_compiled_and_numpy(monkeypatch):
    mesh = sphere_mesh(50.0, 24)
    rng = np.random.default_rng(8)
    u = rng.normal(size=(300, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    r = rng.uniform(0.0, 100.0, 300)
    r = r[np.abs(r - 50.0) > 2.0]
    pts = u[: len(r)] * r[:, None]
    w = winding_numbers(mesh, pts)
    np.testing.assert_allclose(w, (r < 50.0).astype(float), atol=1e-6)
    monkeypatch.setattr(spatial, "_winding_jit", None)
    np.testing.assert_allclose(winding_numbers(mesh, pts, block=10_000), w, atol=1e-9)


def knife_prism(half_angle_deg: float, length: float = 40.0, depth: float = 20.0) -> Mesh:
    """A closed triangular prism along z whose cross-section ends in a knife edge at x = 0."""
    h = length * np.tan(np.radians(half_angle_deg))
    section = np.array([[0.0, 0.0], [length, -h], [length, h]])  # counter-clockwise
    v = np.array([[x, y, z] for z in (0.0, depth) for x, y in section])
    faces = [[0, 2, 1], [3, 4, 5]]  # caps: -z, +z
    for i in range(3):
        j = (i + 1) % 3
        faces += [[i, j, j + 3], [i, j + 3, i + 3]]
    return Mesh(v, np.array(faces))


def test_a_knife_edge_is_doubted_and_signed_right():
    """A 4° wedge: the edge's two face normals are 176° apart, so the sign there comes
    from the winding number; it must agree with the geometry on both sides."""
    mesh = knife_prism(2.0)
    index = MeshIndex(mesh)
    rng = np.random.default_rng(9)
    # around the knife edge (x = 0, y = 0, 0 < z < 20): beyond it, above, below, and inside
    pts = np.column_stack(
        [rng.uniform(-3.0, 3.0, 2000), rng.uniform(-1.5, 1.5, 2000), rng.uniform(2, 18, 2000)]
    )
    h = pts[:, 0] * np.tan(np.radians(2.0))
    inside = (pts[:, 0] > 0) & (np.abs(pts[:, 1]) < h)
    margin = np.abs(np.abs(pts[:, 1]) - h) > 1e-6
    cl = index.closest_points(pts)
    strength = index.feature_strength(cl.face_ids, cl.barycentric)
    on_edge = (cl.barycentric <= 1e-9).any(axis=1)
    assert (strength[~on_edge] == 1.0).all()
    assert (strength[on_edge] < FIN_STRENGTH).sum() > 100
    np.testing.assert_array_equal((index.signed_distance(pts) < 0)[margin], inside[margin])


def ray_parity_inside(
    caster: RayCaster, points: np.ndarray, rng: np.random.Generator
) -> np.ndarray:
    """Inside by counting surface crossings along three random rays (majority vote)."""
    votes = np.zeros(len(points), int)
    for _ in range(3):
        d = rng.normal(size=(len(points), 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        o = points.copy()
        count = np.zeros(len(points), int)
        todo = np.arange(len(points))
        for _ in range(200):
            hits = caster.first_hits(o[todo], d[todo])
            count[todo[hits.hit]] += 1
            todo = todo[hits.hit]
            if len(todo) == 0:
                break
            # step well past the hit: Embree rounds origins to single precision
            o[todo] = hits.points[hits.hit] + 1e-3 * d[todo]
        votes += count % 2
    return votes >= 2


def test_contains_agrees_with_ray_parity_on_real_skull(skull, skull_index):
    rng = np.random.default_rng(6)
    lo, hi = skull.bounds
    pts = np.vstack(
        [
            rng.uniform(lo, hi, (1500, 3)),
            surface_samples(skull, 1500, rng) + rng.normal(0, 1.0, (1500, 3)),
        ]
    )
    sd = skull_index.signed_distance(pts)
    pts = pts[np.abs(sd) > 1e-3]
    inside = skull_index.contains(pts)
    parity = ray_parity_inside(RayCaster(skull), pts, rng)
    assert 0.1 < inside.mean() < 0.9
    np.testing.assert_array_equal(inside, parity)


def test_real_skull_signed_distance_is_continuous_across_the_surface(skull, skull_index):
    rng = np.random.default_rng(7)
    f = rng.integers(0, skull.n_faces, 500)
    centre = skull.triangles[f].mean(axis=1)
    n = skull.face_normals[f]
    # a little way out along the outward normal is outside, a little way in is inside
    step = 1e-4
    assert (skull_index.signed_distance(centre + step * n) > 0).all()
    assert (skull_index.signed_distance(centre - step * n) < 0).all()


def test_single_triangle_and_degenerate_faces():
    mesh = Mesh(
        [[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 2, 2], [3, 3, 3], [4, 4, 4]],
        [[0, 1, 2], [3, 4, 5], [3, 3, 3]],
    )
    index = MeshIndex(mesh)
    pts = np.array([[0.2, 0.2, 1.0], [5.0, 5.0, 5.0], [3.0, 3.0, 3.5], [-1.0, -1.0, 0.0]])
    got = index.closest_points(pts)
    dist, _ = brute_force(mesh, pts)
    np.testing.assert_allclose(got.distances, dist, atol=1e-14)
    np.testing.assert_allclose(got.distances[[0, 3]], [1.0, np.sqrt(2.0)])


def test_bad_inputs_are_refused():
    with pytest.raises(ValueError):
        MeshIndex(Mesh(np.zeros((3, 3))))
    index = MeshIndex(Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]]))
    with pytest.raises(ValueError):
        index.closest_points([[np.nan, 0, 0]])
    assert index.closest_points(np.zeros((0, 3))).distances.shape == (0,)


_coord = st.floats(-10, 10, allow_nan=False)
_point = st.tuples(_coord, _coord, _coord)


@settings(max_examples=200, deadline=None)
@given(p=_point, a=_point, b=_point, c=_point, squash=st.sampled_from([1.0, 1e-3, 0.0]))
def test_closest_on_triangle_is_optimal_and_matches_the_leaf_kernel(p, a, b, c, squash):
    """Two independent point-triangle formulas agree, including slivers and degenerate faces."""
    a, b, c = (np.array(x, float) for x in (a, b, c))
    c = a + squash * (c - a)  # squash = 0: collinear (or coincident) corners
    p = np.array(p, float)
    cp, bary = closest_on_triangles(p[None], a[None], b[None], c[None])
    d = np.linalg.norm(cp[0] - p)
    # no point of the triangle on a fine barycentric grid is closer
    g = np.linspace(0, 1, 41)
    u, v = np.meshgrid(g, g)
    keep = u + v <= 1
    grid = a + u[keep, None] * (b - a) + v[keep, None] * (c - a)
    assert d <= np.linalg.norm(grid - p, axis=1).min() + 1e-9
    assert (bary >= -1e-12).all() and abs(bary.sum() - 1) < 1e-12
    # the branch-free kernel of the leaf tree gives the same distance
    tree = LeafTree(Mesh(np.stack([a, b, c]), [[0, 1, 2]]))
    d2 = tree.leaf_distances(p[None], np.zeros(1, np.int64))
    scale = 1.0 + np.abs(np.stack([a, b, c, p])).max()
    assert abs(np.sqrt(d2.min()) - d) <= 1e-9 * scale


@settings(max_examples=40, deadline=None)
@given(
    n_faces=st.integers(1, 150),
    seed=st.integers(0, 2**32 - 1),
    spread=st.sampled_from([1e-3, 1.0, 100.0]),
)
def test_random_triangle_soups_match_brute_force(n_faces, seed, spread):
    """Small meshes exercise padding, empty leaves, slivers and repeated corners."""
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(n_faces + 2, 3)) * spread
    v[rng.random(len(v)) < 0.2] = v[0]  # coincident corners: degenerate faces
    f = rng.integers(0, len(v), (n_faces, 3))
    mesh = Mesh(v, f)
    index = MeshIndex(mesh)
    pts = np.vstack([rng.normal(size=(40, 3)) * spread * 2, v[:5]])
    got = index.closest_points(pts)
    dist, _ = brute_force(mesh, pts)
    np.testing.assert_allclose(got.distances, dist, rtol=0, atol=1e-12 * spread * 10)


@pytest.mark.parametrize("mirror", [False, True])
def test_a_rigid_copy_borrows_the_shared_index_and_answers_the_same(skull, mirror):
    from scipy.spatial.transform import Rotation

    m = np.eye(4)
    m[:3, :3] = Rotation.from_euler("xyz", (20.0, -35.0, 50.0), degrees=True).as_matrix()
    if mirror:
        m[:3, :3] = m[:3, :3] @ np.diag([-1.0, 1.0, 1.0])
    m[:3, 3] = (15.0, -200.0, 40.0)
    copy = skull.transformed(m)
    shared = MeshIndex.shared(copy)
    assert shared._base is MeshIndex.shared(skull)  # no tree of its own was built
    assert MeshIndex.shared(copy) is shared
    rng = np.random.default_rng(5)
    lo, hi = copy.bounds
    pts = rng.uniform(lo - 10.0, hi + 10.0, (3000, 3))
    got, want = shared.closest_points(pts), MeshIndex(copy).closest_points(pts)
    np.testing.assert_allclose(got.distances, want.distances, atol=1e-9)
    np.testing.assert_allclose(got.points, want.points, atol=1e-8)
    np.testing.assert_allclose(got.barycentric.sum(axis=1), 1.0, atol=1e-12)
    # (face ids may differ at exact ties: a closest vertex or edge shared by several faces)
    tri = copy.triangles[got.face_ids]
    on_face = (got.barycentric[:, :, None] * tri).sum(axis=1)
    np.testing.assert_allclose(on_face, got.points, atol=1e-8)
    np.testing.assert_array_equal(shared.contains(pts), MeshIndex(copy).contains(pts))
    # a copy that is not rigid (scaled) gets its own index
    scaled = skull.transformed(np.diag([1.1, 1.1, 1.1, 1.0]))
    assert MeshIndex.shared(scaled)._base is None


def _check_median_splits(points: np.ndarray, leaves: np.ndarray) -> None:
    """Every pair of sibling groups, at every level, is split at a median of its widest axis."""
    flat = leaves.ravel()
    assert sorted(flat[flat >= 0].tolist()) == list(range(len(points)))
    coords = np.full((len(flat), 3), np.inf)
    coords[flat >= 0] = points[flat[flat >= 0]]
    seg = len(flat)
    while seg > leaves.shape[1]:
        for start in range(0, len(flat), seg):
            group = coords[start : start + seg]
            real = np.isfinite(group[:, 0])
            if not real.any():
                continue
            axis = np.argmax(group[real].max(axis=0) - group[real].min(axis=0))
            low, high = group[: seg // 2, axis], group[seg // 2 :, axis]
            assert low.max() <= high.min()
        seg //= 2


@pytest.mark.parametrize("n_faces", [1, 7, 500, 4_099])
def test_compiled_tree_build_agrees_with_the_numpy_build(n_faces):
    """The numba build (bvh_build) and the numpy build give valid median splits, equal face
    frames, boxes that hold their leaves' corners, and the same closest points."""
    rng = np.random.default_rng(n_faces)
    v = rng.normal(size=(n_faces + 2, 3)) * 30.0
    v[rng.random(len(v)) < 0.1] = v[0]  # degenerate faces too
    mesh = Mesh(v, rng.integers(0, len(v), (n_faces, 3)))
    fast, slow = LeafTree(mesh), LeafTree(mesh, compiled=False)
    centroids = mesh.triangles.mean(axis=1)
    from workbench.core.bvh import _face_frames, _split_compiled, split_leaves

    _check_median_splits(centroids, _split_compiled(centroids))
    _check_median_splits(centroids, split_leaves(centroids))
    assert fast.leaf_faces.shape == slow.leaf_faces.shape
    want = _face_frames(mesh.triangles)[:, fast.leaf_faces]
    finite = np.isfinite(want)
    np.testing.assert_array_equal(np.isfinite(fast.table), finite)
    # the inverse squared edge lengths of slivers carry cancellation: relative tolerance
    np.testing.assert_allclose(fast.table[finite], want[finite], rtol=1e-6, atol=1e-9)
    for tree in (fast, slow):
        box = tree.obb32.astype(float)
        corners = mesh.triangles[tree.leaf_faces].reshape(tree.n_leaves, -1, 3) - tree.origin
        axes = box[:, 3:12].reshape(-1, 3, 3)
        np.testing.assert_allclose(
            axes @ np.swapaxes(axes, 1, 2), np.broadcast_to(np.eye(3), axes.shape), atol=1e-6
        )
        local = np.einsum("lkj,lcj->lck", axes, corners - box[:, None, :3])
        assert (np.abs(local) <= box[:, None, 12:] + 1e-5 * (1.0 + np.abs(corners).max())).all()
        # the leaves' axis-aligned boxes are their corners' (ties at a median, from the
        # repeated corners, may put faces in other leaves in the two builds)
        n = tree.n_leaves
        lo, hi = corners.min(axis=1) + tree.origin, corners.max(axis=1) + tree.origin
        assert (tree.aabb_lo[n:] <= lo).all() and (tree.aabb_hi[n:] >= hi).all()
        np.testing.assert_allclose(tree.aabb_lo[n:], lo, atol=1e-6)
        np.testing.assert_allclose(tree.aabb_hi[n:], hi, atol=1e-6)
    pts = rng.normal(size=(300, 3)) * 60.0
    a, b = MeshIndex(mesh), MeshIndex(mesh)
    b._tree = slow
    np.testing.assert_allclose(
        a.closest_points(pts).distances, b.closest_points(pts).distances, atol=1e-10
    )
