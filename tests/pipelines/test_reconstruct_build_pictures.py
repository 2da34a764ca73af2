"""The reconstruction folder's pictures: the build pictures join the others, and their
failure costs only themselves (``pipelines.reconstruct.reconstruction_pictures``); the
job draws them in the helper process while it writes its other files
(``pipelines.pictures.PicturesAside``).

The renderers are replaced by stand-ins that record their arguments, and the
job result by a minimal stand-in: only the wiring is under test here
(the pictures themselves: ``tests/render/test_build_pictures.py``).
"""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from workbench.core import helper_process
from workbench.core.mesh import Mesh
from workbench.pipelines.pictures import PicturesAside
from workbench.pipelines.reconstruct import reconstruction_pictures
from workbench.render import reconstruction

TRI = Mesh(np.eye(3), np.array([[0, 1, 2]]))


def is_tri(mesh: Mesh) -> bool:
    """The scene's meshes are bare copies (they cross to the helper as pickles)."""
    return np.array_equal(mesh.vertices, TRI.vertices) and np.array_equal(mesh.faces, TRI.faces)


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
    assert is_tri(call["band_face"]) and call["band_mm"].shape == (3,)
    assert is_tri(call["eyes"]) and is_tri(call["skull"])


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


def test_pictures_aside_falls_back_to_drawing_here(renderers, monkeypatch, tmp_path) -> None:
    """Without a helper process the job's pictures are drawn in the job's process, the same."""

    def no_helper(name, *args, fallback=True):
        assert fallback is False  # a worker thread must never draw in-process itself
        raise RuntimeError("helper process could not start")

    monkeypatch.setattr(helper_process, "call", no_helper)
    aside = PicturesAside()
    aside.start(tmp_path / "pictures", fake_result(fake_builds()))
    paths, notes = aside.finish()
    assert notes == []
    assert {k: str(p.relative_to(tmp_path)) for k, p in paths.items()} == reconstruction_pictures(
        tmp_path, fake_result(fake_builds())
    )


def test_pictures_aside_draws_in_the_helper(monkeypatch, tmp_path: Path) -> None:
    """The real renderers, in the helper process: the same pictures as drawn here."""
    monkeypatch.delenv("WORKBENCH_NO_HELPER_PROCESS", raising=False)
    aside = PicturesAside()
    (tmp_path / "aside").mkdir()  # the job's (staged) folder
    aside.start(tmp_path / "aside" / "pictures", fake_result(fake_builds()))
    paths, notes = aside.finish()
    assert helper_process.status() == ""
    (tmp_path / "here").mkdir()
    here = reconstruction_pictures(tmp_path / "here", fake_result(fake_builds()))
    assert notes == [] and set(paths) == set(here) and len(here) >= 4
    assert all(p.is_file() and p.stat().st_size > 1000 for p in paths.values())


def test_no_pictures_into_a_folder_that_is_gone(tmp_path: Path) -> None:
    """A job stopped while the helper was still to draw: nothing is written, not even the
    folder again (it would be left behind beside the output)."""
    from workbench.pipelines.pictures import draw_scene, picture_scene

    gone = tmp_path / "staged" / "pictures"
    paths, notes = draw_scene(str(gone), picture_scene(fake_result(None)))
    assert paths == {} and "no longer exists" in notes[0] and not gone.parent.exists()


def test_a_failed_job_waits_for_the_helper_before_its_folder_goes(
    renderers, monkeypatch, tmp_path: Path
) -> None:
    """Writing the meshes fails while the pictures are drawn aside: the error comes out,
    but only once the helper is done with the folder (the staged folder is removed next)."""
    from workbench.pipelines import reconstruct
    from workbench.services.reconstruction import job

    order: list[str] = []

    class Aside:
        def start(self, out, result):
            order.append("start")

        def wait(self):
            order.append("wait")

        def finish(self):
            raise AssertionError("no report for a failed job")

    def broken(result, out, staged):
        raise OSError("disk full")

    monkeypatch.setattr(job, "write_outputs", broken)
    with pytest.raises(OSError, match="disk full"):
        reconstruct.write_reconstruction(fake_result(None), tmp_path, aside=Aside())  # type: ignore[arg-type]
    assert order == ["start", "wait"]
