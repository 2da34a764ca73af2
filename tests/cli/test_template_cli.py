"""``workbench template export`` and ``workbench render template`` (issue 3, in progress)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import pyvista as pv

from workbench.cli.main import main
from workbench.io.markups import read_landmarks


def test_template_export_writes_loadable_files(tmp_path: Path) -> None:
    out = tmp_path / "pack"
    assert main(["template", "export", "--sex", "female", "--out", str(out)]) == 0
    info = json.loads((out / "template.json").read_text())
    assert info["template_id"].endswith("female") and len(info["content_hash"]) == 64
    # skull-skin offset vectors: the 2023 T-Table pairs are all there, about one depth long
    pg = np.linalg.norm(info["pairs"]["pg"]["offset_mm"])
    assert info["pairs"]["pr"]["skin"] == "ls" and abs(pg - 11.0) < 1.0
    for name in ("skin.ply", "skull.ply", "mandible.ply", "teeth.ply", "eyes.ply", "tongue.ply"):
        mesh = pv.read(out / name)  # other tools read what we write
        assert mesh.n_cells > 1000, name
    muscles = json.loads((out / "muscles.json").read_text())["muscles"]
    assert len(muscles) == 24
    assert {m["kind"] for m in muscles} == {"linear", "sphincter"}
    skin = pv.read(out / "skin.ply")
    assert 5_000 <= skin.n_cells <= 10_000
    skull_lm = read_landmarks(out / "skull.mrk.json", "skull").landmarks
    skin_lm = read_landmarks(out / "skin.mrk.json", "skin").landmarks
    assert {"po_l", "po_r", "or_l", "or_r", "n", "pr", "gn"} <= set(skull_lm.codes)
    # Frankfort Horizontal: porions and orbitales at y = 0 on both surfaces
    for lm in (skull_lm, skin_lm):
        assert np.abs(lm.positions_of(["po_l", "po_r", "or_l", "or_r"])[:, 1]).max() < 0.05


@pytest.mark.render
def test_render_template_pictures_are_not_blank(tmp_path: Path) -> None:
    from PIL import Image

    assert main(["render", "template", "--sex", "male", "--out", str(tmp_path)]) == 0
    pictures = sorted(tmp_path.glob("*.png"))
    assert len(pictures) == 11
    for picture in pictures:
        image = np.asarray(Image.open(picture).convert("RGB")).astype(int)
        assert (np.abs(image - 255).sum(axis=2) > 30).mean() > 0.05, picture.name
