"""The README's main job: ``workbench demo`` on the built-in default case."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from workbench.cli.main import main
from workbench.io.meshes import read_mesh


@pytest.mark.render
def test_demo_writes_surfaces_summary_and_picture(tmp_path: Path) -> None:
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    bone = read_mesh(out / "headsq_bone.ply").mesh
    skin = read_mesh(out / "headsq_skin.ply").mesh
    assert summary["surfaces"]["bone"]["n_faces"] == bone.n_faces
    # the skin encloses the bone: wider and deeper
    assert skin.extent[0] > bone.extent[0] + 20 and skin.extent[1] > bone.extent[1] + 10
    picture = out / summary["picture"]
    from PIL import Image

    image = np.asarray(Image.open(picture).convert("RGB")).astype(int)
    non_white = (np.abs(image - 255).sum(axis=2) > 30).mean()
    assert non_white > 0.05, "the rendered picture is (nearly) blank"
