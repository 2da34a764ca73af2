"""Pictures of the three build faces and the 95 % band (:func:`render_builds`).

Synthetic faces: ellipsoids of known widths (mm) standing in for the slender,
average and heavy faces of one skull, so the pictures can be measured: one
camera for the three panels means their widths in pixels keep the ratio of
their widths in mm.  Pictures are small to keep the module fast.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from scipy.spatial.transform import Rotation

from workbench.core.errors import InputError
from workbench.core.mesh import Mesh, concatenate
from workbench.render.reconstruction import NECK_MARGIN_MM, render_builds

pytestmark = pytest.mark.render
SIZE = (200, 240)
#: half-widths (x), half-heights (y), half-depths (z) in mm, thinnest first
AXES = {
    "slender": (55.0, 100.0, 80.0),
    "average": (70.0, 100.0, 90.0),
    "heavy": (90.0, 100.0, 105.0),
}
BMI = {"slender": 19.0, "average": 24.3, "heavy": 34.0}


def ellipsoid(a: float, b: float, c: float, centre=(0.0, 0.0, 0.0), n: int = 48) -> Mesh:
    """A closed UV ellipsoid (outward triangles), semi-axes ``a, b, c`` mm along x, y, z."""
    theta = np.linspace(0.0, np.pi, n // 2 + 1)[1:-1]  # polar, poles added apart
    phi = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    ring = np.column_stack(
        [
            np.sin(t).ravel() * np.cos(p).ravel(),
            np.cos(t).ravel(),
            np.sin(t).ravel() * np.sin(p).ravel(),
        ]
    )
    verts = np.vstack([[0.0, 1.0, 0.0], ring, [0.0, -1.0, 0.0]])
    rows, cols = len(theta), len(phi)
    idx = 1 + np.arange(rows * cols).reshape(rows, cols)
    nxt = np.roll(idx, -1, axis=1)
    top = np.column_stack([np.zeros(cols, int), nxt[0], idx[0]])
    quads_a = np.column_stack([idx[:-1].ravel(), nxt[:-1].ravel(), nxt[1:].ravel()])
    quads_b = np.column_stack([idx[:-1].ravel(), nxt[1:].ravel(), idx[1:].ravel()])
    bottom = np.column_stack([np.full(cols, len(verts) - 1), idx[-1], nxt[-1]])
    faces = np.vstack([top, quads_a, quads_b, bottom])
    mesh = Mesh(verts * [a, b, c] + np.asarray(centre, float), faces)
    # outward winding: flip when the signed volume comes out negative
    v = mesh.vertices[mesh.faces]
    if np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() < 0:
        mesh = Mesh(mesh.vertices, mesh.faces[:, ::-1])
    return mesh


@pytest.fixture(scope="module")
def faces() -> dict[str, Mesh]:
    return {name: ellipsoid(*axes) for name, axes in AXES.items()}


def pixels(path: Path) -> np.ndarray:
    return np.asarray(Image.open(path).convert("RGB"), float)


def subject(image: np.ndarray) -> np.ndarray:
    """Pixels that are not the white background."""
    return np.abs(image - 255.0).sum(axis=2) > 30


def panel_extent(mask: np.ndarray) -> tuple[int, int, int]:
    """(width, top row, bottom row) in pixels of the subject in one panel, above the label
    strip (the lowest 15 % of the panel holds the labels and the scale bar)."""
    body = mask[: int(0.85 * mask.shape[0])]
    cols = np.flatnonzero(body.any(axis=0))
    rows = np.flatnonzero(body.any(axis=1))
    return int(cols[-1] - cols[0] + 1), int(rows[0]), int(rows[-1])


def thirds(image: np.ndarray) -> list[np.ndarray]:
    w = image.shape[1] // 3
    return [image[:, k * w : (k + 1) * w] for k in range(3)]


def test_three_faces_side_by_side_at_one_scale(faces, tmp_path: Path) -> None:
    band = 2.0 + np.abs(faces["average"].vertices[:, 0]) / 10.0
    out = render_builds(
        faces,
        tmp_path,
        bmi=BMI,
        main="average",
        band_face=faces["average"],
        band_mm=band,
        size=SIZE,
    )
    assert set(out) == {"builds_front", "builds_side", "band"}
    for key, path in out.items():
        assert path == tmp_path / f"{key}.png" and path.is_file()
        image = pixels(path)
        assert image.shape == (SIZE[1], 3 * SIZE[0], 3), key
        assert image.std() > 20.0, key  # not blank
    # front: widths in pixels in the order and the ratio of the widths in mm (one scale)
    front = [panel_extent(subject(t)) for t in thirds(pixels(out["builds_front"]))]
    widths = np.array([w for w, _, _ in front], float)
    assert widths[0] < widths[1] < widths[2], widths
    mm = np.array([2 * AXES[n][0] for n in AXES])
    np.testing.assert_allclose(widths / widths[2], mm / mm[2], atol=0.04)
    # the same vertical placement: equal heights in mm give the same top and bottom rows
    tops, bottoms = [t for _, t, _ in front], [b for _, _, b in front]
    assert max(tops) - min(tops) <= 2 and max(bottoms) - min(bottoms) <= 2, (tops, bottoms)
    # right profile: the depths (z) in the same order and ratio
    side = np.array(
        [panel_extent(subject(t))[0] for t in thirds(pixels(out["builds_side"]))], float
    )
    depth = np.array([2 * AXES[n][2] for n in AXES])
    np.testing.assert_allclose(side / side[2], depth / depth[2], atol=0.04)
    # a label under every face; one scale bar, in the last panel only (dark ink at its right)
    for k, third in enumerate(thirds(pixels(out["builds_front"]))):
        strip = subject(third[int(0.86 * SIZE[1]) :])  # under the faces
        assert strip[:, : int(0.7 * SIZE[0])].sum() > 30, k
        has_bar = strip[:, int(0.8 * SIZE[0]) :].sum() > 15
        assert has_bar == (k == 2), k
    # the band picture is coloured by the colour map (deep reds), not skin
    band_img = pixels(out["band"])
    assert ((band_img[..., 0] > 150) & (band_img[..., 1] < 90)).sum() > 200


def test_order_prefix_eyes_and_no_band(faces, tmp_path: Path) -> None:
    """Panels follow the dict's order; a prefix names the files; no band, no band picture."""
    reverse = {n: faces[n] for n in reversed(list(faces))}
    eyes = concatenate([ellipsoid(12.0, 12.0, 12.0, (x, 20.0, 100.0)) for x in (-30.0, 30.0)])
    out = render_builds(reverse, tmp_path, eyes=eyes, prefix="case7", size=SIZE)
    assert set(out) == {"builds_front", "builds_side"}
    assert out["builds_front"].name == "case7_builds_front.png"
    widths = [panel_extent(subject(t))[0] for t in thirds(pixels(out["builds_front"]))]
    assert widths[0] > widths[1] > widths[2], widths
    # the eyes (a light, nearly grey sclera, where the skin is far redder) show in every panel
    for k, third in enumerate(thirds(pixels(out["builds_front"]))):
        grey = subject(third) & (np.ptp(third, axis=2) < 40) & (third.min(axis=2) > 120)
        assert grey[: int(0.85 * SIZE[1])].sum() > 40, k


def test_frame_and_skull_cut(faces, tmp_path: Path) -> None:
    """Faces in scanner coordinates are turned by the frame; a skull cuts them below it."""
    to_scanner = np.eye(4)
    to_scanner[:3, :3] = Rotation.from_euler("xyz", [90.0, 25.0, -40.0], degrees=True).as_matrix()
    to_scanner[:3, 3] = [120.0, -35.0, 410.0]
    scanned = {n: m.transformed(to_scanner) for n, m in faces.items()}
    ref = render_builds(faces, tmp_path / "ref", size=SIZE)
    framed = render_builds(scanned, tmp_path / "framed", frame=np.linalg.inv(to_scanner), size=SIZE)
    a, b = pixels(ref["builds_front"]), pixels(framed["builds_front"])
    assert np.abs(a - b).mean() < 3.0
    # a skull whose lowest point is 30 mm above the faces' centre: cut 20 mm below that
    skull = ellipsoid(40.0, 40.0, 40.0, (0.0, 70.0, 0.0))
    cut = render_builds(faces, tmp_path / "cut", skull=skull, size=SIZE)
    whole = [panel_extent(subject(t)) for t in thirds(pixels(ref["builds_front"]))]
    bust = [panel_extent(subject(t)) for t in thirds(pixels(cut["builds_front"]))]
    # the whole faces are 200 mm tall; the busts 100 + 30 - 20 = 110 mm (the camera frames them)
    assert NECK_MARGIN_MM == 20.0
    for (w0, t0, b0), (w1, t1, b1) in zip(whole, bust, strict=True):
        ratio_whole, ratio_bust = (b0 - t0) / w0, (b1 - t1) / w1
        assert ratio_bust < 0.75 * ratio_whole, (ratio_whole, ratio_bust)


def test_bad_input_is_named(faces, tmp_path: Path) -> None:
    face = faces["average"]
    with pytest.raises(InputError, match="no BMI for the 'heavy'"):
        render_builds(faces, tmp_path, bmi={"slender": 19.0, "average": 24.0})
    with pytest.raises(InputError, match="positive number"):
        render_builds(faces, tmp_path, bmi={**BMI, "heavy": float("nan")})
    with pytest.raises(InputError, match="values for a face of"):
        render_builds(faces, tmp_path, band_face=face, band_mm=np.ones(10))
    with pytest.raises(InputError, match="cannot be negative"):
        render_builds(faces, tmp_path, band_face=face, band_mm=-np.ones(face.n_vertices))
    with pytest.raises(InputError, match="NaN"):
        render_builds(faces, tmp_path, band_face=face, band_mm=np.full(face.n_vertices, np.nan))
    with pytest.raises(InputError, match="needs both"):
        render_builds(faces, tmp_path, band_mm=np.ones(face.n_vertices))
    with pytest.raises(InputError, match="no triangles"):
        render_builds({**faces, "heavy": Mesh(face.vertices)}, tmp_path)
    with pytest.raises(InputError, match="nothing to draw"):
        render_builds({}, tmp_path)
    with pytest.raises(InputError, match="singular"):
        render_builds(faces, tmp_path, frame=np.zeros((4, 4)))
    assert not list(tmp_path.glob("*.png"))
