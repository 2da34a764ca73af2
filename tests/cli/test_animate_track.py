"""``workbench animate --track``: numbered frames, the last frame, a glTF clip, clear errors."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from workbench.cli.main import main
from workbench.io.mesh_formats import ply
from workbench.io.meshes import read_mesh

TRACK = {
    "fps": 30,
    "keys": [{"t": 0.0, "expression": "neutral"}, {"t": 0.2, "expression": "smile"}],
    "phonemes": [{"p": "M", "start": 0.05, "end": 0.12}, {"p": "aa", "start": 0.12, "end": 0.2}],
    "duration": 0.2,
}


@pytest.fixture
def track(tmp_path: Path) -> Path:
    path = tmp_path / "hello.json"
    path.write_text(json.dumps(TRACK), "utf-8")
    return path


def test_frames_and_last_frame(tmp_path: Path, track: Path, head_male, capsys) -> None:
    out = tmp_path / "frames" / "frame_###.ply"
    assert main(["animate", "reference:male", "--track", str(track), "--out", str(out)]) == 0
    said = capsys.readouterr().out
    assert "7 frames at 30 fps" in said and "20 simulation steps a frame" in said
    files = sorted((tmp_path / "frames").iterdir())
    assert [f.name for f in files] == [f"frame_{i:03d}.ply" for i in range(7)]
    meshes = [read_mesh(f, units="mm").mesh.vertices for f in files]
    assert all(len(v) == head_male.skin.n_vertices for v in meshes)
    comments = " ".join(ply.header_comments(files[3]))
    assert "head frame" in comments and "frame 3 t=0.1s" in comments
    # the frames move: the jaw opens for the /aa/ and the smile comes in
    moved = [np.linalg.norm(v - head_male.skin.vertices, axis=1).max() for v in meshes]
    assert moved[-1] > 3.0 and moved[0] < moved[-1]
    # .ply alone: the last frame, the same as the sequence's
    last = tmp_path / "last.ply"
    assert main(["animate", "reference:male", "--track", str(track), "--out", str(last)]) == 0
    assert "the last frame, t = 0.2 s" in capsys.readouterr().out
    assert np.abs(read_mesh(last, units="mm").mesh.vertices - meshes[-1]).max() < 1e-4
    # the folder is never replaced without --force; with it the old one is kept
    assert main(["animate", "reference:male", "--track", str(track), "--out", str(out)]) == 2
    assert "already exists" in capsys.readouterr().err
    assert (
        main(["animate", "reference:male", "--track", str(track), "--out", str(out), "--force"])
        == 0
    )
    assert (tmp_path / "frames.1" / "frame_000.ply").is_file()


def test_track_glb_clip(tmp_path: Path, head_male, capsys) -> None:
    import pygltflib

    path = tmp_path / "t.json"
    path.write_text(
        json.dumps(
            {
                "fps": 10,
                "keys": [{"t": 0.0}, {"t": 0.5, "expression": "smile"}],
                "phonemes": [
                    {"p": "M", "start": 0.1, "end": 0.2},
                    {"p": "AA", "start": 0.2, "end": 0.3},
                ],
            }
        ),
        "utf-8",
    )
    out = tmp_path / "clip.glb"
    assert main(["animate", "reference:male", "--track", str(path), "--out", str(out)]) == 0
    assert "3 morph targets (1 expressions, 0 key poses, 2 visemes)" in capsys.readouterr().out
    gltf = pygltflib.GLTF2().load(str(out))
    by_name = {n.name: i for i, n in enumerate(gltf.nodes)}
    mesh = gltf.meshes[gltf.nodes[by_name["skin"]].mesh]
    assert mesh.extras["targetNames"] == ["smile", "viseme_M", "viseme_AA"]
    # the /aa/ opens the jaw: the mandible carries the same targets, and its clip too
    mand_node = by_name["mandible"]
    mand = gltf.meshes[gltf.nodes[mand_node].mesh]
    assert mand.extras["targetNames"] == mesh.extras["targetNames"]
    k = mand.primitives[0].targets[2]["POSITION"]
    assert gltf.accessors[k].min[1] < -0.002  # metres: the chin goes down > 2 mm
    (clip,) = gltf.animations
    assert {c.target.path for c in clip.channels} == {"weights"}
    assert {by_name["skin"], mand_node} <= {c.target.node for c in clip.channels}
    sampler = clip.samplers[clip.channels[0].sampler]
    times = gltf.accessors[sampler.input]
    assert times.count == 7 and times.max == [pytest.approx(0.6)]
    blob = gltf.binary_blob()
    acc = gltf.accessors[sampler.output]
    view = gltf.bufferViews[acc.bufferView]
    w = np.frombuffer(blob, "<f4", acc.count, view.byteOffset + (acc.byteOffset or 0))
    w = w.reshape(7, 3)
    assert w[-1, 0] == pytest.approx(1.0) and w[0, 0] == 0.0  # neutral -> smile
    assert w[:, 1].argmax() in (1, 2) and w[:, 1].max() > 0.5  # the /m/ at 0.1-0.2 s
    assert w[:, 2].argmax() in (2, 3) and w[:, 2].max() > 0.5  # the /aa/ at 0.2-0.3 s


@pytest.mark.parametrize(
    ("extra", "out_name", "message"),
    [
        (["--expression", "smile"], "a.ply", "cannot be combined with --expression"),
        ([], "frames/a_#_#.ply", "more than one run of #"),
        ([], "frame_##.ply", "folder of its own"),
        ([], "frames/f_##.glb", "whole clip"),
        ([], "a.stl", "DIR/frame_####.ply"),
    ],
)
def test_track_bad_options(
    tmp_path: Path, track: Path, monkeypatch, capsys, extra, out_name, message
) -> None:
    monkeypatch.chdir(tmp_path)
    args = ["animate", "reference:male", "--track", str(track), *extra, "--out", out_name]
    assert main(args) == 2
    assert message in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["hello.json"]


def test_bad_track_file_is_named(tmp_path: Path, capsys) -> None:
    path = tmp_path / "bad.json"
    path.write_text(json.dumps({"keys": [{"t": 0}, {"t": 0.5, "expression": "joy"}]}), "utf-8")
    out = tmp_path / "x.ply"
    assert main(["animate", "reference:male", "--track", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert re.search(r"bad\.json: key 1: 'joy' is not an expression \(valid names: .*smile", err)
    assert not out.exists()
    # a frame pattern without a track
    assert main(["animate", "reference:male", "--out", str(tmp_path / "f" / "f_##.ply")]) == 2
    assert "needs --track" in capsys.readouterr().err
