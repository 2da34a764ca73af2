"""Drawn meshes are copies: a view that moves drawn points in place never moves the mesh."""

from __future__ import annotations


def test_moving_drawn_points_leaves_the_mesh_as_it_was() -> None:
    """The build slider and drags move drawn points in place: the fit's own mesh (what is
    exported) must not move with them (VTK wraps float64 arrays without copying)."""
    import numpy as np

    from workbench.core.mesh import Mesh
    from workbench.render.snapshots import to_polydata

    mesh = Mesh(np.eye(3) * 10.0, np.array([[0, 1, 2]]))
    poly = to_polydata(mesh, normals=True)
    poly.points[0] = [5.0, 5.0, 5.0]
    assert np.array_equal(mesh.vertices, np.eye(3) * 10.0)
