"""``workbench age``: packs, report.json and sequence.glb written; evidence rules kept."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from workbench.cli.main import main


def test_age_sequence_writes_packs_report_and_glb(tmp_path: Path, head_male, capsys) -> None:
    import pygltflib

    from workbench.io.template_pack import load_template_pack

    out = tmp_path / "aged"
    argv = ["age", "reference:male", "--sex", "male", "--from", "18", "--ages", "3,8"]
    assert main([*argv, "--out", str(out), "--no-pdf"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert [a["to_age"] for a in report["ages"]] == [3.0, 8.0]
    three = report["ages"][0]
    assert three["figures"]["hard_residual_mm"]["max"] < 2.0
    normed = [m for m in three["measurements"] if m["constraint"] == "norms"]
    assert normed and all(abs(m["z_after"] - m["z_before"]) < 0.1 for m in normed)
    assert {"norm_from", "norm_to", "residual_mm"} <= set(normed[0])
    for age in ("3", "8"):
        head = load_template_pack(out / f"head_{age}y")
        assert head.skin.n_vertices == head_male.skin.n_vertices
        assert f"/age/18-{age}" in head.template_id
    # the growth sequence: one morph target per age and a clip through them
    glb = pygltflib.GLTF2().load(str(out / "sequence.glb"))
    skin = next(m for m in glb.meshes if m.name == "skin")
    assert skin.extras["targetNames"] == ["age_3y", "age_8y"]
    assert len(skin.primitives[0].targets) == 2
    assert glb.animations and glb.animations[0].name == "growth"
    assert {c.target.path for c in glb.animations[0].channels} == {"weights"}
    # a rendered frame at weight 1 is the aged skin (metres in glTF)
    blob = glb.binary_blob()
    acc = glb.accessors[skin.primitives[0].targets[0]["POSITION"]]
    view = glb.bufferViews[acc.bufferView]
    start = (view.byteOffset or 0) + (acc.byteOffset or 0)
    delta = np.frombuffer(blob[start : start + acc.count * 12], np.float32).reshape(-1, 3)
    aged = load_template_pack(out / "head_3y").skin.vertices
    frame = head_male.skin.vertices + delta.astype(float) * 1000.0
    assert np.abs(frame - aged).max() < 0.01
    # an existing output is never replaced without --force
    capsys.readouterr()
    assert main([*argv, "--out", str(out), "--no-pdf"]) == 2
    assert "--force" in capsys.readouterr().err


def test_age_a_template_pack_and_back(tmp_path: Path, head_male) -> None:
    from workbench.io.template_pack import load_template_pack

    one = tmp_path / "child"
    assert (
        main(
            [
                "age",
                "reference:male",
                "--sex",
                "male",
                "--from",
                "18",
                "--to",
                "8",
                "--out",
                str(one),
                "--no-pdf",
            ]
        )
        == 0
    )
    back = tmp_path / "grown"
    assert (
        main(
            [
                "age",
                str(one / "head"),
                "--sex",
                "male",
                "--from",
                "8",
                "--to",
                "18",
                "--out",
                str(back),
                "--no-pdf",
            ]
        )
        == 0
    )
    grown = load_template_pack(back / "head")
    d = np.linalg.norm(grown.skin.vertices - head_male.skin.vertices, axis=1)
    assert np.median(d) < 1.0
    prov = json.loads((back / "head" / "template.json").read_text())["provenance"]
    assert prov["age_change"]["from_age"] == 8 and prov["age_change"]["to_age"] == 18


@pytest.mark.parametrize(
    "extra,message",
    [
        (["--to", "8", "--arc-increase", "0.5"], "at most 10 %"),
        (["--ages", "3,3"], "names an age twice"),
    ],
)
def test_age_bad_requests(tmp_path: Path, head_male, capsys, extra, message) -> None:
    argv = ["age", "reference:male", "--sex", "male", "--from", "18", *extra]
    assert main([*argv, "--out", str(tmp_path / "x"), "--no-pdf"]) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_age_the_other_sexs_norms_only_on_purpose(tmp_path: Path, head_male, capsys) -> None:
    """A male head with the female norms: refused, naming both; with the flag, a warning
    on stderr and in report.json."""
    argv = ["age", "reference:male", "--sex", "female", "--from", "18", "--to", "12"]
    assert main([*argv, "--out", str(tmp_path / "x"), "--no-pdf"]) == 2
    err = capsys.readouterr().err
    assert "reference:male" in err and "male head" in err and "--sex female" in err
    assert "--allow-sex-mismatch" in err and not (tmp_path / "x").exists()
    out = tmp_path / "y"
    assert main([*argv, "--allow-sex-mismatch", "--out", str(out), "--no-pdf"]) == 0
    assert "female norms" in capsys.readouterr().err
    report = json.loads((out / "report.json").read_text())
    assert any("--allow-sex-mismatch" in w for w in report["ages"][0]["warnings"])
