"""One handedness in the pictures: the subject's right on the viewer's left in a front view.

Synthetic scenes whose sides can be told apart: a ball "skull" (mm) with one
dowel or one red marker on one side of the subject.  Each is drawn once in an
unmirrored frame and once in a frame that is a mirror image of the subject
(the input → head map a reflection, as for the VTK headsq CT): the marked side
must land on the same side of the picture, the shading must not darken (the
mirrored picture is flipped on screen, OpenGL's front face switched with it),
and the side letters must say R on the left and L on the right.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from workbench.core.frame import RAS_TO_HEAD
from workbench.core.mesh import Mesh
from workbench.render.reconstruction import render_reconstruction
from workbench.render.snapshots import render_surfaces, view_directions
from workbench.render.visuals.orientation import HEAD, Anatomy, edge_letters, reflection

SIZE = (200, 240)
#: input → head maps: the head frame itself, and a mirror image of it (x = the subject's right)
FRAMES = {"as is": np.eye(4), "mirror image": np.diag([-1.0, 1.0, 1.0, 1.0])}


def ball(radius: float = 60.0) -> Mesh:
    import pyvista as pv

    s = pv.Sphere(radius=radius, theta_resolution=48, phi_resolution=48).triangulate()
    return Mesh(np.asarray(s.points, float), np.asarray(s.faces).reshape(-1, 4)[:, 1:])


def pixels(path: Path) -> np.ndarray:
    return np.asarray(Image.open(path).convert("RGB"), float)


def dowel_columns(image: np.ndarray) -> np.ndarray:
    """Columns of the dowel pixels above the colour bar: saturated viridis colours (the bone,
    the white background and the grey letters are all nearly grey)."""
    top = image[: int(0.8 * image.shape[0])]
    return np.flatnonzero((top.max(axis=2) - top.min(axis=2) > 60).any(axis=0))


def left_of_subject(input_to_head: np.ndarray) -> np.ndarray:
    """The subject's left (unit) in the input frame of ``input_to_head``."""
    return np.linalg.solve(input_to_head[:3, :3], [1.0, 0.0, 0.0])


# ------------------------------------------------------------------ anatomy
def test_anatomy_knows_a_mirror_image_frame() -> None:
    assert not HEAD.mirrored
    ras = Anatomy.from_head_frame(RAS_TO_HEAD)  # RAS: left = -x, up = +z, face = +y
    np.testing.assert_allclose(ras.left, [-1.0, 0.0, 0.0], atol=1e-12)
    assert not ras.mirrored
    mirror = Anatomy.from_head_frame(FRAMES["mirror image"])
    np.testing.assert_allclose(mirror.left, [-1.0, 0.0, 0.0], atol=1e-12)
    assert mirror.mirrored and not mirror.shown().mirrored
    # the headsq CT's known anatomy (face -y, up -z, left +x) is a mirror image
    assert Anatomy.of((0, -1, 0), (0, 0, -1), (1, 0, 0)).mirrored
    assert not Anatomy.of((0, -1, 0), (0, 0, -1)).mirrored  # without a left: taken as is


def test_a_reflection_across_the_midsagittal_plane_keeps_face_and_up() -> None:
    m = reflection([5.0, 1.0, 2.0], [1.0, 0.0, 0.0])
    np.testing.assert_allclose(m[:3, :3] @ [0.0, 0.0, 1.0], [0.0, 0.0, 1.0])
    np.testing.assert_allclose(m[:3, :3] @ [1.0, 0.0, 0.0], [-1.0, 0.0, 0.0])
    np.testing.assert_allclose(m @ [5.0, 7.0, 8.0, 1.0], [5.0, 7.0, 8.0, 1.0])  # on the plane
    assert np.linalg.det(m[:3, :3]) == pytest.approx(-1.0)


def test_edge_letters_of_a_frontal_and_a_profile_camera() -> None:
    # a camera in front of the face (+z), up +y: eye x = world x, the subject's left
    front = np.eye(4)
    assert edge_letters(front, HEAD) == {"left": "R", "right": "L", "top": "S", "bottom": "I"}
    # the same camera with the picture flipped left to right
    flipped = np.diag([-1.0, 1.0, 1.0, 1.0])
    assert edge_letters(flipped, HEAD)["left"] == "L"
    # from the subject's right (the camera at -x, eye z = -world x): the face to the right
    profile = np.array(
        [[0.0, 0.0, 1.0, 0.0], [0.0, 1.0, 0.0, 0.0], [-1.0, 0.0, 0.0, 0.0], [0, 0, 0, 1]]
    )
    assert edge_letters(profile, HEAD)["right"] == "A"


def test_the_side_view_looks_at_the_subjects_right_in_either_frame() -> None:
    for to_head in FRAMES.values():
        anatomy = Anatomy.from_head_frame(to_head)
        direction, _up = view_directions("side", anatomy.anterior, anatomy.superior, anatomy.left)
        np.testing.assert_allclose(direction, -left_of_subject(to_head), atol=1e-12)


# ------------------------------------------------------------------ pictures
@pytest.mark.render
@pytest.mark.parametrize("name", list(FRAMES))
def test_a_dowel_on_the_subjects_left_is_on_the_right_of_the_front_picture(
    name: str, tmp_path: Path
) -> None:
    to_head = FRAMES[name]
    left = left_of_subject(to_head)
    origin = 60.0 * left
    dowels = (origin[None], (origin + 12.0 * left)[None])
    out = render_reconstruction(ball(), None, dowels, tmp_path, frame=to_head, size=SIZE)
    front = pixels(out["skull_dowels_front"])
    cols = dowel_columns(front)
    assert len(cols) and cols.min() > SIZE[0] / 2, (name, cols)
    # seen from the subject's right, a dowel on the left hides behind the ball ...
    side = pixels(out["skull_dowels_side"])
    assert not len(dowel_columns(side)), name
    # ... and one on the right stands out of it
    right = (-origin[None], (-origin - 12.0 * left)[None])
    seen = render_reconstruction(ball(), None, right, tmp_path / "r", frame=to_head, size=SIZE)
    assert len(dowel_columns(pixels(seen["skull_dowels_side"]))), name


@pytest.mark.render
def test_a_mirror_image_frame_is_shown_flipped_and_lit_alike(tmp_path: Path) -> None:
    """render_surfaces: the marker on the subject's left lands right in both frames, the ball
    is lit the same (a flipped picture with the front face not switched would be dark)."""
    shots = {}
    for name, to_head in FRAMES.items():
        anatomy = Anatomy.from_head_frame(to_head)
        left = left_of_subject(to_head)
        path = render_surfaces(
            [(ball(), "ivory", 1.0)],
            tmp_path / f"{name}.png",
            views=("front",),
            orientation=(anatomy.anterior, anatomy.superior, anatomy.left),
            size=SIZE,
            points=[(70.0 * left[None], "red")],
        )
        shots[name] = pixels(path)
    for name, image in shots.items():
        red = (image[..., 0] > 180) & (image[..., 1] < 80) & (image[..., 2] < 80)
        cols = np.flatnonzero(red.any(axis=0))
        assert len(cols) and cols.min() > SIZE[0] / 2, name
    lit = {
        name: image[np.abs(image - 255.0).sum(axis=2) > 30].mean() for name, image in shots.items()
    }
    assert lit["mirror image"] == pytest.approx(lit["as is"], abs=8.0), lit
