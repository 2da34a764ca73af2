"""``workbench animate --out FILE.glb`` with hair, brows, beard and moustache (issue 34):
``--hair/--brows/--beard/--moustache STYLE``, or the appearance a reconstruction folder's
``case.fcase`` keeps; each piece a node with the skin's morph targets, said to be an
artistic addition."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pygltflib
import pytest

from workbench.cli.main import main
from workbench.model.appearance import Appearance


def _nodes(path: Path) -> tuple[pygltflib.GLTF2, dict[str, pygltflib.Mesh]]:
    gltf = pygltflib.GLTF2().load(str(path))
    return gltf, {n.name: gltf.meshes[n.mesh] for n in gltf.nodes if n.mesh is not None}


def _colours(gltf: pygltflib.GLTF2, mesh: pygltflib.Mesh) -> np.ndarray:
    acc = gltf.accessors[mesh.primitives[0].attributes.COLOR_0]
    offset = gltf.bufferViews[acc.bufferView].byteOffset
    return np.frombuffer(gltf.binary_blob(), "<f4", 3 * acc.count, offset).reshape(-1, 3)


@pytest.mark.slow
def test_animate_glb_with_hair_options(tmp_path: Path, head_male, capsys) -> None:
    plain, groomed = tmp_path / "plain.glb", tmp_path / "groomed.glb"
    args = ["animate", "reference:male", "--targets", "au26"]
    assert main([*args, "--out", str(plain)]) == 0
    capsys.readouterr()
    assert main([*args, "--brows", "thick", "--beard", "short", "--out", str(groomed)]) == 0
    said = capsys.readouterr().out
    assert "brows thick, beard short: artistic additions, not evidence" in said
    gltf, meshes = _nodes(groomed)
    assert {"brows", "beard"} <= set(meshes) and not {"hair", "moustache"} & set(meshes)
    for kind in ("brows", "beard"):
        assert meshes[kind].extras["targetNames"] == ["au26"]
    # the skin is painted under the beard (the case's way), darker than the plain tone
    _, before = _nodes(plain)
    skin_plain = _colours(pygltflib.GLTF2().load(str(plain)), before["skin"])
    skin_groomed = _colours(gltf, meshes["skin"])
    chin = head_male.skin.vertices[:, 1] < -70.0
    assert skin_groomed[chin].mean() < skin_plain[chin].mean() - 0.02
    # styles go into a .glb only, and are checked by argparse
    ply = tmp_path / "x.ply"
    assert main(["animate", "reference:male", "--hair", "short", "--out", str(ply)]) == 2
    assert "needs --out FILE.glb" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["animate", "reference:male", "--beard", "mohawk", "--out", str(groomed)])
    assert not ply.exists()


@pytest.mark.slow
def test_animate_takes_the_case_appearance(tmp_path: Path, head_male, capsys) -> None:
    from workbench.io.case_file import save_case
    from workbench.io.template_pack import export_template
    from workbench.model.case import Case

    folder = tmp_path / "recon"
    export_template(head_male, folder / "head", frame="the skull file's frame, mm")
    kept = Appearance(tone="mst8", iris="green", grooming={"moustache": "full", "brows": "thin"})
    save_case(Case(appearance=kept), folder / "case.fcase")
    out = tmp_path / "case.glb"
    assert main(["animate", str(folder), "--targets", "au1", "--out", str(out)]) == 0
    assert "brows thin, moustache full: artistic additions" in capsys.readouterr().out
    gltf, meshes = _nodes(out)
    assert {"brows", "moustache"} <= set(meshes)
    eye = next(m for m in gltf.materials if m.name.startswith("eye_"))
    assert eye.name == "eye_green"  # the case's iris
    # an option changes one choice: no moustache, hair added
    again = tmp_path / "changed.glb"
    args = ["--moustache", "none", "--hair", "buzz", "--out", str(again)]
    assert main(["animate", str(folder), "--targets", "au1", *args]) == 0
    _, meshes = _nodes(again)
    assert {"brows", "hair"} <= set(meshes) and "moustache" not in meshes


@pytest.mark.slow
def test_track_glb_with_brows(tmp_path: Path, head_male, capsys) -> None:
    track = tmp_path / "raise.json"
    keys = [{"t": 0.0, "expression": "neutral"}, {"t": 0.2, "expression": "au1"}]
    track.write_text(json.dumps({"fps": 30, "keys": keys}), "utf-8")
    out = tmp_path / "clip.glb"
    args = ["animate", "reference:male", "--track", str(track), "--brows", "straight"]
    assert main([*args, "--out", str(out)]) == 0
    assert "brows straight: artistic additions" in capsys.readouterr().out
    gltf, meshes = _nodes(out)
    assert meshes["brows"].extras["targetNames"] == meshes["skin"].extras["targetNames"]
    (clip,) = gltf.animations
    brows_node = next(i for i, n in enumerate(gltf.nodes) if n.name == "brows")
    assert brows_node in {c.target.node for c in clip.channels}  # the clip drives them too
