"""``workbench.core.visibility``: walls of a cavity are not seen from outside (mm)."""

from __future__ import annotations

import numpy as np

from workbench.core.mesh import Mesh, concatenate
from workbench.core.visibility import seen_from_outside


def _sphere(radius: float, centre=(0.0, 0.0, 0.0), n: int = 24) -> Mesh:
    """A UV sphere wound outward (mm)."""
    th = np.linspace(0, np.pi, n + 1)[1:-1]
    ph = np.linspace(0, 2 * np.pi, 2 * n, endpoint=False)
    t, p = np.meshgrid(th, ph, indexing="ij")
    ring = np.column_stack(
        [
            np.sin(t).ravel() * np.cos(p).ravel(),
            np.sin(t).ravel() * np.sin(p).ravel(),
            np.cos(t).ravel(),
        ]
    )
    v = np.vstack([[0, 0, 1], ring, [0, 0, -1]]) * radius + centre
    m, k = len(th), len(ph)
    idx = lambda i, j: 1 + i * k + (j % k)  # noqa: E731
    faces = [(0, idx(0, j), idx(0, j + 1)) for j in range(k)]
    for i in range(m - 1):
        for j in range(k):
            a, b, c, d = idx(i, j), idx(i, j + 1), idx(i + 1, j), idx(i + 1, j + 1)
            faces += [(a, c, b), (b, c, d)]
    last = len(v) - 1
    faces += [(idx(m - 1, j), last, idx(m - 1, j + 1)) for j in range(k)]
    mesh = Mesh(v, np.array(faces))
    # wind outward whatever the construction did
    if np.einsum("ij,ij->", mesh.face_normals, mesh.vertices[mesh.faces].mean(1) - centre) < 0:
        mesh = Mesh(v, mesh.faces[:, ::-1])
    return mesh


def test_outer_surface_seen_cavity_walls_hidden():
    outer = _sphere(45.0)
    cavity = _sphere(10.0, centre=(0.0, -10.0, 15.0))  # an "airway" inside the head
    mesh = concatenate([outer, cavity])
    seen = seen_from_outside(mesh)
    assert seen[: outer.n_vertices].all()
    assert not seen[outer.n_vertices :].any()


def test_far_surfaces_do_not_block():
    # a second body 300 mm away (beyond the blocking range) does not hide the first
    a, b = _sphere(20.0), _sphere(40.0, centre=(0.0, 0.0, 320.0))
    seen = seen_from_outside(concatenate([a, b]))
    assert seen.all()
    # within range, a surface facing another closely (a chin over the chest) is hidden
    near = _sphere(40.0, centre=(0.0, 0.0, 70.0))
    seen = seen_from_outside(concatenate([a, near]))[: a.n_vertices]
    n = a.vertices / 20.0
    assert not seen[n[:, 2] > 0.97].any()
    assert seen[n[:, 2] < 0.0].all()


def test_field_of_view_caps_are_the_flat_lids_on_the_box():
    from workbench.core.visibility import field_of_view_caps

    # a sphere cut flat at z = -30 (a CT volume ending below the chin), the cut closed by a lid
    ball = _sphere(50.0, n=40)
    v = ball.vertices.copy()
    v[:, 2] = np.maximum(v[:, 2], -30.0)
    caps = field_of_view_caps(Mesh(v, ball.faces))
    lid = v[:, 2] <= -30.0 + 1e-9
    inner = lid & (np.hypot(v[:, 0], v[:, 1]) < 35.0)  # away from the lid's rim
    assert caps[inner].all()
    assert not caps[v[:, 2] > -29.0].any()  # the round surface is skin, even at its poles


def test_what_is_seen_does_not_depend_on_the_axes_or_the_winding():
    """A rotated, mirrored or rewound copy sees the same vertices: the cone of rays turns
    with the surface (toward a neighbour), not with the file's axes."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(4)
    base = _sphere(40.0, n=20)
    # deep bumps and pits: many vertices are seen along only some rays of their cone
    bumpy = base.with_vertices(base.vertices * rng.uniform(0.6, 1.4, (base.n_vertices, 1)))
    seen = seen_from_outside(bumpy, min_free=4)
    assert 0.05 < 1.0 - seen.mean() < 0.95  # the cone decides for many vertices
    rot = np.eye(4)
    rot[:3, :3] = Rotation.from_euler("xyz", (30.0, 40.0, 50.0), degrees=True).as_matrix()
    mirror = rot @ np.diag([-1.0, 1.0, 1.0, 1.0])
    for copy in (bumpy.transformed(rot), bumpy.transformed(mirror)):
        assert (seen_from_outside(copy, min_free=4) != seen).sum() <= 2  # float32 grazes
    rewound = bumpy.reversed_winding()
    normals = -rewound.vertex_normals  # outward, as the caller says
    assert (seen_from_outside(rewound, normals=normals, min_free=4) != seen).sum() <= 2
