"""Mesh value type and validate() (workbench.core.mesh) on meshes with known defects."""

from __future__ import annotations

import numpy as np
import pytest
from _shapes import OCTA_F, OCTA_V, octahedron, subdivided_octahedron

from workbench.core.mesh import Mesh, boundary_loops, validate
from workbench.io.meshes import read_mesh

TETRA_V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float) + 5.0
TETRA_F = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])

CLEAN = {
    "nonfinite_vertices": 0,
    "degenerate_faces": 0,
    "duplicate_faces": 0,
    "nonmanifold_edges": 0,
    "boundary_edges": 0,
    "holes": 0,
    "hole_sizes": [],
    "n_components": 1,
    "unreferenced_vertices": 0,
    "inconsistent_orientation_edges": 0,
    "watertight": True,
}


def report(mesh: Mesh) -> dict:
    d = validate(mesh).to_dict()
    return {k: d[k] for k in CLEAN}


def expect(**changes) -> dict:
    return CLEAN | changes


def t_junction_degenerate() -> Mesh:
    """Octahedron with edge (0, 2) split on one side only, closed by a zero-area face."""
    v = np.vstack([OCTA_V, 0.5 * (OCTA_V[0] + OCTA_V[2])])  # vertex 6 on edge 0-2
    f = OCTA_F.tolist()
    f.remove([0, 2, 4])
    f += [[0, 6, 4], [6, 2, 4], [2, 6, 0]]  # the last one has zero area
    return Mesh(v, f)


def test_clean_octahedron():
    mesh = octahedron()
    assert report(mesh) == CLEAN
    r = validate(mesh)
    assert r.is_clean and r.is_watertight and r.problems() == []
    assert mesh.volume == pytest.approx(4.0 / 3.0)
    assert "no problems found" in r.summary()


@pytest.mark.parametrize(
    ("build", "expected"),
    [
        (
            lambda: Mesh(np.vstack([OCTA_V, [[np.nan, 0, 0]]]), OCTA_F),
            expect(nonfinite_vertices=1, unreferenced_vertices=1),
        ),
        (t_junction_degenerate, expect(degenerate_faces=1)),
        (
            lambda: Mesh(OCTA_V, np.vstack([OCTA_F, OCTA_F[3]])),
            # the copy's three edges are now shared by three triangles
            expect(duplicate_faces=1, nonmanifold_edges=3, watertight=False),
        ),
        (
            lambda: Mesh(np.vstack([OCTA_V, [[5.0, 5.0, 5.0]]]), OCTA_F),
            expect(unreferenced_vertices=1),
        ),
        (
            lambda: Mesh(OCTA_V, np.vstack([OCTA_F[:5], OCTA_F[5, ::-1], OCTA_F[6:]])),
            expect(inconsistent_orientation_edges=3),
        ),
        (
            lambda: Mesh(np.vstack([OCTA_V, TETRA_V]), np.vstack([OCTA_F, TETRA_F + 6])),
            expect(n_components=2),
        ),
    ],
)
def test_single_defects_are_counted_exactly(build, expected):
    assert report(build()) == expected


def test_a_referenced_nan_vertex_also_makes_its_triangles_degenerate():
    v = OCTA_V.copy()
    v[4] = np.nan
    r = validate(Mesh(v, OCTA_F))
    assert r.nonfinite_vertices == 1
    assert r.degenerate_faces == 4  # the four faces around vertex 4
    assert np.isfinite(Mesh(v, OCTA_F).bounds).all()


def test_nonmanifold_edge_shared_by_three_triangles():
    v = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0], [0.5, 0, 1]], float)
    mesh = Mesh(v, [[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    r = validate(mesh)
    assert r.nonmanifold_edges == 1
    assert r.boundary_edges == 6 and sum(len(loop) for loop in r.boundary_loops) == 6
    assert r.n_components == 1 and not r.is_watertight and not r.is_clean


def test_two_holes_of_known_sizes():
    mesh = subdivided_octahedron(2)  # 128 faces
    faces = mesh.faces
    # one hole from one face, another (4 edges) from two adjacent faces far away
    first = 0
    share = lambda i, j: len(set(faces[i]) & set(faces[j]))  # noqa: E731
    far = [i for i in range(len(faces)) if share(first, i) == 0]
    pair = next(
        (i, j)
        for i in far
        for j in far
        if i < j and share(i, j) == 2 and all(share(first, k) == 0 for k in (i, j))
    )
    keep = np.ones(len(faces), bool)
    keep[[first, *pair]] = False
    holed = Mesh(mesh.vertices, faces[keep])
    assert report(holed) == expect(boundary_edges=7, holes=2, hole_sizes=[4, 3], watertight=False)
    loops = boundary_loops(holed)
    assert sorted(loops[1].tolist()) == sorted(faces[first].tolist())


def test_all_defects_together_add_up():
    base = t_junction_degenerate()  # 7 vertices, one zero-area face
    f = base.faces.copy()
    f[5] = f[5, ::-1]  # flip a face away from the T-junction
    v = np.vstack([base.vertices, TETRA_V, [[np.nan, 1, 1]], [[9, 9, 9]]])
    mesh = Mesh(v, np.vstack([f, TETRA_F + 7]))
    assert report(mesh) == expect(
        nonfinite_vertices=1,
        degenerate_faces=1,
        n_components=2,
        unreferenced_vertices=2,
        inconsistent_orientation_edges=3,
    )
    r = validate(mesh)
    assert r.component_face_counts == (10, 4)
    assert len(r.problems()) == 5


def test_real_skull_is_watertight_one_piece_and_clean(skull_obj):
    mesh = read_mesh(skull_obj, units="cm").mesh
    r = validate(mesh)
    assert r.is_watertight and r.is_clean
    assert r.n_components == 1 and r.inconsistent_orientation_edges == 0
    assert r.boundary_loops == ()
    assert mesh.volume > 0  # outward winding


def test_arrays_are_read_only_and_inputs_are_copied():
    v, f = OCTA_V.copy(), OCTA_F.copy()
    mesh = Mesh(v, f)
    v[0] = 99.0
    f[0] = [1, 1, 1]
    assert mesh.vertices[0, 0] == 1.0 and mesh.faces[0, 0] == 0
    for a in (
        mesh.vertices,
        mesh.faces,
        mesh.triangles,
        mesh.face_normals,
        mesh.face_areas,
        mesh.face_cross,
        mesh.bounds,
        mesh.edges_sorted,
    ):
        with pytest.raises(ValueError):
            a.flat[0] = 0


def test_operations_return_new_meshes_and_never_mutate():
    mesh = octahedron()
    before = mesh.vertices.copy(), mesh.faces.copy()
    mirror = np.diag([-1.0, 1.0, 1.0, 1.0])
    mirrored = mesh.transformed(mirror)
    assert mirrored.volume == pytest.approx(mesh.volume)  # winding flipped with the mirror
    assert validate(mirrored).inconsistent_orientation_edges == 0
    moved = mesh.transformed(np.array([[1, 0, 0, 5], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]]))
    np.testing.assert_allclose(moved.vertices, mesh.vertices + [5, 0, 0])
    assert mesh.scaled(2.0).volume == pytest.approx(8 * mesh.volume)
    assert mesh.with_vertices(mesh.vertices * 3).equals(mesh.scaled(3.0))
    validate(mesh)
    np.testing.assert_array_equal(mesh.vertices, before[0])
    np.testing.assert_array_equal(mesh.faces, before[1])
    with pytest.raises(ValueError):
        mesh.with_vertices(np.zeros((2, 3)))
    with pytest.raises(ValueError):
        Mesh(OCTA_V, [[0, 1, 6]])


def test_empty_mesh_validates():
    r = validate(Mesh(np.zeros((0, 3))))
    assert r.n_faces == 0 and r.n_components == 0
    assert "no triangles" in r.problems()[0]


def test_open_face_edges_mark_the_boundary() -> None:
    """A square of two triangles: the diagonal is shared, the four sides are open."""
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    m = Mesh(v, np.array([[0, 1, 2], [0, 2, 3]]))
    # face 0: (0,1) open, (1,2) open, (2,0) the diagonal; face 1: (0,2) diagonal, (2,3), (3,0)
    np.testing.assert_array_equal(m.open_face_edges, [[True, True, False], [False, True, True]])
    assert not subdivided_octahedron(2).open_face_edges.any()


@pytest.mark.parametrize("copy", ["rigid", "mirrored", "with_vertices", "reversed_winding"])
def test_copies_take_over_the_connectivity_and_it_is_what_they_would_compute(copy) -> None:
    """Copies with the same (or corner-reversed) faces carry the original's cached edges,
    boundary and components instead of recomputing them; each equals a fresh computation."""
    rng = np.random.default_rng(3)
    base = subdivided_octahedron(2)
    keep = rng.random(base.n_faces) > 0.15  # holes, so boundaries and several pieces
    mesh = Mesh(base.vertices, base.faces[keep])
    filled = (mesh.open_face_edges, mesh.face_components, mesh.vertex_faces_matrix)
    assert all(x is not None for x in filled)  # the caches are filled
    mirror = np.diag([-1.0, 1.0, 1.0, 1.0])
    out = {
        "rigid": lambda: mesh.transformed(
            np.array([[0, -1, 0, 5], [1, 0, 0, 0], [0, 0, 1, 2], [0, 0, 0, 1.0]])
        ),
        "mirrored": lambda: mesh.transformed(mirror),
        "with_vertices": lambda: mesh.with_vertices(mesh.vertices * 2.0),
        "reversed_winding": mesh.reversed_winding,
    }[copy]()
    assert "_unique_edges" in out.__dict__ and "open_face_edges" in out.__dict__  # taken over
    fresh = Mesh(out.vertices, out.faces)
    np.testing.assert_array_equal(out.edges_sorted, fresh.edges_sorted)
    for got, want in zip(out._unique_edges, fresh._unique_edges, strict=True):
        np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(out.open_face_edges, fresh.open_face_edges)
    np.testing.assert_array_equal(out.face_components, fresh.face_components)
    assert (out.vertex_faces_matrix != fresh.vertex_faces_matrix).nnz == 0
    assert [len(x) for x in boundary_loops(out)] == [len(x) for x in boundary_loops(fresh)]
