"""Report pictures of a reconstruction: skull + dowels, face over skull, face, spread map.

Real data: the built-in reference head (its cranium, mandible and teeth as
the skull, 2023 T-Table dowels from its skull landmarks, its skin and eyes as
the face).  Pictures are small to keep the module fast.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from scipy.spatial.transform import Rotation

from workbench.core.errors import InputError
from workbench.core.mesh import Mesh, concatenate
from workbench.render.reconstruction import VIEWS, render_reconstruction
from workbench.services.tissue.dowels import DepthSettings, plan_dowels

pytestmark = pytest.mark.render
SIZE = (200, 240)


def merge(*meshes: Mesh) -> Mesh:
    return concatenate(list(meshes))


@pytest.fixture(scope="module")
def scene(head_male):
    head = head_male
    m = head.meshes
    skull = merge(m["cranium"], m["mandible"], m["upper_teeth"], m["lower_teeth"])
    plan = plan_dowels(skull, head.skull_landmarks, DepthSettings(interpolate=False))
    active = plan.active()
    dowels = (np.array([d.origin for d in active]), np.array([d.tip for d in active]))
    return skull, head.skin, m["eyes"], dowels


def pixels(path: Path) -> np.ndarray:
    return np.asarray(Image.open(path).convert("RGB"), float)


def bluish(image: np.ndarray) -> int:
    """Pixels much bluer than red: viridis dowels, never the bone or the skin."""
    return int((image[..., 2] > image[..., 0] + 40).sum())


def test_every_picture_is_written_and_not_blank(scene, tmp_path: Path) -> None:
    skull, skin, eyes, dowels = scene
    spread = np.linalg.norm(skin.vertices - skin.vertices.mean(axis=0), axis=1) / 50.0
    out = render_reconstruction(
        skull, skin, dowels, tmp_path, spread=spread, eyes=eyes, prefix="case7", size=SIZE
    )
    expected = {f"{kind}_{v}" for kind in ("skull_dowels", "face_skull", "face") for v in VIEWS}
    assert set(out) == expected | {"spread"}
    for key, path in out.items():
        assert path.parent == tmp_path and path.name == f"case7_{key}.png"
        image = pixels(path)
        width = SIZE[0] * (3 if key == "spread" else 1)
        assert image.shape == (SIZE[1], width, 3), key
        assert image.std() > 20.0, key  # not blank
        covered = (np.abs(image - 255).sum(axis=2) > 30).mean()
        assert 0.1 < covered < 0.9, (key, covered)  # the subject fills the frame, with a margin
    # dowels show (viridis pegs and bar), the bare face has none; the spread map is coloured
    assert bluish(pixels(out["skull_dowels_front"])) > 300
    assert bluish(pixels(out["face_front"])) < 20
    spread_img = pixels(out["spread"])
    assert ((spread_img[..., 0] > 150) & (spread_img[..., 1] < 90)).sum() > 500  # deep reds


def test_no_face_gives_skull_pictures_only(scene, tmp_path: Path) -> None:
    skull, _, _, dowels = scene
    out = render_reconstruction(skull, None, dowels, tmp_path, views=("front",), size=SIZE)
    assert set(out) == {"skull_dowels_front"}
    bare = render_reconstruction(skull, None, None, tmp_path / "bare", views=("front",), size=SIZE)
    assert (
        bluish(pixels(bare["skull_dowels_front"])) < 20 < bluish(pixels(out["skull_dowels_front"]))
    )


def test_frame_orients_views_of_a_skull_in_scanner_coordinates(scene, tmp_path: Path) -> None:
    """A skull in scanner coordinates, with its frame, looks the same as in the head frame."""
    skull = scene[0]
    to_scanner = np.eye(4)
    to_scanner[:3, :3] = Rotation.from_euler("xyz", [90.0, 25.0, -40.0], degrees=True).as_matrix()
    to_scanner[:3, 3] = [120.0, -35.0, 410.0]
    scanned = skull.transformed(to_scanner)
    views = ("front", "side")
    ref = render_reconstruction(skull, None, None, tmp_path / "ref", views=views, size=SIZE)
    framed = render_reconstruction(
        scanned,
        None,
        None,
        tmp_path / "framed",
        views=views,
        size=SIZE,
        frame=np.linalg.inv(to_scanner),
    )
    unframed = render_reconstruction(scanned, None, None, tmp_path / "raw", views=views, size=SIZE)
    for key in ref:
        a, b, c = (pixels(p[key]) for p in (ref, framed, unframed))
        same, other = np.abs(a - b).mean(), np.abs(a - c).mean()
        assert same < 3.0, (key, same)
        assert other > 4 * same + 5.0, (key, other)


def test_bad_input_is_named(scene, tmp_path: Path) -> None:
    skull, skin, _, (origins, tips) = scene
    with pytest.raises(InputError, match="spread"):
        render_reconstruction(skull, skin, None, tmp_path, spread=np.ones(10))
    with pytest.raises(InputError, match="needs the face"):
        render_reconstruction(skull, None, None, tmp_path, spread=np.ones(skin.n_vertices))
    with pytest.raises(InputError, match="origins but"):
        render_reconstruction(skull, skin, (origins, tips[:-1]), tmp_path)
    with pytest.raises(InputError, match="singular"):
        render_reconstruction(skull, skin, None, tmp_path, frame=np.zeros((4, 4)))
    assert not list(tmp_path.glob("*.png"))
