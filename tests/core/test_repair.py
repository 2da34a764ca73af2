"""Explicit mesh repairs (workbench.core.repair): each fixes exactly its defect."""

from __future__ import annotations

import numpy as np
import pytest
from _shapes import OCTA_F, OCTA_V, octahedron, subdivided_octahedron

from workbench.core.mesh import Mesh, validate
from workbench.core.repair import (
    clean,
    fill_small_holes,
    keep_largest_component,
    merge_close_vertices,
    remove_degenerate_faces,
    remove_duplicate_faces,
    remove_nonfinite,
    remove_unreferenced_vertices,
)

TETRA_V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float) + 5.0
TETRA_F = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])


def t_junction_degenerate() -> Mesh:
    """Octahedron with edge (0, 2) split on one side only, closed by a zero-area face."""
    v = np.vstack([OCTA_V, 0.5 * (OCTA_V[0] + OCTA_V[2])])
    f = OCTA_F.tolist()
    f.remove([0, 2, 4])
    f += [[0, 6, 4], [6, 2, 4], [2, 6, 0]]
    return Mesh(v, f)


def hole_sizes(mesh: Mesh) -> list[int]:
    return validate(mesh).to_dict()["hole_sizes"]


STRAY = np.array([[9.0, 9.0, 9.0]])  # an unreferenced vertex that must survive other repairs


def frozen_copy(mesh: Mesh) -> tuple[np.ndarray, np.ndarray]:
    return mesh.vertices.copy(), mesh.faces.copy()


def assert_unmutated(mesh: Mesh, saved: tuple[np.ndarray, np.ndarray]) -> None:
    np.testing.assert_array_equal(mesh.vertices, saved[0])
    np.testing.assert_array_equal(mesh.faces, saved[1])


def test_remove_nonfinite_removes_exactly_the_bad_vertex_and_its_faces():
    v = np.vstack([OCTA_V, STRAY])
    v[4] = np.nan
    mesh = Mesh(v, OCTA_F)
    saved = frozen_copy(mesh)
    fixed = remove_nonfinite(mesh)
    assert_unmutated(mesh, saved)
    assert fixed.changed and "1 non-finite vertices and 4 triangles" in fixed.message
    r = validate(fixed.mesh)
    assert r.nonfinite_vertices == 0 and r.degenerate_faces == 0
    assert fixed.mesh.n_faces == 4 and fixed.mesh.n_vertices == 6
    assert r.unreferenced_vertices == 1  # the stray vertex is not this repair's business
    np.testing.assert_array_equal(fixed.vertex_source, [0, 1, 2, 3, 5, 6])
    np.testing.assert_array_equal(fixed.mesh.vertices, v[fixed.vertex_source])


def test_remove_degenerate_faces():
    mesh = t_junction_degenerate()
    fixed = remove_degenerate_faces(mesh)
    assert fixed.message == "removed 1 degenerate triangles"
    assert validate(fixed.mesh).degenerate_faces == 0
    assert fixed.mesh.n_faces == mesh.n_faces - 1
    np.testing.assert_array_equal(fixed.mesh.vertices, mesh.vertices)
    # the crack the zero-area face was covering is now visible, not hidden
    assert validate(fixed.mesh).boundary_edges == 3


def test_remove_duplicate_faces_restores_the_octahedron():
    mesh = Mesh(OCTA_V, np.vstack([OCTA_F, OCTA_F[3], OCTA_F[5, ::-1]]))
    fixed = remove_duplicate_faces(mesh)
    assert fixed.message == "removed 2 duplicate triangles"
    assert fixed.mesh.equals(octahedron())
    assert validate(fixed.mesh).is_clean


def test_remove_unreferenced_vertices_renumbers():
    v = np.vstack([STRAY, OCTA_V, STRAY + 1])
    mesh = Mesh(v, OCTA_F + 1)
    fixed = remove_unreferenced_vertices(mesh)
    assert fixed.message == "removed 2 unreferenced vertices"
    assert fixed.mesh.equals(octahedron())
    np.testing.assert_array_equal(fixed.vertex_source, np.arange(1, 7))


def test_merge_close_vertices_welds_a_split_corner_only():
    # vertex 4 duplicated 1e-8 mm away; two faces use the copy
    v = np.vstack([OCTA_V, OCTA_V[4] + 1e-8, STRAY])
    f = OCTA_F.copy()
    f[[0, 1]] = np.where(f[[0, 1]] == 4, 6, f[[0, 1]])
    mesh = Mesh(v, f)
    assert validate(mesh).boundary_edges == 4  # the split opens a crack
    fixed = merge_close_vertices(mesh, tol_mm=1e-6)
    assert fixed.message == "merged 1 vertices closer than 1e-06 mm"
    assert fixed.mesh.n_vertices == 7  # the stray vertex stays
    np.testing.assert_array_equal(fixed.vertex_source, [0, 1, 2, 3, 4, 5, 7])
    assert validate(fixed.mesh).boundary_edges == 0
    assert validate(fixed.mesh).unreferenced_vertices == 1
    assert not merge_close_vertices(octahedron()).changed


def test_merge_ignores_nonfinite_vertices():
    v = np.vstack([OCTA_V, [[np.nan, 0, 0]], [[np.nan, 0, 0]]])
    assert not merge_close_vertices(Mesh(v, OCTA_F)).changed


def test_keep_largest_component_drops_only_the_other_pieces():
    v = np.vstack([OCTA_V, TETRA_V, STRAY])
    mesh = Mesh(v, np.vstack([TETRA_F + 6, OCTA_F]))
    fixed = keep_largest_component(mesh)
    assert "largest of 2 pieces (8 of 12 triangles)" in fixed.message
    r = validate(fixed.mesh)
    assert r.n_components == 1 and r.n_faces == 8
    assert r.unreferenced_vertices == 1  # the stray vertex was not part of a piece
    np.testing.assert_array_equal(fixed.vertex_source, [0, 1, 2, 3, 4, 5, 10])
    assert not keep_largest_component(octahedron()).changed


def holed_sphere() -> tuple[Mesh, int]:
    mesh = subdivided_octahedron(2)
    faces = mesh.faces
    share = lambda i, j: len(set(faces[i]) & set(faces[j]))  # noqa: E731
    far = [i for i in range(len(faces)) if share(0, i) == 0]
    pair = next((i, j) for i in far for j in far if i < j and share(i, j) == 2)
    keep = np.ones(len(faces), bool)
    keep[[0, *pair]] = False
    return Mesh(mesh.vertices, faces[keep]), mesh.n_vertices


def test_fill_small_holes_closes_small_holes_consistently():
    holed, n = holed_sphere()
    saved = frozen_copy(holed)
    only_small = fill_small_holes(holed, max_edges=3)
    assert_unmutated(holed, saved)
    assert only_small.message == "filled 1 holes of up to 3 edges"
    assert hole_sizes(only_small.mesh) == [4]
    both = fill_small_holes(holed, max_edges=4)
    r = validate(both.mesh)
    assert r.is_watertight and r.is_clean and r.inconsistent_orientation_edges == 0
    assert both.mesh.volume > 0
    np.testing.assert_array_equal(both.vertex_source, np.r_[np.arange(n), -1, -1])
    assert not fill_small_holes(both.mesh).changed


def test_fill_small_holes_keeps_big_holes():
    mesh = subdivided_octahedron(4)
    cap = mesh.triangles.mean(axis=1)[:, 2] > 0.9  # a polar cap: one hole of many edges
    holed = Mesh(mesh.vertices, mesh.faces[~cap])
    sizes = hole_sizes(holed)
    assert len(sizes) == 1 and sizes[0] > 30
    assert not fill_small_holes(holed, max_edges=30).changed
    assert validate(fill_small_holes(holed, max_edges=sizes[0]).mesh).is_watertight


@pytest.mark.parametrize(
    "repair",
    [
        remove_nonfinite,
        remove_degenerate_faces,
        remove_duplicate_faces,
        remove_unreferenced_vertices,
        merge_close_vertices,
        keep_largest_component,
        fill_small_holes,
    ],
)
def test_repairs_leave_clean_meshes_alone(repair):
    mesh = octahedron()
    result = repair(mesh)
    assert not result.changed and result.message == ""
    assert result.mesh.equals(mesh)
    np.testing.assert_array_equal(result.vertex_source, np.arange(6))


def test_clean_runs_the_safe_repairs_in_order():
    v = np.vstack([OCTA_V, [[np.nan, 0, 0]], STRAY])
    mesh = Mesh(v, np.vstack([OCTA_F, OCTA_F[0], [[0, 0, 1]]]))
    cleaned, messages = clean(mesh)
    assert validate(cleaned).is_clean
    assert cleaned.equals(octahedron())
    assert len(messages) == 4
