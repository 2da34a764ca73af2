"""Appearance presets and painted eyes (workbench.core.appearance): colour helpers, the pupil,
iris and sclera bands by angle from the gaze, the eyeball texture and its UV mapping."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.core import appearance as ap
from workbench.core.mesh import Mesh


def _rotation_to(gaze: np.ndarray) -> np.ndarray:
    """A rotation taking +z to ``gaze`` (Rodrigues)."""
    z = np.array([0.0, 0.0, 1.0])
    g = gaze / np.linalg.norm(gaze)
    v, c = np.cross(z, g), float(z @ g)
    k = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + k + k @ k / (1.0 + c)


def test_presets_cite_their_sources_and_colour_helpers_round_trip() -> None:
    assert [ap.SKIN_TONES[f"mst{k}"].hex for k in (1, 6, 10)] == ["#f6ede4", "#a07e56", "#292420"]
    for name in ("light", "medium", "dark"):
        assert "Monk" in ap.SKIN_TONES[name].source
    for inner, outer in ap.IRIS_COLOURS.values():
        assert inner.source and outer.source
    assert set(ap.IRIS_COLOURS) == {"brown", "hazel", "green", "blue", "grey"}
    with pytest.raises(ValueError, match="choose one of"):
        ap.skin_tone("olive")
    rgb = np.random.default_rng(1).random((500, 3))
    assert np.abs(ap.hsv_to_rgb(ap.rgb_to_hsv(rgb)) - rgb).max() < 1e-12
    assert np.allclose(ap.rgb_to_hsv([1.0, 0.0, 0.0]), [0.0, 1.0, 1.0])
    assert np.allclose(ap.rgb_to_hsv([0.0, 0.0, 1.0]), [2 / 3, 1.0, 1.0])
    assert np.allclose(ap.hsv_to_rgb([1 / 3, 0.5, 0.8]), [0.4, 0.8, 0.4])
    grey = np.arange(256)
    assert np.array_equal(ap.linear_to_srgb(ap.srgb_to_linear(grey)), grey)
    lips = np.array(ap.lip_srgb(ap.SKIN_TONES["medium"].srgb))
    skin = np.array(ap.SKIN_TONES["medium"].srgb)
    assert lips.sum() < skin.sum() and lips[0] > lips[1]  # darker and redder


@pytest.mark.parametrize("gaze", [(0.0, 0.0, 1.0), (0.3, -0.2, 0.93), (-1.0, 0.0, 0.0)])
@pytest.mark.parametrize("iris", ["brown", "blue"])
def test_eye_colours_dark_pupil_coloured_iris_white_sclera(gaze, iris) -> None:
    centre = np.array([31.5, 13.0, 57.3])
    g = np.asarray(gaze) / np.linalg.norm(gaze)
    eye = ap.fine_eyes(centre[None], g[None], subdivisions=5)
    colours = ap.eye_colours(eye.vertices, centre, g, iris=iris).astype(float)
    theta, _ = ap.eye_angles(eye.vertices, centre, g)
    deg = np.degrees(theta)
    pupil_deg = np.degrees(np.arcsin(ap.PUPIL_DIAMETER_MM / 2 / ap.EYE_RADIUS_MM))  # 8.4
    iris_deg = np.degrees(np.arcsin(ap.IRIS_DIAMETER_MM / 2 / ap.EYE_RADIUS_MM))  # 29.2
    pupil = deg < pupil_deg - 1.0
    ring = (deg > pupil_deg + 2.0) & (deg < iris_deg - 5.0)
    sclera = deg > iris_deg + 2.0
    assert pupil.sum() >= 10 and ring.sum() > 100 and sclera.sum() > 1000
    assert colours[pupil].max() < 30  # black
    hsv = ap.rgb_to_hsv(colours[ring] / 255.0)
    assert np.median(hsv[:, 1]) > 0.25  # coloured, not grey or white
    assert 0.15 < np.median(hsv[:, 2]) < 0.9
    hue = np.median(hsv[:, 0])
    assert (0.0 < hue < 0.12) if iris == "brown" else (0.5 < hue < 0.7)
    assert np.abs(colours[sclera] - ap.SCLERA.srgb).max() <= 1  # white (off-white)
    # the limbal ring: the outer edge of the iris is darker than its middle
    edge = (deg > iris_deg - 2.5) & (deg < iris_deg - 0.8)
    assert colours[edge].mean() < colours[ring].mean()


def test_reference_eye_resolution_and_finer_replacement(head_female) -> None:
    """The reference globes have 15 vertices within 2 mm of the pole (too few for a crisp
    pupil in vertex colours): the finer replacement has far more, same centre and radius."""
    eyes = head_female.meshes["eyes"]
    centres = head_female.eye_centres
    gazes = ap.eye_gazes(eyes.vertices, centres)
    assert np.allclose(gazes, [[0.0, 0.0, 1.0]] * 2, atol=1e-6)  # read from the cornea
    # in another frame (a skull file's, here rotated and mirrored) the cornea still tells
    turn = _rotation_to(np.array([0.5, 0.3, 0.8])) @ np.diag([-1.0, 1.0, 1.0])
    moved = ap.eye_gazes(eyes.vertices @ turn.T + 7.0, centres @ turn.T + 7.0)
    assert np.allclose(moved, [turn @ [0.0, 0.0, 1.0]] * 2, atol=1e-6)
    owner = ap.eye_owner(eyes.vertices, centres)
    coarse = ap.vertices_near_pole(eyes.vertices[owner == 0], centres[0], gazes[0])
    assert coarse < 30
    fine = ap.fine_eyes(centres, gazes)
    fine_owner = ap.eye_owner(fine.vertices, centres)
    dense = ap.vertices_near_pole(fine.vertices[fine_owner == 0], centres[0], gazes[0])
    assert dense > 5 * coarse
    r = np.linalg.norm(fine.vertices - centres[fine_owner], axis=1)
    assert abs(np.median(r) - head_female.eye_radius) < 1e-9
    r_ref = np.linalg.norm(eyes.vertices - centres[owner], axis=1)
    assert abs(r.max() - r_ref.max()) < 0.05  # the same corneal bulge


def test_eye_texture_matches_vertex_colours_through_the_uv_mapping() -> None:
    size = 1024
    image = ap.eye_texture(size, iris="green").astype(float)
    assert image.shape == (size, size, 3)
    assert image[size // 2, size // 2].max() < 30  # the pupil in the middle
    assert np.abs(image[5, 5] - ap.SCLERA.srgb).max() <= 1  # sclera outside the disc
    centre, gaze = np.zeros(3), np.array([0.0, 0.0, 1.0])
    eye = ap.fine_eyes(centre[None], gaze[None], subdivisions=5)
    uv = ap.eye_uv(eye.vertices, centre, gaze)
    assert np.allclose(uv[np.argmax(eye.vertices[:, 2])], [0.5, 0.5])  # pole at the centre
    col = np.clip((uv[:, 0] * size).astype(int), 0, size - 1)
    row = np.clip(((1.0 - uv[:, 1]) * size).astype(int), 0, size - 1)  # row 0 is v = 1
    sampled = image[row, col]
    painted = ap.eye_colours(eye.vertices, centre, gaze, iris="green").astype(float)
    theta, _ = ap.eye_angles(eye.vertices, centre, gaze)
    deg = np.degrees(theta)
    # away from the sharp pupil and limbus edges the texel is the vertex's colour
    calm = (deg < 7.0) | ((deg > 11.0) & (deg < 26.0)) | (deg > 32.0)
    assert np.median(np.abs(sampled[calm] - painted[calm])) < 8.0


def test_corner_uvs_keep_the_iris_off_the_back_of_the_globe(head_female) -> None:
    eyes = head_female.meshes["eyes"]
    centres = head_female.eye_centres
    gazes = ap.eye_gazes(eyes.vertices, centres)
    corners = ap.eyes_corner_uv(eyes, centres, gazes)
    assert corners.shape == (eyes.n_faces, 3, 2)
    owner = ap.eye_owner(eyes.vertices, centres)
    theta = np.empty(eyes.n_vertices)
    for i in range(2):
        theta[owner == i] = ap.eye_angles(eyes.vertices[owner == i], centres[i], gazes[i])[0]
    behind = (theta[eyes.faces] > np.pi / 2).any(axis=1)
    # no triangle behind the equator has a UV triangle that reaches the iris disc
    iris_uv = 0.5 * np.sin(np.arcsin(ap.IRIS_DIAMETER_MM / 2 / ap.EYE_RADIUS_MM) / 2) + 0.01
    samples = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1], [2, 1, 1], [1, 2, 1]], float)
    samples /= samples.sum(axis=1, keepdims=True)
    points = np.einsum("sk,mkj->msj", samples, corners[behind])
    assert np.hypot(points[..., 0] - 0.5, points[..., 1] - 0.5).min() > iris_uv
    # ... and the triangles whose corners would have spread around the rim are few
    assert np.all(corners == ap.BACK_UV, axis=(1, 2)).sum() < 0.01 * eyes.n_faces


def test_head_looks_give_every_part_a_material(head_female) -> None:
    looks = ap.head_looks(head_female.meshes, head_female.eye_centres, regions=head_female.regions)
    assert set(looks) == set(head_female.meshes)
    skin = looks["skin"]
    assert [m.name for m in skin.materials] == ["skin", "lips"]
    lips = skin.faces_of(head_female.skin.n_faces) == 1
    assert 0 < lips.sum() < 0.1 * head_female.skin.n_faces
    assert skin.vertex_srgb is not None and len(skin.vertex_srgb) == head_female.skin.n_vertices
    eye = looks["eyes"].materials[0]
    assert eye.texture is not None and eye.texture_file == "eye_brown.png"
    assert looks["upper_teeth"].materials[0].name == "teeth"
    assert looks["cranium"].materials[0].name == "bone"
    assert all(m.metallic == 0.0 for look in looks.values() for m in look.materials)
    vertex = ap.head_looks(
        {"eyes": head_female.meshes["eyes"]}, head_female.eye_centres, eyes="vertex"
    )
    fine = vertex["eyes"]
    assert fine.mesh is not None and fine.vertex_srgb is not None
    assert len(fine.vertex_srgb) == fine.mesh.n_vertices > head_female.meshes["eyes"].n_vertices
    with pytest.raises(ValueError, match="iris"):
        ap.head_looks({"eyes": head_female.meshes["eyes"]}, head_female.eye_centres, iris="red")
    plain = ap.plain_look("hair")
    assert plain.materials[0].name == "hair" and ap.plain_look("xyz").materials[0].name == "other"
    one = Mesh(np.eye(3), np.array([[0, 1, 2]]))
    with pytest.raises(ValueError, match="texture"):
        ap.head_looks(
            {"skin": one},
            skin_texture=ap.SkinTexture(np.zeros((4, 4, 3), np.uint8), np.zeros((2, 3, 2))),
        )
