"""The window's visuals (``workbench.render.visuals``) drawn into an off-screen plotter.

Small synthetic meshes (an icosphere of radius 50 mm, its own frame); each test checks
what a visual puts in the plotter (names, colours, sizes, colour bars, culling) and that
the in-place updates move exactly the drawn data.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import pytest

from workbench.core.mesh import Mesh
from workbench.render.visuals import face, markers, muscles, scalar_bars, skull, update
from workbench.render.visuals.style import BONE, SKIN


@pytest.fixture
def sphere() -> Mesh:
    """A fresh sphere per test: a drawn surface may share its points with the mesh."""
    import pyvista as pv

    ico = pv.Icosphere(radius=50.0, nsub=2)
    return Mesh(np.asarray(ico.points, float), np.asarray(ico.regular_faces, np.int64))


@pytest.fixture
def plotter():
    import pyvista as pv

    p = pv.Plotter(off_screen=True, window_size=(200, 160))
    yield p
    p.close()


def _colour(actor) -> tuple[int, ...]:
    """The actor's colour in 8-bit steps (pyvista stores colours as bytes)."""
    return tuple(round(c * 255) for c in actor.GetProperty().GetColor())


def _rgb8(colour) -> tuple[int, ...]:
    return tuple(round(c * 255) for c in colour)


def test_the_visuals_import_without_qt() -> None:
    script = textwrap.dedent("""
        import importlib, pkgutil, sys
        class Block:
            def find_spec(self, name, path=None, target=None):
                if name.split('.')[0] in {'PySide6', 'pyvistaqt', 'qtpy'}:
                    raise ImportError('no Qt in render: ' + name)
        sys.meta_path.insert(0, Block())
        import workbench.render.visuals as pkg
        for info in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + '.'):
            importlib.import_module(info.name)
        print('ok')
    """)
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, check=False
    )
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr


def test_scalar_bar_arguments_and_visibility(plotter, sphere) -> None:
    args = scalar_bars.bar_args("signed mm", n_labels=6)
    assert args["title"] == "signed mm" and args["n_labels"] == 6
    assert args["vertical"] and args["render"] is False and args["position_x"] == 0.82
    assert "title" not in scalar_bars.SCALAR_BAR  # the shared settings stay untitled
    face.add_truth(plotter, sphere, np.linspace(-3, 3, sphere.n_vertices))
    assert "signed mm" in plotter.scalar_bars
    scalar_bars.set_bar_visible(plotter, "signed mm", False)
    assert not plotter.scalar_bars["signed mm"].GetVisibility()
    scalar_bars.set_bar_visible(plotter, "no such bar", False)  # nothing to hide: no error


def test_skull_and_faces_have_their_colours_names_and_culling(plotter, sphere) -> None:
    bone = skull.add_skull(plotter, sphere, name="layer_skull", pickable=True)
    assert _colour(bone) == _rgb8(BONE) and bone.GetPickable()
    assert not bone.GetProperty().GetBackfaceCulling()
    skin = face.add_face(plotter, sphere)
    assert _colour(skin) == _rgb8(SKIN) and not skin.GetPickable()
    assert skin.GetProperty().GetBackfaceCulling()  # translucent layers: no sorting
    assert {"layer_skull", "layer_face"} <= set(plotter.renderer.actors)
    # with values: coloured by them, the bar titled as asked
    values = np.linspace(0.0, 7.0, sphere.n_vertices)
    coloured = face.add_face(plotter, sphere, values, "spread mm")
    assert plotter.renderer.actors["layer_face"] is coloured  # replaced by name
    assert "spread mm" in plotter.scalar_bars
    np.testing.assert_allclose(coloured.GetMapper().GetScalarRange(), (0.0, 7.0))
    truth = face.add_truth(plotter, sphere, np.full(sphere.n_vertices, 9.0), limit_mm=4.0)
    assert truth.GetMapper().GetScalarRange() == (-4.0, 4.0)
    gv = face.add_guide_face(plotter, sphere)
    assert gv.GetProperty().GetOpacity() == pytest.approx(face.GUIDE_FACE_OPACITY)


def test_the_scan_is_coloured_only_by_a_distance_per_vertex(plotter, sphere) -> None:
    distance = np.linspace(0.0, 3.0, sphere.n_vertices)
    distance[:5] = np.nan
    actor, poly = face.add_scan(plotter, sphere, distance, title="d mm", clim=(0.0, 2.5))
    assert actor.GetPickable() and "d mm" in poly.point_data
    assert actor.GetMapper().GetScalarRange() == (0.0, 2.5)
    grey, poly = face.add_scan(plotter, sphere, distance[:-1], title="d mm", clim=(0.0, 2.5))
    assert "d mm" not in poly.point_data and _colour(grey) == _rgb8(face.SCAN_GREY)


def test_landmark_markers_by_status_and_the_selected_one(plotter) -> None:
    pts = np.array([[0.0, 0, 0], [10, 0, 0], [20, 0, 0]])
    actors = markers.add_status_markers(
        plotter, pts, ["placed", "suggested", "placed"], markers.STATUS_COLOURS, 12.0, "lm_"
    )
    assert [a.GetMapper().GetInput().GetNumberOfPoints() for a in actors] == [2, 1]
    assert {"lm_placed", "lm_suggested"} <= set(plotter.renderer.actors)
    assert all(a.GetProperty().GetRenderPointsAsSpheres() and not a.GetPickable() for a in actors)
    sel = markers.add_selected(plotter, pts[1], 12.0, "lm_selected")
    assert sel.GetProperty().GetPointSize() == pytest.approx(12.0 * 1.8)
    assert _colour(sel) == _rgb8(markers.SELECTED)
    label = markers.add_label(plotter, pts[1], "g: Glabella", "lm_label")
    assert label is not None and any(k.startswith("lm_label") for k in plotter.renderer.actors)
    # statuses with a space are named with an underscore
    over = markers.add_status_markers(
        plotter, pts[:1], ["over hole"], {"over hole": (0.6, 0.4, 0.9)}, 10.0, "scan_"
    )
    assert len(over) == 1 and "scan_over_hole" in plotter.renderer.actors


def test_line_sets_of_dowels_and_guides(plotter) -> None:
    origins = np.zeros((3, 3))
    tips = np.array([[0.0, 0, 5], [0, 6, 0], [7, 0, 0]])
    lines = markers.segments(origins, tips)
    assert lines.n_lines == 3 and lines.n_points == 6
    np.testing.assert_allclose(np.ptp(lines.points, axis=0), [7, 6, 5])
    pegs, tip_points = markers.add_dowels(plotter, origins, tips, 12.0)
    assert pegs.GetProperty().GetLineWidth() == 4
    assert tip_points.GetProperty().GetPointSize() == pytest.approx(9.6)
    guides = markers.add_guides(plotter, [(origins[0], tips[0])], np.zeros((0, 3)), 12.0)
    assert len(guides) == 1 and guides[0].GetMapper().GetInput().n_lines == 1
    sets = markers.add_guide_set(
        plotter, [np.array([[0.0, 0, 0], [0, 1, 0]])], [np.array([[1.0, 1, 1]])], (1, 0, 1), 4, "gv"
    )
    assert set(sets) == {"lines", "points"}
    assert {"gv_lines", "gv_points"} <= set(plotter.renderer.actors)
    marks = markers.add_measure_marks(plotter, tips, tips[:1], ["aperture"])
    assert len(marks) == 2 and _colour(marks[0]) == _rgb8(markers.MEASURE)


def test_muscle_sheets_and_fibres_share_their_points(plotter) -> None:
    rows = [np.array([[0.0, 0, 0], [10, 0, 0], [20, 0, 0]]), np.array([[0.0, 10, 0], [20, 10, 0]])]
    points, faces, lines = muscles.muscle_geometry([rows])
    assert points.shape == (6, 3) and faces.shape == (4, 3)
    np.testing.assert_allclose(points[4], [10, 10, 0])  # the short row resampled by length
    assert len(lines) == 2 + 3  # rows and columns
    actors, n_faces, n_lines = muscles.add_muscles(plotter, [rows])
    assert (len(actors), n_faces, n_lines) == (2, 4, 5)
    assert muscles.add_muscles(plotter, []) == ([], 0, 0)


def test_points_move_in_place_with_their_normals(plotter, sphere) -> None:
    values = np.linspace(0.0, 1.0, sphere.n_vertices)
    actor = face.add_face(plotter, sphere, values, "mm")
    moved = sphere.vertices * 1.5 + [0.0, 0.0, 10.0]
    update.move_points(actor, moved)
    data = update.source_data(actor)
    np.testing.assert_allclose(update.drawn_points(data), moved)
    normals = np.asarray(data.GetPointData().GetNormals())
    np.testing.assert_allclose(normals, Mesh(moved, sphere.faces).vertex_normals, atol=1e-9)
    with pytest.raises(ValueError, match="points"):
        update.move_points(actor, moved[:-1])
    # markers: a range of points overwritten
    dots = markers.add_markers(plotter, np.zeros((4, 3)), (1, 1, 1), 5.0, "dots")
    update.set_input_points(dots, np.ones((2, 3)), first=1)
    got = update.drawn_points(dots.GetMapper().GetInput())
    np.testing.assert_allclose(got[:, 0], [0, 1, 1, 0])
    # a surface with or without its vertex-face matrix gets the same normals
    bone = skull.add_skull(plotter, sphere, name="s", pickable=False)
    update.set_surface_points(bone, moved, sphere.faces, sphere.vertex_faces_matrix)
    with_matrix = np.array(bone.GetMapper().GetInput().GetPointData().GetNormals())
    update.set_surface_points(bone, moved, sphere.faces)
    without = np.array(bone.GetMapper().GetInput().GetPointData().GetNormals())
    np.testing.assert_allclose(with_matrix, without, atol=1e-9)


def test_the_skull_is_drawn_in_bone_colour(plotter, sphere) -> None:
    skull.add_skull(plotter, sphere, name="layer_skull", pickable=True)
    plotter.view_xy()
    image = np.asarray(plotter.screenshot(return_img=True), float)
    centre = image[80, 100, :3] / 255.0
    # lit bone: warm (red above blue), far from the black background
    assert centre[0] > centre[2] and centre.sum() > 1.0


def test_age_heads_and_the_aged_skin_moved_in_place(plotter, sphere) -> None:
    from workbench.render.visuals import heads

    shell = heads.add_age_source(plotter, sphere, overlay=True)
    assert shell.GetProperty().GetOpacity() == pytest.approx(heads.OVERLAY_OPACITY)
    assert shell.GetProperty().GetBackfaceCulling()
    beside = heads.add_age_source(plotter, sphere, overlay=False)
    assert beside.GetProperty().GetOpacity() == 1.0 and _colour(beside) == _rgb8(SKIN)
    aged = heads.add_aged_skin(plotter, sphere, overlay=True)
    assert heads.DISTANCE_TITLE in plotter.scalar_bars
    grown = sphere.vertices * 1.1
    distance = np.linalg.norm(grown - sphere.vertices, axis=1)  # ~5 mm
    heads.show_aged(aged, grown, Mesh(grown, sphere.faces).vertex_normals, distance, overlay=True)
    data = update.mapper_dataset(aged)
    np.testing.assert_allclose(update.drawn_points(data), grown)
    np.testing.assert_allclose(np.asarray(data.point_data[heads.DISTANCE_TITLE]), distance)
    assert aged.GetMapper().GetScalarRange() == (0.0, 10.0)  # 99th percentile, up to 5 mm steps
    caption = heads.add_age_caption(plotter)
    heads.set_caption(caption, "10 y")
    assert caption.GetText(2) == "10 y"


def test_animated_skin_see_through_and_eye_colours(plotter, sphere) -> None:
    from types import SimpleNamespace

    from workbench.render.visuals import heads

    skin = heads.add_animated_skin(plotter, sphere)
    heads.set_see_through(skin, True)
    assert skin.GetProperty().GetOpacity() == pytest.approx(heads.SEE_THROUGH_OPACITY)
    assert skin.GetProperty().GetBackfaceCulling()
    heads.set_see_through(skin, False)
    assert skin.GetProperty().GetOpacity() == 1.0 and not skin.GetProperty().GetBackfaceCulling()
    # one eye at the origin looking along +z: the pupil in front, white behind
    anim = SimpleNamespace(
        head=SimpleNamespace(meshes={"eyes": sphere}, eye_centres=np.zeros((1, 3)))
    )
    rgb = heads.eye_colours(anim)  # type: ignore[arg-type]
    front, back = sphere.vertices[:, 2].argmax(), sphere.vertices[:, 2].argmin()
    assert rgb.dtype == np.uint8 and tuple(rgb[front]) == heads.PUPIL
    assert tuple(rgb[back]) == heads.EYE_WHITE
    eyes = heads.add_animated_part(plotter, "eyes", sphere, anim)  # type: ignore[arg-type]
    assert "animate_eyes" in plotter.renderer.actors
    assert "rgb" in update.mapper_dataset(eyes).point_data  # coloured per vertex
    teeth = heads.add_animated_part(plotter, "upper_teeth", sphere, anim)  # type: ignore[arg-type]
    assert _colour(teeth) == _rgb8(heads.INNER_COLOURS["upper_teeth"])


def test_view_backgrounds(plotter) -> None:
    from workbench.render.visuals.style import set_view_background

    set_view_background(plotter)
    ren = plotter.renderer
    assert ren.GetGradientBackground()
    assert _rgb8(ren.GetBackground()) == (0x2B, 0x2F, 0x36)
    assert _rgb8(ren.GetBackground2()) == (0x59, 0x60, 0x6B)
    set_view_background(plotter, guide=True)
    assert _rgb8(plotter.renderer.GetBackground()) == (0x1F, 0x23, 0x29)
