"""``workbench compare RECON TRUTH`` end to end (issue 4, "Validation")."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from workbench.cli.main import main
from workbench.core.headgen.skin import build_skin
from workbench.core.mesh import Mesh
from workbench.core.normals import vertex_normals
from workbench.io.meshes import write_mesh
from workbench.io.template_pack import export_template


@pytest.fixture(scope="module")
def meshes(tmp_path_factory: pytest.TempPathFactory, head_male) -> dict[str, Path]:
    """The male template skin as reconstruction; truths 3 mm outside it; a remeshed copy."""
    folder = tmp_path_factory.mktemp("compare")
    skin = build_skin("male")
    thick = skin.mesh.with_vertices(skin.mesh.vertices + 3.0 * vertex_normals(skin.mesh))
    # a reconstruction that is not on the template's topology (a few triangles gone)
    other = Mesh(skin.mesh.vertices, skin.mesh.faces[10:])
    paths = {
        "recon": folder / "face.ply",
        "truth": folder / "truth.ply",
        "truth_cm": folder / "truth_cm.obj",
        "other": folder / "other.ply",
    }
    write_mesh(paths["recon"], skin.mesh)
    write_mesh(paths["truth"], thick)
    write_mesh(paths["truth_cm"], thick.scaled(0.1))
    write_mesh(paths["other"], other)
    # a template pack as `workbench template export` writes it
    paths["pack"] = folder / "pack"
    export_template(head_male, paths["pack"])
    return paths


@pytest.mark.render
def test_compare_prints_figures_and_writes_heatmap(
    meshes, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from PIL import Image

    out = tmp_path / "validation"
    assert (
        main(
            [
                "compare",
                str(meshes["recon"]),
                str(meshes["truth"]),
                "--out",
                str(out),
                "--clim",
                "4",
            ]
        )
        == 0
    )
    data = json.loads(capsys.readouterr().out)
    assert data == json.loads((out / "compare.json").read_text())
    fig = data["figures"]
    assert fig["signed_mean_mm"] == pytest.approx(-3.0, abs=0.35)  # reconstruction too thin
    assert fig["pct_within_5mm"] == 100.0 and fig["pct_within_2_5mm"] < 12.0
    assert fig["coverage"] > 0.98
    assert set(data["regions"]) == {"forehead", "orbits", "nose", "cheeks", "mouth", "chin"}
    assert data["regions"]["forehead"]["signed_mean_mm"] == pytest.approx(-3.0, abs=0.05)
    assert "built-in reference head (male)" in data["template"]
    image = np.asarray(Image.open(out / "heatmap.png").convert("RGB")).astype(int)
    assert image.std() > 20
    assert (image[..., 2] > image[..., 0] + 60).mean() > 0.01  # blue: reconstruction inside


def test_other_topology_needs_region_all(meshes, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["compare", str(meshes["other"]), str(meshes["truth"]), "--region", "face"]) == 2
    err = capsys.readouterr().err
    assert "other.ply" in err and "topology" in err and "--region all" in err
    assert main(["compare", str(meshes["other"]), str(meshes["truth"]), "--region", "all"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["template"] is None and data["regions"] == {}
    assert data["figures"]["n_vertices"] > 4000
    assert main(["compare", str(meshes["recon"]), str(meshes["truth"]), "--region", "ears"]) == 2
    assert "unknown region 'ears'" in capsys.readouterr().err


def test_truth_units_and_template_pack(meshes, capsys: pytest.CaptureFixture[str]) -> None:
    # a truth in cm is refused until its units are given
    assert main(["compare", str(meshes["recon"]), str(meshes["truth_cm"])]) == 2
    assert "truth_cm.obj" in capsys.readouterr().err
    assert (
        main(
            [
                "compare",
                str(meshes["recon"]),
                str(meshes["truth_cm"]),
                "--truth-units",
                "cm",
                "--template",
                str(meshes["pack"]),
                "--region",
                "nose",
            ]
        )
        == 0
    )
    data = json.loads(capsys.readouterr().out)
    assert "template pack" in data["template"] and list(data["regions"]) == ["nose"]
    assert data["regions"]["nose"]["signed_mean_mm"] == pytest.approx(-2.8, abs=0.3)
    # a folder that is not a pack
    assert (
        main(
            [
                "compare",
                str(meshes["recon"]),
                str(meshes["truth"]),
                "--template",
                str(meshes["recon"].parent),
            ]
        )
        == 2
    )
    assert "not a template pack" in capsys.readouterr().err


def test_a_truth_made_from_a_credited_ct_carries_its_credit(
    meshes, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A skin extracted from the Visible Human CT (PLY ``comment credit: ...``) is credited."""
    from workbench.io.mesh_formats import ply
    from workbench.io.meshes import read_mesh
    from workbench.io.samples import credit_comment

    credit = "Courtesy of the U.S. National Library of Medicine."
    truth = tmp_path / "vhp_skin.ply"
    ply.write(truth, read_mesh(meshes["truth"]).mesh, comments=[credit_comment(credit)])
    assert main(["compare", str(meshes["recon"]), str(truth)]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["credits"] == [credit]
    assert main(["compare", str(meshes["recon"]), str(meshes["truth"])]) == 0
    assert "credits" not in json.loads(capsys.readouterr().out)
