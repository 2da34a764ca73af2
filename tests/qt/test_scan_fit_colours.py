"""The Fit scan dock keeps the scan's own colours (issue 34) under Xvfb: a scan with vertex
colours (PLY) or a texture (OBJ + MTL + PNG) is drawn in them, the distance map is one
choice away, and the fitted skin carries the colours the pack carries.

The scans are the female reference skin with two holes (``tests/services/_scans.py``),
in a scanner frame, coloured by ramps over the head frame's x and y (mm), so that the
colour expected at any point of the face is known.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

pytest.importorskip("pytestqt")
if os.environ.get("QT_QPA_PLATFORM") != "xcb":
    pytest.skip(
        "the 3D view needs QT_QPA_PLATFORM=xcb under Xvfb (see HEADLESS.md)",
        allow_module_level=True,
    )

from PIL import Image

from tests.services._scans import damaged_skin, scan_pose
from workbench.io.mesh_formats import ply
from workbench.io.meshes import write_mesh

pytestmark = pytest.mark.gui
FIT_MS = 180_000
#: the texture image (pixels) of the textured scan
TEXTURE_SIZE = (256, 320)


def _ramp(t: np.ndarray) -> np.ndarray:
    """0..1 → 20..220 (an 8-bit level)."""
    return 20.0 + 200.0 * np.clip(t, 0.0, 1.0)


def _head_frame_box(head) -> tuple[np.ndarray, np.ndarray]:
    v = head.skin.vertices
    return v.min(axis=0), v.max(axis=0)


def _expected(points_head: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The colour both scans carry at head-frame points: red along x, green along y."""
    t = (points_head[:, :2] - lo[:2]) / (hi[:2] - lo[:2])
    return np.column_stack([_ramp(t[:, 0]), _ramp(t[:, 1]), np.full(len(t), 128.0)])


@pytest.fixture(scope="module")
def coloured_scans(head_female, tmp_path_factory):
    """``(ply path, its (n, 3) uint8 colours, obj path, its (H, W, 3) image, (n, 2) uv, box)``.

    The PLY's vertex colours and the OBJ's texture show the same ramps; the OBJ's
    texture coordinates are the head frame's x, y scaled to 0..1 (one per vertex).
    """
    folder = tmp_path_factory.mktemp("coloured_scan")
    scan, _ = damaged_skin(head_female)
    lo, hi = _head_frame_box(head_female)
    head_v = head_female.skin.vertices  # the scan's vertices, in the same order
    rgb = np.rint(_expected(head_v, lo, hi)).astype(np.uint8)
    ply_path = folder / "coloured_scan.ply"
    ply_path.write_bytes(ply.encode(scan.vertices, scan.faces, vertex_rgb=rgb))

    uv = (head_v[:, :2] - lo[:2]) / (hi[:2] - lo[:2])
    h, w = TEXTURE_SIZE
    # pixel centres: u = (i + 0.5) / w, v = 1 - (j + 0.5) / h (row 0 at the top)
    u = (np.arange(w) + 0.5) / w
    v = 1.0 - (np.arange(h) + 0.5) / h
    uu, vv = np.meshgrid(u, v)
    image = np.stack([_ramp(uu), _ramp(vv), np.full_like(uu, 128.0)], axis=-1)
    image = np.rint(image).astype(np.uint8)
    Image.fromarray(image, "RGB").save(folder / "scan_texture.png")
    (folder / "textured_scan.mtl").write_text("newmtl skin\nKd 1 1 1\nmap_Kd scan_texture.png\n")
    lines = ["mtllib textured_scan.mtl", "o scan"]
    lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in scan.vertices]
    lines += [f"vt {a:.7f} {b:.7f}" for a, b in uv]
    lines += ["usemtl skin"]
    lines += [f"f {a}/{a} {b}/{b} {c}/{c}" for a, b, c in scan.faces + 1]
    obj_path = folder / "textured_scan.obj"
    obj_path.write_text("\n".join(lines) + "\n")
    return ply_path, rgb, obj_path, image, uv, (lo, hi)


def _wait(qtbot, window, timeout=FIT_MS) -> None:
    qtbot.waitUntil(lambda: not window.busy, timeout=timeout)
    assert not window.errors, window.errors


def _open(qtbot, window, path) -> None:
    window.open_scan(path, units="mm")
    _wait(qtbot, window, 60_000)
    assert window.scan_fit.has_scan


def _scan_input(tool):
    from workbench.render.visuals.update import mapper_dataset

    return mapper_dataset(tool.actors("scan")[0])


def _drawn_skin_colours(tool) -> np.ndarray:
    """The fitted skin's drawn colours per skin vertex (both parts share the vertices)."""
    from workbench.render.visuals.face import SCAN_COLOURS
    from workbench.render.visuals.update import mapper_dataset

    actors = tool.actors("skin")
    assert actors
    for a in actors:  # the part on the scan is hidden (not drawn yet): run its pipeline
        a.GetMapper().Update()
    drawn = [np.asarray(mapper_dataset(a).point_data[SCAN_COLOURS]) for a in actors]
    for a, colours in zip(actors, drawn, strict=True):
        assert a.GetMapper().GetScalarVisibility()
        np.testing.assert_array_equal(colours, drawn[0])
    return drawn[0]


def _to_head(points_scan: np.ndarray) -> np.ndarray:
    """Scanner frame → the reference head frame the scans were made in (mm)."""
    pose = np.linalg.inv(scan_pose())
    return points_scan @ pose[:3, :3].T + pose[:3, 3]


def _check_skin_colours(tool, scan_mesh, box, truth_hole) -> None:
    """Observed skin vertices carry the scan's colour there; the skin over the hole is
    filled, not observed."""
    from workbench.core.spatial import MeshIndex

    view = tool.view
    assert view.skin_colours is not None
    drawn = _drawn_skin_colours(tool).astype(float)
    np.testing.assert_array_equal(drawn, view.skin_colours.rgb)
    observed = view.skin_colours.observed
    assert 0.7 < observed.mean() < 1.0
    near = MeshIndex(scan_mesh).closest_points(view.skin.vertices)
    on_scan = observed & (near.distances < 1.0)
    assert on_scan.mean() > 0.5
    expected = _expected(_to_head(near.points[on_scan]), *box)
    err = np.abs(drawn[on_scan] - expected).max(axis=1)
    assert np.median(err) < 2.0, np.median(err)
    assert np.percentile(err, 95) < 5.0, np.percentile(err, 95)
    # over the hole at the left cheek: no scan, the colour is filled
    hole = np.linalg.norm(view.skin.vertices - truth_hole, axis=1) < 5.0
    assert hole.any() and not observed[hole].any()
    assert "Skin colour" in tool.panel.figures.text()


def test_vertex_coloured_scan_own_colours_distance_and_coloured_fit(
    qtbot, window, coloured_scans, head_female
):
    from workbench.qt.tools.scan_fit.tool import DISTANCE_TITLE
    from workbench.render.visuals.face import SCAN_COLOURS

    ply_path, rgb, _obj, _image, _uv, box = coloured_scans
    _, truth = damaged_skin(head_female)
    tool, panel = window.scan_fit, window.scan_fit_panel
    _open(qtbot, window, ply_path)
    combo = panel.scan_colours_combo
    # a coloured scan opens in its own colours: the file's, vertex by vertex
    assert combo.isEnabled() and panel.scan_colours() == "own"
    assert "vertex colours" in combo.toolTip() and "vertex colours" in panel.file_label.text()
    poly = _scan_input(tool)
    np.testing.assert_array_equal(np.asarray(poly.point_data[SCAN_COLOURS]), rgb)
    mapper = tool.actors("scan")[0].GetMapper()
    assert mapper.GetScalarVisibility() and mapper.GetArrayName() == SCAN_COLOURS
    # clicks are still picked on the scan surface: the drawn polydata itself
    assert tool._scan_poly is poly
    window.docks["fit_scan"].raise_()
    window.scene.render_now()
    width, height = window.plotter.render_window.GetSize()
    hit = tool.picker.pick(width // 2, height // 2)
    assert hit is not None
    d = np.linalg.norm(tool.scan.mesh.vertices - hit, axis=1).min()
    assert d < 10.0  # on the scan (within a triangle's size of a vertex)

    # the distance map instead (grey before a fit), and fit
    panel.set_scan_colours("distance")
    assert panel.scan_colours() == "distance" and panel.preferred_scan_colours == "distance"
    assert SCAN_COLOURS not in _scan_input(tool).point_data
    window.fit_scan()
    _wait(qtbot, window)
    assert tool.view is not None
    values = np.asarray(_scan_input(tool).point_data[DISTANCE_TITLE])
    assert np.isfinite(values).sum() > 1000 and np.nanmax(values) < 10.0
    assert window.plotter.scalar_bars[DISTANCE_TITLE].GetVisibility()
    _check_skin_colours(tool, tool.scan.mesh, box, truth["chk_l"].position)

    # back to the scan's own colours: the key goes, the view stays where it was
    camera = window.plotter.renderer.GetActiveCamera().GetPosition()
    panel.set_scan_colours("own")
    np.testing.assert_array_equal(np.asarray(_scan_input(tool).point_data[SCAN_COLOURS]), rgb)
    assert window.plotter.renderer.GetActiveCamera().GetPosition() == camera
    assert DISTANCE_TITLE not in window.plotter.scalar_bars or not (
        window.plotter.scalar_bars[DISTANCE_TITLE].GetVisibility()
    )
    # the fine detail is coloured too, one colour per detailed vertex
    panel.detail_check.setChecked(True)
    fine = _drawn_skin_colours(tool)
    assert len(fine) == len(tool.view.detail_colours.rgb) > 4 * tool.view.skin.n_vertices
    panel.detail_check.setChecked(False)


def test_textured_obj_is_drawn_with_its_texture_and_colours_the_fit(
    qtbot, window, coloured_scans, head_female
):
    _ply, _rgb, obj_path, image, uv, box = coloured_scans
    _, truth = damaged_skin(head_female)
    tool, panel = window.scan_fit, window.scan_fit_panel
    _open(qtbot, window, obj_path)
    assert panel.scan_colours() == "own" and "texture" in panel.scan_colours_combo.toolTip()
    actor = tool.actors("scan")[0]
    texture = actor.texture
    assert texture is not None
    np.testing.assert_array_equal(texture.to_array()[::-1], image)  # VTK's rows: bottom up
    poly = _scan_input(tool)
    assert tool._scan_poly is poly
    faces = poly.regular_faces
    corners = np.asarray(poly.active_texture_coordinates)[faces]
    scan = tool.scan.mesh
    np.testing.assert_allclose(corners, uv[scan.faces], atol=1e-6)  # the file's coordinates
    np.testing.assert_allclose(np.asarray(poly.points)[faces], scan.vertices[scan.faces])

    window.fit_scan()
    _wait(qtbot, window)
    assert tool.view.skin_colours is not None and tool.view.skin_colours.kind == "texture"
    _check_skin_colours(tool, scan, box, truth["chk_l"].position)
    # the fit kept the choice: still textured
    assert tool.actors("scan")[0].texture is not None


def test_colour_problems_leave_the_scan_open(qtbot, window, coloured_scans, tmp_path):
    """A texture that cannot be read: the scan opens without colours and the dock says
    why; a scan without colours: the choice is off, its tooltip says why."""
    from workbench.qt.panels.scan_fit_panel import NO_COLOURS_TIP
    from workbench.render.visuals.face import SCAN_COLOURS

    _ply, _rgb, obj_path, _image, _uv, _box = coloured_scans
    broken = tmp_path / "broken_texture.obj"
    broken.write_text(obj_path.read_text().replace("textured_scan.mtl", "broken.mtl"))
    (tmp_path / "broken.mtl").write_text("newmtl skin\nmap_Kd missing_texture.png\n")
    tool, panel = window.scan_fit, window.scan_fit_panel
    _open(qtbot, window, broken)
    assert tool.scan.colours is None and "missing_texture.png" in tool.scan.colour_note
    assert not panel.scan_colours_combo.isEnabled() and panel.scan_colours() == "distance"
    assert "could not be read" in panel.scan_colours_combo.toolTip()
    assert "could not be read" in panel.state_label.text()
    assert "missing_texture.png" in panel.state_label.text()
    assert SCAN_COLOURS not in _scan_input(tool).point_data

    plain = write_mesh(tmp_path / "plain.ply", tool.scan.mesh)
    _open(qtbot, window, plain)
    assert tool.scan.colours is None and not tool.scan.colour_note
    assert not panel.scan_colours_combo.isEnabled()
    assert panel.scan_colours_combo.toolTip() == NO_COLOURS_TIP
