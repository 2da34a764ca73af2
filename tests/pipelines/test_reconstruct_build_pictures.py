"""The reconstruction folder's pictures: the build pictures join the others, and their
failure costs only themselves (``pipelines.reconstruct.reconstruction_pictures``).

The renderers are replaced by stand-ins that record their arguments, and the
job result by a minimal stand-in: only the wiring is under test here
(the pictures themselves: ``tests/render/test_build_pictures.py``).
"""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from workbench.core.mesh import Mesh
from workbench.pipelines.reconstruct import reconstruction_pictures
from workbench.render import reconstruction

TRI = Mesh(np.eye(3), np.array([[0, 1, 2]]))


def fake_result(builds) -> SimpleNamespace:
    recon = SimpleNamespace(
        plan=SimpleNamespace(active=lambda: []),
        to_input=lambda points: points,
        mesh_to_input=lambda mesh: mesh,
        registration=None,
        head=SimpleNamespace(meshes={"eyes": TRI}),
        face=TRI,
        input_to_head=np.eye(4),
        inferred=None,
    )
    return SimpleNamespace(
        recon=recon,
        opened=SimpleNamespace(
            case=SimpleNamespace(specimen=SimpleNamespace(mesh=TRI), appearance=None)
        ),
        spread=None,
        fit=SimpleNamespace(builds=builds),
    )


def fake_builds() -> SimpleNamespace:
    names = ("slender", "average", "heavy")
    return SimpleNamespace(
        names=names,
        bmi={"slender": 19.0, "average": 24.3, "heavy": 34.0},
        main="average",
        half_width_mm=np.full(3, 9.0),
        face=lambda name, recon: TRI,
    )


@pytest.fixture
def renderers(monkeypatch):
    calls: dict[str, dict] = {}

    def recon_pictures(skull, face, dowels, out_dir, **kw):
        calls["reconstruction"] = kw
        return {"face_front": Path(out_dir) / "recon_face_front.png"}

    def build_pictures(faces, out_dir, **kw):
        calls["builds"] = {"faces": faces, **kw}
        return {k: Path(out_dir) / f"{k}.png" for k in ("builds_front", "builds_side", "band")}

    monkeypatch.setattr(reconstruction, "render_reconstruction", recon_pictures)
    monkeypatch.setattr(reconstruction, "render_builds", build_pictures)
    return calls


def test_build_pictures_join_the_others(renderers, tmp_path: Path) -> None:
    pictures = reconstruction_pictures(tmp_path, fake_result(fake_builds()))
    assert pictures == {
        "face_front": "pictures/recon_face_front.png",
        "builds_front": "pictures/builds_front.png",
        "builds_side": "pictures/builds_side.png",
        "band": "pictures/band.png",
    }
    call = renderers["builds"]
    assert list(call["faces"]) == ["slender", "average", "heavy"]
    assert call["main"] == "average" and call["bmi"]["heavy"] == 34.0
    assert call["band_face"] is TRI and call["band_mm"].shape == (3,)
    assert call["eyes"] is TRI and call["skull"] is TRI


def test_no_builds_no_build_pictures(renderers, tmp_path: Path) -> None:
    pictures = reconstruction_pictures(tmp_path, fake_result(None))
    assert pictures == {"face_front": "pictures/recon_face_front.png"}
    assert "builds" not in renderers
    result = fake_result(None)
    result.fit = None  # a job without a fit (e.g. a library of packs)
    assert reconstruction_pictures(tmp_path, result) == pictures


def test_a_build_picture_failure_is_a_note(renderers, monkeypatch, tmp_path) -> None:
    def broken(faces, out_dir, **kw):
        raise RuntimeError("off-screen window lost")

    monkeypatch.setattr(reconstruction, "render_builds", broken)
    notes: list[str] = []
    pictures = reconstruction_pictures(tmp_path, fake_result(fake_builds()), notes.append)
    assert pictures == {"face_front": "pictures/recon_face_front.png"}
    assert len(notes) == 1 and notes[0].startswith("no build pictures")
