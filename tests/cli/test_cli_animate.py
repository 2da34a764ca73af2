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
    from workbench.services.reconstruct import warp_head

    shift = np.array([10.0, 200.0, -35.0])
    export_template(
        warp_head(head_male, lambda p: np.asarray(p) + shift),
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
