"""Colour transfer scan → fitted skin (head frame, mm; colours 0..255)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.services._scans import damaged_skin
from workbench.core.colour_transfer import (
    NO_COLOUR,
    ScanColours,
    fill_colours,
    sample_image,
    transfer_colours,
)
from workbench.core.errors import InputError
from workbench.core.mesh import Mesh


def gradient(points: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """A linear colour ramp over the box ``lo..hi``: 20..220 in each channel."""
    return 20.0 + 200.0 * (points - lo) / (hi - lo)


@pytest.fixture(scope="module")
def scene(head_male):
    """(skin, scan with holes, fitted skin = skin moved 0.6 mm out and 0.4 mm sideways)."""
    skin = head_male.skin
    scan, _ = damaged_skin(head_male, np.eye(4))
    normals = skin.vertex_normals
    wobble = 0.4 * np.sin(skin.vertices / 15.0)
    fitted = skin.with_vertices(skin.vertices + 0.6 * normals + wobble)
    return skin, scan, fitted


def test_vertex_colours_recovered_on_deformed_copy(scene):
    skin, scan, fitted = scene
    lo, hi = skin.vertices.min(axis=0), skin.vertices.max(axis=0)
    rgb = np.rint(gradient(scan.vertices, lo, hi)).astype(np.uint8)
    colours = ScanColours("scan.ply", scan.n_vertices, scan.faces, vertex_rgb=rgb)
    out = transfer_colours(fitted, scan, colours)
    assert out.rgb.shape == (fitted.n_vertices, 3) and out.rgb.dtype == np.uint8
    assert out.kind == "vertex"
    expected = gradient(fitted.vertices, lo, hi)
    err = np.abs(out.rgb.astype(float) - expected)[out.observed]
    assert out.observed.mean() > 0.9
    # 0.6 mm off the surface moves ~0.5-0.7 levels along this ramp; rounding adds 0.5
    assert err.mean() < 1.5 and err.max() < 4.0


def test_skin_over_hole_is_filled_and_not_observed(scene, head_male):
    skin, scan, fitted = scene
    lo, hi = skin.vertices.min(axis=0), skin.vertices.max(axis=0)
    rgb = np.rint(gradient(scan.vertices, lo, hi)).astype(np.uint8)
    colours = ScanColours("scan.ply", scan.n_vertices, scan.faces, vertex_rgb=rgb)
    out = transfer_colours(fitted, scan, colours)
    centre = head_male.skin_landmarks.as_dict()["chk_l"]  # a 12 mm hole in the scan
    inner = np.linalg.norm(skin.vertices - centre, axis=1) < 7.0
    assert inner.sum() >= 3
    assert not out.observed[inner].any()
    assert out.distance[inner].min() > 3.0
    # filled harmonically from the rim: close to the ramp, not a flat grey
    expected = gradient(fitted.vertices[inner], lo, hi)
    assert np.abs(out.rgb[inner].astype(float) - expected).max() < 12.0
    assert not np.all(out.rgb[inner] == NO_COLOUR)


def test_texture_colours_recovered_and_rewinding_is_harmless(scene):
    skin, scan, fitted = scene
    lo, hi = skin.vertices.min(axis=0), skin.vertices.max(axis=0)
    # planar projection of x, y as texture coordinates; the image is a smooth ramp of u, v
    uv_v = (scan.vertices[:, :2] - lo[:2]) / (hi[:2] - lo[:2])
    corner_uv = uv_v[scan.faces]
    h, w = 256, 320
    yy, xx = np.mgrid[0:h, 0:w]
    u, v = (xx + 0.5) / w, 1.0 - (yy + 0.5) / h
    image = np.stack([40 + 180 * u, 40 + 180 * v, 200 - 150 * u * v], axis=-1)
    image = np.rint(image).astype(np.uint8)
    colours = ScanColours("scan.obj", scan.n_vertices, scan.faces, corner_uv=corner_uv, image=image)
    rewound = Mesh(scan.vertices, scan.faces[:, [1, 2, 0]][:, ::-1])
    for mesh in (scan, rewound):
        out = transfer_colours(fitted, mesh, colours)
        assert out.kind == "texture"
        fu, fv = ((fitted.vertices[:, :2] - lo[:2]) / (hi[:2] - lo[:2])).T
        expected = np.stack([40 + 180 * fu, 40 + 180 * fv, 200 - 150 * fu * fv], axis=1)
        err = np.abs(out.rgb.astype(float) - expected)[out.observed]
        assert out.observed.mean() > 0.9
        assert np.median(err) < 1.5 and np.percentile(err, 99) < 5.0


def test_colours_of_another_mesh_are_refused(scene):
    _, scan, fitted = scene
    rgb = np.zeros((scan.n_vertices - 1, 3), np.uint8)
    colours = ScanColours("other.ply", scan.n_vertices - 1, scan.faces[:10], vertex_rgb=rgb)
    with pytest.raises(InputError, match=r"other\.ply.*vertices"):
        transfer_colours(fitted, scan, colours)
    uv = np.zeros((scan.n_faces, 3, 2))
    img = np.zeros((4, 4, 3), np.uint8)
    shuffled = ScanColours("other.obj", scan.n_vertices, scan.faces[::-1], corner_uv=uv, image=img)
    with pytest.raises(InputError, match="triangles"):
        transfer_colours(fitted, scan, shuffled)


def test_fill_gives_unreached_component_the_mean():
    # two separate triangles; only the first has known colours
    verts = np.r_[np.eye(3), np.eye(3) + [0, 0, 5]]
    mesh = Mesh(verts, [[0, 1, 2], [3, 4, 5]])
    rgb = np.zeros((6, 3))
    rgb[:3] = [[0, 0, 0], [30, 60, 90], [60, 120, 180]]
    known = np.array([1, 1, 1, 0, 0, 0], bool)
    out = fill_colours(mesh, rgb, known)
    np.testing.assert_allclose(out[:3], rgb[:3])
    np.testing.assert_allclose(out[3:], [[30, 60, 90]] * 3, atol=1e-3)
    assert np.all(fill_colours(mesh, rgb, np.zeros(6, bool)) == NO_COLOUR)


def test_fill_is_harmonic_on_a_path():
    # a strip of triangles along x: the unknown middle rises smoothly from one end to the other
    n = 11
    xs = np.arange(n, dtype=float)
    verts = np.r_[np.c_[xs, np.zeros(n), np.zeros(n)], np.c_[xs, np.ones(n), np.zeros(n)]]
    faces = [[i, i + 1, n + i] for i in range(n - 1)] + [
        [i + 1, n + i + 1, n + i] for i in range(n - 1)
    ]
    mesh = Mesh(verts, faces)
    known = (verts[:, 0] == 0) | (verts[:, 0] == n - 1)
    rgb = np.where(
        known[:, None], np.c_[verts[:, 0] * 20, verts[:, 0] * 10, 255 - verts[:, 0] * 20], 0
    )
    out = fill_colours(mesh, rgb, known)
    np.testing.assert_allclose(out[known], rgb[known])
    for row in (slice(0, n), slice(n, 2 * n)):
        assert np.all(np.diff(out[row, 0]) > 0) and np.all(np.diff(out[row, 2]) < 0)
    # uniform edge weights: near, not exactly, linear along the strip
    assert np.abs(out[:, 0] - verts[:, 0] * 20).max() < 8.0


def test_sample_image_bilinear_and_wraps():
    img = np.zeros((2, 2, 3), np.uint8)
    img[0, 0] = [200, 0, 0]  # top-left texel
    img[1, 1] = [0, 100, 0]  # bottom-right texel
    out = sample_image(img, np.array([[0.25, 0.75], [0.75, 0.25], [0.5, 0.5], [1.25, 0.75]]))
    np.testing.assert_allclose(out[0], [200, 0, 0])
    np.testing.assert_allclose(out[1], [0, 100, 0])
    np.testing.assert_allclose(out[2], [50, 25, 0])
    np.testing.assert_allclose(out[3], out[0])
    assert np.isnan(sample_image(img, np.array([[np.nan, 0.5]]))).all()
