"""Muscle grids stored on the skin follow any deformation of the skin exactly."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.core.headgen.skin import build_skin
from workbench.core.tps import fit_warp
from workbench.model.muscles import MuscleGrid, SurfacePoints


@pytest.fixture(scope="module")
def skin():
    return build_skin("female")


def _grid(skin) -> MuscleGrid:
    rng = np.random.default_rng(3)
    faces = rng.integers(0, skin.mesh.n_faces, 6)
    bary = rng.dirichlet(np.ones(3), 6)
    return MuscleGrid(
        "zygomaticus_major_l",
        "zygomaticus major",
        "linear",
        "skull",
        "left",
        (2, 2, 2),
        SurfacePoints(faces, bary, np.full(6, 4.0)),
    )


def test_grid_points_follow_a_warp_of_the_skin(skin) -> None:
    grid = _grid(skin)
    on_surface = SurfacePoints(grid.points.faces, grid.points.barycentric)
    before = on_surface.evaluate(skin.mesh)
    warp = fit_warp(
        skin.landmarks.positions[:12], skin.landmarks.positions[:12] * 1.1 + [0.0, 2.0, 0.0]
    )
    warped = skin.mesh.with_vertices(warp(skin.mesh.vertices))
    after = on_surface.evaluate(warped)
    # points on the surface are barycentric combinations, so they follow the
    # warp of the triangle corners exactly (the warp itself is not affine)
    corners = warped.vertices[warped.faces[grid.points.faces]]
    assert np.allclose(after, np.einsum("ij,ijk->ik", grid.points.barycentric, corners))
    assert not np.allclose(before, after)
    # the pushed-in points sit 4 mm below the skin
    below = grid.points.evaluate(skin.mesh)
    assert np.allclose(np.linalg.norm(below - before, axis=1), 4.0)


def test_grid_state_round_trip_and_validation(skin) -> None:
    grid = _grid(skin)
    again = MuscleGrid.from_state(grid.to_state())
    assert np.array_equal(again.points.faces, grid.points.faces)
    assert np.array_equal(again.points.barycentric, grid.points.barycentric)
    assert [r.shape for r in again.rows(skin.mesh)] == [(2, 3)] * 3
    with pytest.raises(ValueError, match="row lengths"):
        MuscleGrid("x", "x", "linear", "skull", "left", (2, 2), grid.points)
    with pytest.raises(ValueError, match="axis"):
        MuscleGrid("x", "x", "sphincter", "skull", "left", (2, 2, 2), grid.points)
