"""Portraits of a head (issue 34 item 4): the camera, the handedness, the colours on the pixels.

The male reference head (head frame, mm) is drawn off-screen at 500 px, once in colour and
once in clay, for the module.  Points of the head are projected into the pictures with the
portrait's own camera (:meth:`PortraitCamera.project`), which the pupil test checks against
the rendered pixels: the pupil lands on a dark pixel.  The front view is not mirrored (the
left eye, x > 0, is on the picture's right, and a skin painted by sides shows its left half
there), the head fills about 80 % of the frame height and is not cut at the top or the
sides, a cheek has the skin tone's hue and the clay version has no hue at all.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from workbench.core.appearance import SKIN_TONES, SkinTexture, rgb_to_hsv
from workbench.core.errors import InputError
from workbench.core.mesh import Mesh
from workbench.render import portrait
from workbench.render.portrait import (
    BACKGROUND_SRGB,
    HEAD_FILL,
    VIEW_ANGLE_DEG,
    VIEWS,
    check_size,
    check_views,
    make_portrait,
    portrait_cameras,
)
from workbench.render.portrait_scene import occlusion, refine

SIZE = 500


@pytest.fixture(scope="module")
def coloured(head_male):
    return make_portrait(head_male, size=SIZE, colour=True, skin_tone="medium", iris="brown")


@pytest.fixture(scope="module")
def clay(head_male):
    return make_portrait(head_male, size=SIZE, colour=False)


def _at(image: np.ndarray, point: np.ndarray, half: int = 1) -> np.ndarray:
    """The pixels within ``half`` of a (column, row) position, ``(k, 3)`` uint8."""
    c, r = (int(round(v)) for v in point)
    return image[r - half : r + half + 1, c - half : c + half + 1].reshape(-1, 3)


def _pupils(p: portrait.Portrait) -> np.ndarray:
    """The corneal apex of each eye (mm, head frame): the middle of the pupil."""
    from workbench.core.appearance import eye_gazes

    head = p.head
    assert head is not None
    centres = np.asarray(head.eye_centres, float)
    gazes = eye_gazes(head.meshes["eyes"].vertices, centres)
    d = head.meshes["eyes"].vertices[:, None] - centres[None]
    reach = np.max(np.einsum("nkj,kj->nk", d, gazes), axis=0)  # the cornea's apex
    return centres + gazes * reach[:, None]


# ------------------------------------------------------------------ camera
def test_the_lens_and_the_framing(head_male) -> None:
    assert VIEW_ANGLE_DEG == pytest.approx(16.07, abs=0.01)  # 85 mm on a 24 mm frame
    cams = portrait_cameras(head_male)
    assert list(cams) == list(VIEWS)
    distances = {round(c.distance_mm, 6) for c in cams.values()}
    assert len(distances) == 1 and 800.0 < distances.pop() < 1300.0  # one distance, ~1 m
    eye_level = float(np.mean(head_male.eye_centres[:, 1]))
    for cam in cams.values():
        assert cam.position[1] == pytest.approx(eye_level)  # the camera at eye level
    # the front camera on +z, the profile on the subject's right (-x), the 3/4 between
    assert cams["front"].axes()[0] @ [0, 0, 1] > 0.99
    assert cams["profile"].axes()[0] @ [-1, 0, 0] > 0.99
    back = cams["three_quarter"].axes()[0]
    assert back[0] < -0.6 and back[2] > 0.6


def test_the_head_fills_80_percent_of_the_height_and_is_not_cut(coloured, clay) -> None:
    background = np.asarray(BACKGROUND_SRGB)
    for p in (coloured, clay):
        for view, image in p.images.items():
            head = np.abs(image.astype(int) - background).max(axis=2) > 6
            assert not head[0].any() and not head[:, 0].any() and not head[:, -1].any(), view
        rows = np.flatnonzero(
            (np.abs(p.images["front"].astype(int) - background).max(axis=2) > 6).any(axis=1)
        )
        assert p.head is not None
        chin = p.cameras["front"].project(p.head.skin_landmarks["me"].position[None], SIZE)[0, 1]
        fill = (chin - rows[0]) / SIZE
        assert fill == pytest.approx(HEAD_FILL, abs=0.04)


# ------------------------------------------------------------------ handedness
def test_the_front_view_is_not_mirrored(coloured) -> None:
    cam = coloured.cameras["front"]
    head = coloured.head
    centres = np.asarray(head.eye_centres, float)
    left = centres[np.argmax(centres[:, 0])]  # the subject's left eye: x > 0
    assert cam.project(left[None], SIZE)[0, 0] > SIZE / 2
    po_l = head.skin_landmarks["po_l"].position
    assert cam.project(po_l[None], SIZE)[0, 0] > SIZE / 2
    # the profile shows the right side: the face toward the picture's right
    prof = coloured.cameras["profile"]
    assert prof.project(head.skin_landmarks["prn"].position[None], SIZE)[0, 0] > SIZE / 2


def test_a_skin_painted_by_sides_shows_its_left_half_on_the_right(head_male) -> None:
    """Pixels, not only projections: the subject's left half of the skin is painted blue."""
    skin = head_male.skin
    image = np.zeros((8, 8, 3), np.uint8)
    image[:, :4] = (200, 150, 120)  # u < 0.5: warm
    image[:, 4:] = (60, 90, 220)  # u > 0.5: blue
    left = skin.vertices[skin.faces].mean(axis=1)[:, 0] > 0
    uv = np.where(left[:, None, None], 0.75, 0.25) * np.ones((skin.n_faces, 3, 2))
    p = make_portrait(
        head_male, views=["front"], size=300, skin_texture=SkinTexture(image, uv, "sides.png")
    )
    img = p.images["front"].astype(int)
    cam = p.cameras["front"]
    assert p.head is not None
    for code, blue in (("chk_l", True), ("chk_r", False), ("po_l", True), ("po_r", False)):
        point = cam.project(p.head.skin_landmarks[code].position[None], 300)[0]
        r, _, b = _at(img, point, 2).mean(axis=0)
        assert (b > r) == blue, code


def test_a_mirror_image_head_is_drawn_the_right_way_round(head_male) -> None:
    """A reconstruction of a mirror-image skull file is stored mirrored: drawn as the subject."""
    from workbench.services.registration.skull_registration import head_transformed

    a = np.radians(30.0)
    m = np.eye(4)
    m[:3, :3] = np.diag([-1.0, 1.0, 1.0]) @ [
        [np.cos(a), 0.0, np.sin(a)],
        [0.0, 1.0, 0.0],
        [-np.sin(a), 0.0, np.cos(a)],
    ]
    m[:3, 3] = [5.0, -120.0, 40.0]
    mirrored = head_transformed(head_male, m)
    mirrored = replace(
        mirrored, meshes={k: Mesh(v.vertices, v.faces[:, ::-1]) for k, v in mirrored.meshes.items()}
    )
    p = make_portrait(mirrored, views=["front"], size=300)
    framed = p.head
    assert framed is not None
    assert np.allclose(framed.skin.vertices, head_male.skin.vertices, atol=0.05)
    left = framed.eye_centres[np.argmax(framed.eye_centres[:, 0])]
    assert p.cameras["front"].project(left[None], 300)[0, 0] > 150


# ------------------------------------------------------------------ colours
def test_the_colour_version_has_dark_pupils_and_a_skin_coloured_cheek(coloured) -> None:
    img = coloured.images["front"]
    cam = coloured.cameras["front"]
    for pupil in cam.project(_pupils(coloured), SIZE):
        assert _at(img, pupil).astype(int).sum(axis=1).min() < 3 * 45  # the pupil: near black
    swatch = rgb_to_hsv(np.asarray(SKIN_TONES["medium"].srgb) / 255.0)
    for code in ("chk_l", "chk_r"):
        point = cam.project(coloured.head.skin_landmarks[code].position[None], SIZE)[0]
        hsv = rgb_to_hsv(_at(img, point, 2).mean(axis=0) / 255.0)
        assert abs(hsv[0] - swatch[0]) < 0.04 and hsv[1] > 0.2, code  # the swatch's hue
        assert 0.3 < hsv[2] < 0.95  # lit, neither black nor blown out


def test_the_clay_version_claims_no_colour(clay) -> None:
    for view, image in clay.images.items():
        spread = image.max(axis=2).astype(int) - image.min(axis=2)
        assert spread.max() <= 3, view  # grey everywhere: no hue
    # and it is not flat: the face is shaded
    face = clay.images["front"][SIZE // 4 : 3 * SIZE // 4, SIZE // 3 : 2 * SIZE // 3, 0]
    assert np.percentile(face, 95) - np.percentile(face, 5) > 40


def test_the_summary_says_what_was_drawn(coloured, clay) -> None:
    s = coloured.summary()
    assert s["disclaimer"] == portrait.DISCLAIMER and s["views"] == list(VIEWS)
    assert s["lens"]["focal_length_mm"] == 85.0 and s["skin"] == "medium"
    assert [light["name"] for light in s["lights"]] == ["key", "fill", "rim", "bounce"]
    assert set(s["cameras"]) == set(VIEWS) and "render" in s["seconds"]
    assert clay.summary()["iris"] is None and "clay" in clay.summary()["skin"]


# ------------------------------------------------------------------ checks and helpers
def test_bad_options_are_refused(head_male) -> None:
    with pytest.raises(InputError, match="not a portrait view"):
        check_views(["front", "back"])
    with pytest.raises(InputError, match="256 to 8000"):
        check_size(100)
    with pytest.raises(InputError, match="256 to 8000"):
        check_size(9000)
    assert check_views(["profile", "front", "profile"]) == ("profile", "front")
    with pytest.raises(InputError, match="skin tone"):
        make_portrait(head_male, size=256, skin_tone="purple")


def test_refine_keeps_the_vertices_and_rounds_the_edges() -> None:
    from workbench.core.headgen.eyes import icosphere

    unit = icosphere(2)
    sphere = Mesh(unit.vertices * 50.0, unit.faces)
    normals = sphere.vertices / 50.0
    fine, fine_normals, colours, _ = refine(sphere, normals, np.ones((sphere.n_vertices, 3)))
    assert fine.n_faces == 4 * sphere.n_faces
    assert np.array_equal(fine.vertices[: sphere.n_vertices], sphere.vertices)
    radius = np.linalg.norm(fine.vertices[sphere.n_vertices :], axis=1)
    flat = Mesh(sphere.vertices, sphere.faces)  # flat midpoints sit well inside the sphere
    a, b = flat.faces[:, 0], flat.faces[:, 1]
    flat_r = np.linalg.norm(0.5 * (flat.vertices[a] + flat.vertices[b]), axis=1)
    assert np.abs(radius - 50.0).max() < np.abs(flat_r - 50.0).min()
    assert np.allclose(np.linalg.norm(fine_normals, axis=1), 1.0)
    assert colours is not None and np.allclose(colours, 1.0)


def test_occlusion_is_open_outside_and_closed_inside() -> None:
    from workbench.core.headgen.eyes import icosphere
    from workbench.core.raycast import RayCaster

    unit = icosphere(3)
    ball = Mesh(unit.vertices * 20.0, unit.faces)
    caster = RayCaster(ball)
    outside = ball.vertices[:10] * 1.0
    assert np.allclose(occlusion(outside, outside / 20.0, caster), 1.0)
    centre, up = np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]])
    # every ray blocked by a wall 20 mm away: 1 - 20/25 of it; by one 5 mm away: 1 - 5/25
    assert occlusion(centre, up, caster, reach_mm=25.0)[0] == pytest.approx(0.8, abs=0.01)
    small = RayCaster(Mesh(unit.vertices * 5.0, unit.faces))
    assert occlusion(centre, up, small, reach_mm=25.0)[0] == pytest.approx(0.2, abs=0.01)


def test_render_portrait_returns_pictures_or_files(head_male, tmp_path) -> None:
    from PIL import Image

    from workbench.render.portrait import render_portrait

    images = render_portrait(head_male, None, views=["front"], size=256, colour=False)
    assert list(images) == ["front"] and np.asarray(images["front"]).shape == (256, 256, 3)
    files = render_portrait(head_male, tmp_path, views=["profile"], size=256, formats=["png"])
    assert files == {"profile": (tmp_path / "portrait_profile.png",)}
    assert Image.open(tmp_path / "portrait_profile.png").text["Description"] == portrait.DISCLAIMER  # type: ignore[attr-defined]
