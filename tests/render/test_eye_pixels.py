"""Eyes that read as eyes (issue 34 item 1): pupil, iris and sclera on the rendered pixels.

Real data: ``skull.obj`` × 15 mm with the male reference head's suggested landmarks,
fitted once for the module (the face and the fitted head's eyes, in the skull file's
frame, mm).  The front picture and the builds panel are rendered and the eyes'
points projected into them by the renderer's own world → display conversion (taken
right after each picture is shot); the age compare picture (the reference head) by
its parallel projection.  The pupil (the globe's centre + gaze × radius) must be dark, the
iris (4.5 mm from the pole along the surface, toward the nose and the ear) brown at
a middle luminance, the sclera beside it (40° from the gaze) light and nearly
colourless, unlike the skin.  The same holds for a mirror image of the case (the
picture is drawn reflected, the eyes' gaze read in the frame they are drawn in).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from workbench.core.appearance import eye_gazes, rgb_to_hsv
from workbench.core.mesh import Mesh
from workbench.render import reconstruction
from workbench.render.age_pictures import _frame, render_compare
from workbench.render.reconstruction import render_builds, render_reconstruction

pytestmark = pytest.mark.render
SIZE = (600, 700)
IRIS_MM = 4.5  # from the pole along the surface: inside the 11.7 mm iris, outside the pupil
SCLERA_DEG = 40.0  # 8 mm from the gaze axis: beside the iris, inside the lid opening


@pytest.fixture(scope="module")
def fitted(skull_obj_suggested, head_male):
    """``(skull, face, eyes, centres, radius, input_to_head)`` of a real fit, input frame."""
    from workbench.services.reconstruction.reconstruct import reconstruct

    skull, landmarks = skull_obj_suggested
    recon = reconstruct(skull, landmarks, head_male)
    eyes = recon.mesh_to_input(recon.head.meshes["eyes"])
    centres = recon.to_input(np.asarray(recon.head.eye_centres, float))
    return skull, recon.face, eyes, centres, float(recon.head.eye_radius), recon.input_to_head


def eye_points(centres: np.ndarray, gazes: np.ndarray, radius: float) -> dict[str, np.ndarray]:
    """``{name: (k, 3)}`` points on each globe (mm): the pupil, the iris and the sclera
    toward the nose (medial) and the ear (lateral)."""
    mid = centres.mean(axis=0)
    out: dict[str, list[np.ndarray]] = {}
    for c, g in zip(centres, gazes, strict=True):
        lateral = (c - mid) - ((c - mid) @ g) * g
        lateral /= np.linalg.norm(lateral)
        out.setdefault("pupil", []).append(c + radius * g)
        for side, e in (("medial", -lateral), ("lateral", lateral)):
            for part, angle in (("iris", IRIS_MM / radius), ("sclera", np.radians(SCLERA_DEG))):
                p = c + radius * (np.cos(angle) * g + np.sin(angle) * e)
                out.setdefault(f"{part}_{side}", []).append(p)
    return {k: np.array(v) for k, v in out.items()}


def to_display(renderer, points: np.ndarray) -> np.ndarray:
    """``(k, 2)`` display pixels (x right, y up from the bottom) of world points (mm)."""
    out = []
    for p in points:
        renderer.SetWorldPoint(*np.asarray(p, float), 1.0)
        renderer.WorldToDisplay()
        out.append(renderer.GetDisplayPoint()[:2])
    return np.array(out)


def spy_on_shots(monkeypatch, points: dict[str, np.ndarray]) -> dict[str, dict[str, np.ndarray]]:
    """Record, for each picture shot, where ``points`` fall in its last panel (display px)."""
    seen: dict[str, dict[str, np.ndarray]] = {}
    shoot: Callable = reconstruction._shoot

    def spy(studio, path, panels, draw, **kw):
        out = shoot(studio, path, panels, draw, **kw)
        renderer = studio.plotter.renderer
        seen[Path(path).name] = {k: to_display(renderer, v) for k, v in points.items()}
        return out

    monkeypatch.setattr(reconstruction, "_shoot", spy)
    return seen


def pixel(image: np.ndarray, xy: np.ndarray, x0: int = 0) -> np.ndarray:
    """RGB (0-255) at display point ``xy`` of a panel starting at column ``x0``."""
    x, y = (int(round(v)) for v in xy)
    return image[image.shape[0] - 1 - y, x0 + x].astype(float)


def luminance(rgb: np.ndarray) -> float:
    return float(rgb @ np.array([0.2126, 0.7152, 0.0722]))


def check_eye(rgb: dict[str, np.ndarray], where: str) -> None:
    """The pupil dark, the iris brown (hue 5-50°) at a middle luminance, the sclera light
    and nearly grey (the skin is light too, but clearly orange)."""
    values = {k: (tuple(int(c) for c in v), round(luminance(v))) for k, v in rgb.items()}
    note = f"{where}: {values}"
    print(note)  # the measured (R, G, B) and luminance per point
    assert luminance(rgb["pupil"]) < 60, note
    for side in ("medial", "lateral"):
        iris = rgb[f"iris_{side}"]
        hue, sat, _ = rgb_to_hsv(iris / 255.0)
        assert 20 < luminance(iris) < 150 and 5 / 360 < hue < 50 / 360 and sat > 0.2, note
        sclera = rgb[f"sclera_{side}"]
        assert luminance(sclera) > 140 and np.ptp(sclera) < 40, note


def mirrored(mesh: Mesh) -> Mesh:
    return Mesh(mesh.vertices * [-1.0, 1.0, 1.0], mesh.faces[:, ::-1])


@pytest.mark.parametrize("mirror", [False, True], ids=["as_scanned", "mirror_image"])
def test_the_front_picture_shows_pupil_iris_and_sclera(fitted, mirror, monkeypatch, tmp_path):
    skull, face, eyes, centres, radius, to_head = fitted
    if mirror:  # the same case in a mirror-image file: x negated
        flip = np.diag([-1.0, 1.0, 1.0, 1.0])
        skull, face, eyes = mirrored(skull), mirrored(face), mirrored(eyes)
        centres, to_head = centres * [-1.0, 1.0, 1.0], to_head @ flip
    gazes = eye_gazes(eyes.vertices, centres)  # read from the corneas, in this frame
    points = eye_points(centres, gazes, radius)
    seen = spy_on_shots(monkeypatch, points)
    out = render_reconstruction(
        skull, face, None, tmp_path, frame=to_head, eyes=eyes, views=("front",), size=SIZE
    )
    image = np.asarray(Image.open(out["face_front"]).convert("RGB"))
    where = seen[out["face_front"].name]
    label = "front picture" + (", mirror image" if mirror else "")
    for k in range(len(centres)):
        check_eye({name: pixel(image, xy[k]) for name, xy in where.items()}, f"{label}, eye {k}")
    # the subject's right eye on the viewer's left, mirrored file or not
    right = int(
        np.argmin((centres - centres.mean(axis=0)) @ np.linalg.solve(to_head[:3, :3], [1, 0, 0]))
    )
    assert where["pupil"][right][0] < where["pupil"][1 - right][0]


def test_the_builds_panel_shows_the_eyes(fitted, monkeypatch, tmp_path):
    skull, face, eyes, centres, radius, to_head = fitted
    points = eye_points(centres, eye_gazes(eyes.vertices, centres), radius)
    seen = spy_on_shots(monkeypatch, points)
    out = render_builds(
        {"average": face}, tmp_path, frame=to_head, eyes=eyes, skull=skull, size=SIZE
    )
    image = np.asarray(Image.open(out["builds_front"]).convert("RGB"))
    where = seen[out["builds_front"].name]
    for k in range(len(centres)):
        rgb = {name: pixel(image, xy[k]) for name, xy in where.items()}
        check_eye(rgb, f"builds panel, eye {k}")


def test_the_age_picture_shows_pupil_iris_and_sclera(head_male, tmp_path):
    """The compare picture (source front in its first panel): a parallel projection onto
    the panel, centred on :func:`_frame`'s focal point, half a panel high per scale."""
    size = (480, 560)
    path = render_compare(head_male, head_male, tmp_path / "compare.png", size=size)
    image = np.asarray(Image.open(path).convert("RGB"))
    centre, half = _frame([head_male.skin, head_male.skin])
    eyes = head_male.meshes["eyes"]
    centres = np.asarray(head_male.eye_centres, float)
    points = eye_points(centres, eye_gazes(eyes.vertices, centres), head_male.eye_radius)
    px_per_mm = size[1] / 2 / half
    for k in range(len(centres)):
        rgb = {}
        for name, p in points.items():
            xy = np.array([size[0] / 2, size[1] / 2]) + (p[k, :2] - centre[:2]) * px_per_mm
            rgb[name] = pixel(image, xy)
        check_eye(rgb, f"age compare picture, eye {k}")
