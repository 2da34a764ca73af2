"""``workbench template build`` end to end on the headsq CT, and the pack used by other commands."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from workbench.cli.main import main
from workbench.core.landmarks import LandmarkSet
from workbench.io.markups import write_mrk_json
from workbench.io.meshes import read_mesh, write_mesh
from workbench.io.template_pack import load_template_pack
from workbench.reporting.report import read_report_json
from workbench.services.landmarks.transfer import transfer_landmarks
from workbench.services.templates.reference_parts import skull_surface

HEADSQ_FLAGS = ["--anterior", "0,-1,0", "--superior", "0,0,-1", "--left", "1,0,0"]
SEEDS = ("po_l", "po_r", "or_l", "or_r", "n")


@pytest.fixture(scope="module")
def build(
    tmp_path_factory: pytest.TempPathFactory, headsq_surfaces, headsq_orientation, head_male
) -> dict:
    folder = tmp_path_factory.mktemp("cli-template-build")
    skin = write_mesh(folder / "skin.ply", headsq_surfaces["skin"])
    bone = write_mesh(folder / "bone.ply", headsq_surfaces["bone"])
    # a few skull landmarks "placed by hand" (here: taken from a suggestion)
    suggested = transfer_landmarks(
        headsq_surfaces["bone"],
        skull_surface(head_male),
        head_male.skull_landmarks,
        orientation=headsq_orientation,
    )
    seeds = LandmarkSet(
        "skull", tuple(suggested.landmarks[c].moved(suggested.landmarks[c].position) for c in SEEDS)
    )
    seed_file = folder / "seeds.mrk.json"
    write_mrk_json(seed_file, seeds)
    pack = folder / "pack"
    code = main(
        [
            "template",
            "build",
            "--skin",
            str(skin),
            "--skull",
            str(bone),
            *HEADSQ_FLAGS,
            "--landmarks-skull",
            str(seed_file),
            "--out",
            str(pack),
        ]
    )
    return {
        "code": code,
        "pack": pack,
        "skin": skin,
        "bone": bone,
        "seeds": seeds,
        "folder": folder,
    }


def test_build_writes_a_loadable_pack(build, head_male, capsys):
    assert build["code"] == 0
    pack = load_template_pack(build["pack"])
    assert pack.template_id.startswith(f"{head_male.template_id}/built/")
    roles = {i["role"] for i in pack.provenance["built_from"]}
    assert roles == {"skin", "skull", "skull_landmarks"}
    # the hand-placed points were kept: the pack's landmarks (carried on its
    # bone) lie close to them, in the CT's frame
    inv = np.linalg.inv(np.asarray(pack.provenance["input_to_head"]))
    back = pack.skull_landmarks.transformed(inv)
    d = np.linalg.norm(back.positions_of(SEEDS) - build["seeds"].positions_of(SEEDS), axis=1)
    assert d.max() < 4.0
    for name in ("skin.ply", "skull.ply", "mandible.ply", "skin.mrk.json", "muscles.json"):
        assert (build["pack"] / name).is_file()


def test_reconstruct_accepts_the_pack(build, tmp_path, capsys):
    pack = load_template_pack(build["pack"])
    inv = np.linalg.inv(np.asarray(pack.provenance["input_to_head"]))
    absent = set(pack.provenance["absent_landmarks"]["skull"])
    present = LandmarkSet(
        "skull", tuple(lm for lm in pack.skull_landmarks.transformed(inv) if lm.code not in absent)
    )
    lm_file = tmp_path / "skull_ct.mrk.json"
    write_mrk_json(lm_file, present)
    out = tmp_path / "recon"
    code = main(
        [
            "reconstruct",
            str(build["bone"]),
            "--template",
            str(build["pack"]),
            "--landmarks",
            str(lm_file),
            "--no-pictures",
            "--out",
            str(out),
        ]
    )
    assert code == 0, capsys.readouterr().err
    report = read_report_json(out / "report.json")
    assert report["template"]["content_hash"] == pack.content_hash
    face = read_mesh(out / "face.ply", units="mm").mesh
    assert face.n_vertices == pack.skin.n_vertices


def test_export_re_exports_a_pack(build, tmp_path):
    out = tmp_path / "again"
    assert main(["template", "export", "--template", str(build["pack"]), "--out", str(out)]) == 0
    info = json.loads((out / "template.json").read_text())
    assert info["content_hash"] == load_template_pack(build["pack"]).content_hash


def test_missing_or_unreadable_mesh_is_a_clear_error(build, tmp_path, capsys):
    out = tmp_path / "never"
    missing = tmp_path / "no_such_skin.ply"
    assert (
        main(
            [
                "template",
                "build",
                "--skin",
                str(missing),
                "--skull",
                str(build["bone"]),
                "--out",
                str(out),
            ]
        )
        == 2
    )
    assert "no_such_skin.ply" in capsys.readouterr().err
    broken = tmp_path / "broken_bone.ply"
    broken.write_text("this is not a mesh\n")
    assert (
        main(
            [
                "template",
                "build",
                "--skin",
                str(build["skin"]),
                "--skull",
                str(broken),
                "--out",
                str(out),
            ]
        )
        == 2
    )
    err = capsys.readouterr().err
    assert "broken_bone.ply" in err and "PLY" in err
    assert not Path(out).exists()
