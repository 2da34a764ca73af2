"""Coarse-to-fine non-rigid registration: exactness, holes, extra parts, parts, stability."""

from __future__ import annotations

import numpy as np

from tests.core._shapes import subdivided_octahedron
from workbench.core.mesh import Mesh, concatenate
from workbench.core.nonrigid import Level, Target, folding_normals, register, soft_match
from workbench.core.spatial import MeshIndex

LEVELS = (Level(30.0, 1.0, 10.0, 6), Level(15.0, 0.5, 6.0, 6), Level(8.0, 0.4, 4.0, 6))


def _ellipsoid(axes, centre=(0.0, 0.0, 0.0), levels: int = 4) -> Mesh:
    s = subdivided_octahedron(levels)
    return Mesh(s.vertices * np.asarray(axes, float) + np.asarray(centre, float), s.faces)


def test_sphere_onto_an_ellipsoid():
    src = _ellipsoid((50, 50, 50))
    tgt = _ellipsoid((56, 47, 62), levels=5)
    reg = register(src, Target(tgt, np.ones(tgt.n_vertices)), levels=LEVELS)
    d = MeshIndex(tgt).closest_points(reg.vertices).distances
    assert np.percentile(d, 95) < 0.5
    assert (reg.weights > 0.5).mean() > 0.95


def test_a_hole_in_the_target_is_filled_by_the_template_shape():
    src = _ellipsoid((50, 50, 50))
    full = _ellipsoid((55, 55, 55), levels=5)
    keep = full.triangles.mean(axis=1)[:, 2] < 30.0  # the top cap is missing
    tgt = Mesh(full.vertices, full.faces[keep])
    w = np.ones(tgt.n_vertices)
    reg = register(src, Target(tgt, w), levels=LEVELS)
    r = np.linalg.norm(reg.vertices, axis=1)
    top = reg.vertices[:, 2] > 45.0
    # where there is data the fit is exact; the missing cap follows smoothly (no collapse)
    assert abs(np.median(r[~top & (reg.vertices[:, 2] < 20)]) - 55.0) < 0.5
    assert np.all(r[top] > 50.0) and np.all(r[top] < 60.0)
    assert (reg.weights[top] < 0.3).all()


def test_extra_anatomy_with_zero_weight_is_ignored():
    src = _ellipsoid((50, 50, 50))
    tgt_main = _ellipsoid((53, 53, 53), levels=5)
    spine = _ellipsoid((8, 30, 8), centre=(0, -75, -10), levels=3)
    tgt = concatenate([tgt_main, spine])
    w = np.r_[np.ones(tgt_main.n_vertices), np.zeros(spine.n_vertices)]
    reg = register(src, Target(tgt, w), levels=LEVELS)
    assert np.abs(np.linalg.norm(reg.vertices, axis=1) - 53.0).max() < 1.5


def test_parts_move_independently():
    a = _ellipsoid((20, 20, 20), centre=(-30, 0, 0), levels=3)
    b = _ellipsoid((20, 20, 20), centre=(30, 0, 0), levels=3)
    src = concatenate([a, b])
    parts = np.r_[np.zeros(a.n_vertices, int), np.ones(b.n_vertices, int)]
    tgt = concatenate(
        [
            _ellipsoid((20, 20, 20), centre=(-30, 0, 0), levels=4),
            _ellipsoid((20, 20, 20), centre=(30, 0, 8), levels=4),
        ]
    )
    reg = register(src, Target(tgt, np.ones(tgt.n_vertices)), parts=parts, levels=LEVELS)
    shift = reg.vertices - src.vertices
    assert np.abs(shift[: a.n_vertices]).max() < 0.8  # part a stays
    assert np.median(shift[a.n_vertices :, 2]) > 7.0  # part b moves up by 8 mm


def test_hard_constraints_are_met():
    src = _ellipsoid((50, 50, 50))
    tgt = _ellipsoid((50, 50, 50), levels=5)
    vid = int(np.argmax(src.vertices[:, 2]))
    goal = src.vertices[vid] + [6.0, 0.0, 0.0]
    reg = register(
        src, Target(tgt, np.ones(tgt.n_vertices)), levels=LEVELS, hard=(np.array([vid]), goal[None])
    )
    assert np.linalg.norm(reg.vertices[vid] - goal) < 1.5


def test_tiny_changes_of_the_target_change_little():
    src = _ellipsoid((50, 50, 50))
    tgt = _ellipsoid((56, 47, 62), levels=5)
    a = register(src, Target(tgt, np.ones(tgt.n_vertices)), levels=LEVELS).vertices
    rng = np.random.default_rng(0)
    moved = Mesh(tgt.vertices + 1e-9 * rng.standard_normal(tgt.vertices.shape), tgt.faces)
    b = register(src, Target(moved, np.ones(tgt.n_vertices)), levels=LEVELS).vertices
    assert np.abs(a - b).max() < 1e-4
    again = register(src, Target(tgt, np.ones(tgt.n_vertices)), levels=LEVELS).vertices
    np.testing.assert_array_equal(a, again)


def _folded_sheet(centre, size: float = 24.0, n: int = 7) -> Mesh:
    """A flat square wound both ways on the same vertices: its vertex normals cancel."""
    g = np.linspace(-size / 2, size / 2, n)
    xx, yy = np.meshgrid(g, g)
    v = np.column_stack([xx.ravel(), yy.ravel(), np.zeros(n * n)]) + np.asarray(centre, float)
    f = []
    for i in range(n - 1):
        for j in range(n - 1):
            a, b, c, d = i * n + j, i * n + j + 1, (i + 1) * n + j, (i + 1) * n + j + 1
            f += [(a, b, d), (a, d, c)]
    f = np.array(f)
    return Mesh(v, np.vstack([f, f[:, ::-1]]))


def test_folding_normals_fade_where_faces_fold_back():
    sheet = _folded_sheet((0.0, 0.0, 0.0))
    assert np.abs(np.linalg.norm(folding_normals(sheet), axis=1)).max() < 1e-12
    ball = _ellipsoid((50, 50, 50))
    length = np.linalg.norm(folding_normals(ball), axis=1)
    assert length.min() > 0.98 and length.max() <= 1.0 + 1e-12


def test_noise_on_a_folded_sheet_of_the_target_changes_little():
    """Back-to-back faces (a CT bone's thin sheets) must not flip their normals with noise."""
    src = _ellipsoid((50, 50, 50))
    tgt = concatenate([_ellipsoid((56, 47, 62), levels=5), _folded_sheet((0.0, 0.0, 63.0))])
    a = register(src, Target(tgt, np.ones(tgt.n_vertices)), levels=LEVELS).vertices
    rng = np.random.default_rng(1)
    moved = Mesh(tgt.vertices + 1e-9 * rng.standard_normal(tgt.vertices.shape), tgt.faces)
    b = register(src, Target(moved, np.ones(tgt.n_vertices)), levels=LEVELS).vertices
    assert np.abs(a - b).max() < 1e-4


def test_soft_match_prefers_the_surface_that_faces_the_same_way():
    # a query between two parallel walls facing opposite ways matches the agreeing one
    wall_out = np.array([[x, y, 2.0] for x in range(-3, 4) for y in range(-3, 4)], float)
    wall_in = wall_out - [0, 0, 3.0]
    cloud = np.vstack([wall_out, wall_in])
    normals = np.vstack(
        [np.tile([0, 0, 1.0], (len(wall_out), 1)), np.tile([0, 0, -1.0], (len(wall_in), 1))]
    )
    from scipy.spatial import cKDTree

    q = np.array([[0.0, 0.0, -0.5]])  # nearer the inner wall
    p, quality, dist, _, _ = soft_match(
        q, np.array([[0, 0, 1.0]]), cKDTree(cloud), cloud, normals, k=30
    )
    assert p[0, 2] > 1.5 and quality[0] > 0.9


def test_a_target_adopts_an_index_built_on_its_own_mesh_only():
    import pytest

    tgt = subdivided_octahedron(2)
    target = Target(tgt, np.ones(tgt.n_vertices))
    own = MeshIndex(tgt)
    target.use_index(own)
    assert target.index is own
    other = Target(tgt.with_vertices(tgt.vertices * 2.0), np.ones(tgt.n_vertices))
    with pytest.raises(ValueError, match="own mesh"):
        other.use_index(own)
