"""The face drawn in its chosen colours (issue 34, colouring): ``add_face(rgb=...)`` and
:func:`~workbench.render.visuals.face.paint_face` on an off-screen plotter (an icosphere of
radius 50 mm stands in for the fitted skin)."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.core.mesh import Mesh
from workbench.render.visuals import face, update


@pytest.fixture
def sphere() -> Mesh:
    import pyvista as pv

    ico = pv.Icosphere(radius=50.0, nsub=2)
    return Mesh(np.asarray(ico.points, float), np.asarray(ico.regular_faces, np.int64))


@pytest.fixture
def plotter():
    import pyvista as pv

    p = pv.Plotter(off_screen=True, window_size=(200, 160))
    yield p
    p.close()


def _drawn(actor) -> np.ndarray | None:
    from vtkmodules.util.numpy_support import vtk_to_numpy

    array = actor.GetMapper().GetInput().GetPointData().GetArray(face.FACE_COLOURS)
    return None if array is None else vtk_to_numpy(array)


def test_a_plain_face_is_painted_in_place_and_back(plotter, sphere: Mesh) -> None:
    rgb = np.zeros((sphere.n_vertices, 3), np.uint8)
    rgb[:, 0] = np.linspace(0, 255, sphere.n_vertices).astype(np.uint8)
    actor = face.add_face(plotter, sphere)
    assert face.face_plain(actor) and not face.face_painted(actor)
    assert face.paint_face(actor, rgb)
    assert face.face_painted(actor) and np.array_equal(_drawn(actor), rgb)
    assert actor.GetMapper().GetColorMode() == 2  # VTK_COLOR_MODE_DIRECT_SCALARS
    image = plotter.screenshot(None, return_img=True)
    assert image.std() > 0
    # the colours ride on the points: moving them keeps the colours
    update.move_points(actor, sphere.vertices * 1.1)
    assert np.array_equal(_drawn(actor), rgb)
    assert face.paint_face(actor, None)
    assert not face.face_painted(actor) and _drawn(actor) is None
    assert not face.paint_face(actor, rgb[:5])  # not one colour per point: nothing changes
    assert not face.face_painted(actor)


def test_a_face_coloured_by_a_value_is_left_alone(plotter, sphere: Mesh) -> None:
    actor = face.add_face(plotter, sphere, np.arange(sphere.n_vertices, dtype=float), "spread mm")
    rgb = np.full((sphere.n_vertices, 3), 200, np.uint8)
    assert not face.face_plain(actor)
    assert not face.paint_face(actor, rgb) and _drawn(actor) is None


def test_add_face_draws_given_colours(plotter, sphere: Mesh) -> None:
    rgb = np.full((sphere.n_vertices, 3), (160, 126, 86), np.uint8)
    actor = face.add_face(plotter, sphere, rgb=rgb)
    assert face.face_painted(actor) and np.array_equal(_drawn(actor), rgb)
    # a value map wins over colours
    other = face.add_face(plotter, sphere, np.zeros(sphere.n_vertices), "mm", rgb=rgb, name="x")
    assert not face.face_painted(other)
