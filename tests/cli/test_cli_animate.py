"""``workbench animate``: a posed skin written as PLY/OBJ (mm), and clear errors for bad input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from workbench.cli.main import main
from workbench.io.mesh_formats import ply
from workbench.io.meshes import read_mesh


def test_animate_reference_smile_writes_ply(tmp_path: Path, head_male, capsys) -> None:
    out = tmp_path / "smile.ply"
    assert main(["animate", "reference:male", "--expression", "smile", "--out", str(out)]) == 0
    mesh = read_mesh(out, units="mm").mesh
    assert mesh.n_vertices == head_male.skin.n_vertices
    moved = np.linalg.norm(mesh.vertices - head_male.skin.vertices, axis=1)
    assert 3.0 < moved.max() < 30.0
    comments = " ".join(ply.header_comments(out))
    assert "head frame" in comments and "mm" in comments and "expression=smile" in comments
    assert "wrote" in capsys.readouterr().out
    # never replaced without --force; with --force the old file is kept
    assert main(["animate", "reference:male", "--muscle", "mentalis=0.5", "--out", str(out)]) == 2
    assert "already exists" in capsys.readouterr().err
    args = [
        "animate",
        "reference:male",
        "--muscle",
        "mentalis=0.5",
        "--jaw",
        "5",
        "--out",
        str(out),
    ]
    assert main([*args, "--force"]) == 0
    assert (tmp_path / "smile.1.ply").is_file()


def test_animate_template_pack_to_obj(tmp_path: Path, head_male) -> None:
    from workbench.io.template_pack import export_template

    pack = tmp_path / "pack"
    export_template(head_male, pack)
    out = tmp_path / "open.obj"
    assert main(["animate", str(pack), "--jaw", "10", "--out", str(out)]) == 0
    mesh = read_mesh(out, units="mm").mesh
    low = head_male.skin.vertices[:, 1] < -60.0
    drop = head_male.skin.vertices[low, 1] - mesh.vertices[low, 1]
    assert drop.max() > 8.0  # the chin went down with the jaw


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--muscle", "zygomatic=0.3"], "valid names: .*zygomaticus_major_l"),
        (["--muscle", "mentalis=1.5"], "between 0"),
        (["--muscle", "mentalis"], "NAME=C"),
        (["--expression", "joy"], "valid names: .*happiness"),
        (["--jaw", "90"], "range"),
    ],
)
def test_animate_bad_input(tmp_path: Path, head_male, capsys, extra, message) -> None:
    out = tmp_path / "x.ply"
    assert main(["animate", "reference:male", *extra, "--out", str(out)]) == 2
    import re

    assert re.search(message, capsys.readouterr().err)
    assert not out.exists()


def test_animate_bad_head_and_output(tmp_path: Path, capsys) -> None:
    assert main(["animate", str(tmp_path), "--out", str(tmp_path / "a.ply")]) == 2
    assert "template pack" in capsys.readouterr().err
    assert main(["animate", "reference:cat", "--out", str(tmp_path / "a.ply")]) == 2
    assert main(["animate", "reference:male", "--out", str(tmp_path / "a.stl")]) == 2
    assert ".ply or .obj" in capsys.readouterr().err


def test_animate_reconstruction_folder(tmp_path: Path, head_male) -> None:
    """A reconstruction folder holds its head as head/ in the skull file's frame."""
    from workbench.io.template_pack import export_template

    shift = np.array([10.0, 200.0, -35.0])
    export_template(
        head_male.warped(lambda p: np.asarray(p) + shift),
        tmp_path / "recon" / "head",
        frame="the skull file's frame, mm",
    )
    out = tmp_path / "recon_smile.ply"
    assert (
        main(["animate", str(tmp_path / "recon"), "--expression", "smile", "--out", str(out)]) == 0
    )
    assert "the skull file's frame" in " ".join(ply.header_comments(out))
    mesh = read_mesh(out, units="mm").mesh
    moved = np.linalg.norm(mesh.vertices - (head_male.skin.vertices + shift), axis=1)
    assert 3.0 < moved.max() < 30.0  # posed, and still in the pack's frame


def test_animate_glb_morph_targets(tmp_path: Path, head_male, capsys) -> None:
    """--out .glb: the expressions as morph targets; weight 1 on one = its settled skin."""
    import pygltflib

    from workbench.services.animation.animator import Animator

    out = tmp_path / "head.glb"
    args = ["animate", "reference:male", "--targets", "smile,au26", "--expression", "happiness"]
    assert main([*args, "--out", str(out)]) == 0
    assert "3 morph targets" in capsys.readouterr().out
    gltf = pygltflib.GLTF2().load(str(out))
    by_name = {n.name: i for i, n in enumerate(gltf.nodes)}
    assert {"skin", "eyes", "upper_teeth", "lower_teeth", "tongue", "mandible"} <= set(by_name)
    mesh = gltf.meshes[gltf.nodes[by_name["skin"]].mesh]
    names = mesh.extras["targetNames"]
    assert names == ["smile", "au26", "happiness"]
    assert mesh.weights == [0.0, 0.0, 1.0]
    (prim,) = mesh.primitives
    blob = gltf.binary_blob()

    def read(index: int) -> np.ndarray:
        acc = gltf.accessors[index]
        assert acc.componentType == pygltflib.FLOAT
        view = gltf.bufferViews[acc.bufferView]
        width = 3 if acc.type == "VEC3" else 1
        data = np.frombuffer(
            blob, "<f4", acc.count * width, view.byteOffset + (acc.byteOffset or 0)
        )
        return data.reshape(acc.count, width).astype(float)

    rest = read(prim.attributes.POSITION) * 1000.0  # metres -> mm
    assert len(rest) == head_male.skin.n_vertices
    anim = Animator(head_male)
    anim.set_expression("smile")
    anim.settle()
    want = anim.skin().vertices  # the head's own frame: that of its PLY files
    k = names.index("smile")
    assert gltf.accessors[prim.targets[k]["POSITION"]].count == len(rest)
    frame = rest + 1.0 * read(prim.targets[k]["POSITION"]) * 1000.0
    assert np.abs(frame - want).max() < 0.01  # the glTF frame is `animate --out .ply`'s frame
    # au26 opens the jaw: the mandible node carries the same targets and moves for au26
    mand = gltf.meshes[gltf.nodes[by_name["mandible"]].mesh]
    assert mand.extras["targetNames"] == names
    assert np.abs(read(mand.primitives[0].targets[1]["POSITION"])).max() > 1e-3  # > 1 mm
    (clip,) = gltf.animations
    assert {c.target.path for c in clip.channels} == {"weights"}
    assert by_name["skin"] in {c.target.node for c in clip.channels}
    times = read(clip.samplers[0].input)[:, 0]
    assert times[0] == 0.0 and times[-1] == 1.0
    # bad requests are refused before any simulation
    bad = tmp_path / "bad.glb"
    assert main(["animate", "reference:male", "--targets", "smile,grin", "--out", str(bad)]) == 2
    assert "grin is not an expression" in capsys.readouterr().err
    assert main(["animate", "reference:male", "--jaw", "5", "--out", str(bad)]) == 2
    assert "morph targets" in capsys.readouterr().err
    assert not bad.exists()


def test_animate_glb_arkit_targets(tmp_path: Path, head_male, capsys) -> None:
    """--arkit: the 52 ARKit names as extra targets, each the weighted sum of its AU targets."""
    import pygltflib

    from workbench.io.arkit_table import read_arkit_table

    out = tmp_path / "arkit.glb"
    args = ["animate", "reference:male", "--targets", "au12,au26", "--arkit", "--out", str(out)]
    assert main(args) == 0
    assert "52 ARKit targets" in capsys.readouterr().out
    gltf = pygltflib.GLTF2().load(str(out))
    by_name = {n.name: i for i, n in enumerate(gltf.nodes)}
    mesh = gltf.meshes[gltf.nodes[by_name["skin"]].mesh]
    names = mesh.extras["targetNames"]
    recipes = read_arkit_table()
    needed = {t for mix in recipes.values() for t in mix}
    assert names[:2] == ["au12", "au26"] and needed <= set(names)  # settled automatically
    assert {"mouthSmileLeft", "jawOpen", "tongueOut"} <= set(names)
    assert set(recipes) <= set(names)
    (prim,) = mesh.primitives
    blob = gltf.binary_blob()

    def read(index: int) -> np.ndarray:
        acc = gltf.accessors[index]
        view = gltf.bufferViews[acc.bufferView]
        data = np.frombuffer(blob, "<f4", acc.count * 3, view.byteOffset + (acc.byteOffset or 0))
        return data.reshape(acc.count, 3).astype(float) * 1000.0  # metres -> mm

    def delta(name: str) -> np.ndarray:
        return read(prim.targets[names.index(name)]["POSITION"])

    want = sum(w * delta(t) for t, w in recipes["jawOpen"].items())
    got = delta("jawOpen")
    assert np.abs(got).max() > 1.0 and np.abs(got - want).max() < 0.01
    assert np.abs(delta("tongueOut")).max() == 0.0  # no AU basis: zero displacement
    # a user table naming an unknown target is refused before any simulation
    table = tmp_path / "mine.csv"
    table.write_text("arkit_name,recipe,source,notes\njawOpen,au26:1;grin:1,me,\n", "utf-8")
    bad = tmp_path / "bad.glb"
    assert main(["animate", "reference:male", "--arkit", str(table), "--out", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "mine.csv" in err and "line 2" in err and "grin" in err and "valid names" in err
    assert main(["animate", "reference:male", "--arkit", "--out", str(tmp_path / "a.ply")]) == 2
    assert "--arkit" in capsys.readouterr().err
    assert not bad.exists()
