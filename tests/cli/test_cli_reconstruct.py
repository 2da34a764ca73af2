"""``workbench reconstruct`` and ``workbench landmarks suggest`` end to end."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from workbench.cli.main import main
from workbench.io.case_file import load_case
from workbench.io.markups import read_landmarks, write_mrk_json
from workbench.io.meshes import read_mesh, write_mesh
from workbench.model.evidence import file_sha256 as sha256_file
from workbench.reporting.report import read_report_json, validate_report
from workbench.services.templates.reference_parts import skull_surface

HEADSQ_FLAGS = ["--anterior", "0,-1,0", "--superior", "0,0,-1", "--left", "1,0,0"]


@pytest.fixture(scope="module")
def inputs(tmp_path_factory: pytest.TempPathFactory, head_female) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("recon-inputs")
    paths = {
        "skull": folder / "skull.ply",
        "landmarks": folder / "skull.mrk.json",
        "truth": folder / "truth_skin.ply",
    }
    write_mesh(paths["skull"], skull_surface(head_female))
    write_mrk_json(paths["landmarks"], head_female.skull_landmarks)
    write_mesh(paths["truth"], head_female.skin)
    return paths


@pytest.mark.render
def test_reconstruct_writes_face_head_case_and_report(inputs, tmp_path, head_male, capsys):
    out = tmp_path / "recon"
    code = main(
        [
            "reconstruct",
            str(inputs["skull"]),
            "--landmarks",
            str(inputs["landmarks"]),
            "--sex",
            "male",
            "--ensemble",
            "3",
            "--truth",
            str(inputs["truth"]),
            "--exclude",
            "ecm2s",
            "--override",
            "g=6.5",
            "--out",
            str(out),
        ]
    )
    assert code == 0, capsys.readouterr().err
    face = read_mesh(out / "face.ply", units="mm").mesh
    assert face.n_vertices == head_male.skin.n_vertices
    assert (out / "head" / "template.json").is_file() and (out / "head" / "muscles.json").is_file()
    pack = json.loads((out / "head" / "template.json").read_text())
    assert pack["frame"].startswith("the skull file's frame") and pack["units"] == "mm"
    report = read_report_json(out / "report.json")
    validate_report(report)
    assert report["template"]["content_hash"] == head_male.content_hash
    assert report["validation"]["pct_within_2_5mm"] > 75.0  # ~83 % with the exclusions above
    assert report["ensemble"]["n"] == 3
    rows = {r["code"]: r for r in report["landmarks"]}
    assert rows["g"]["source"] == "override" and rows["g"]["depth_mm"] == 6.5
    assert rows["ecm2s_l"]["source"] == "excluded" and rows["ecm2s_l"]["depth_mm"] is None
    skull_sha = sha256_file(inputs["skull"])
    assert any(i["sha256"] == skull_sha and i["role"] == "skull" for i in report["inputs"])
    assert any(i["role"] == "table" for i in report["inputs"])
    assert all((out / p).is_file() for p in report["pictures"].values())
    from pypdf import PdfReader

    text = "".join(page.extract_text() for page in PdfReader(out / "report.pdf").pages)
    assert report["case_id"] in text and "Hona" in text and skull_sha in text.replace("\n", "")
    loaded = load_case(out / "case.fcase")
    assert loaded.case.parameters["template_hash"] == head_male.content_hash
    assert loaded.case.dowels.excluded == ("ecm2s",)
    assert dict(loaded.case.dowels.overrides) == {"g": 6.5} and loaded.case.dowels.sex == "male"
    assert loaded.case.guides is None  # computed from the skull, not stored
    assert report["parameters"]["dowels"]["excluded"] == ["ecm2s"]
    ops = [r["command"] for r in loaded.audit_records if r["action"] == "do"]
    assert "SetDowelSettings" in ops and "SetParameter" in ops


def test_suggest_then_reconstruct_headsq_bone(headsq_surfaces, tmp_path, capsys):
    bone = write_mesh(tmp_path / "bone.ply", headsq_surfaces["bone"])
    lm_file = tmp_path / "suggested.mrk.json"
    assert main(["landmarks", "suggest", str(bone), *HEADSQ_FLAGS, "--out", str(lm_file)]) == 0
    printed = capsys.readouterr().out
    assert '"absent"' in printed
    lms = read_landmarks(lm_file, "skull", allow_undefined=True).landmarks
    assert lms["v"].status == "absent"
    assert sum(lm.status == "suggested" for lm in lms) >= 35
    out = tmp_path / "recon"
    assert (
        main(
            [
                "reconstruct",
                str(bone),
                "--landmarks",
                str(lm_file),
                "--no-pictures",
                "--truth",
                str(write_mesh(tmp_path / "skin.ply", headsq_surfaces["skin"])),
                "--out",
                str(out),
            ]
        )
        == 0
    )
    report = read_report_json(out / "report.json")
    # the suggested landmarks' left/right labels tell the mirrored file (the shape cannot)
    assert "mirrored" in report["frame"]
    assert report["validation"]["n"] > 1000
    assert report["validation"]["pct_within_2_5mm"] > 60.0
    assert report["registration"]["parts"][1]["present"]


def test_reconstruct_refuses_a_skull_in_metres(inputs, tmp_path, capsys):
    mesh = read_mesh(inputs["skull"], units="mm").mesh
    metres = write_mesh(tmp_path / "skull_m.ply", mesh.scaled(0.001))
    assert main(["reconstruct", str(metres), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "skull_m.ply" in err and ("metre" in err or "units" in err)


def test_face_is_written_in_the_skull_files_units(inputs, tmp_path):
    mesh = read_mesh(inputs["skull"], units="mm").mesh
    cm = write_mesh(tmp_path / "skull_cm.ply", mesh.scaled(0.1))
    out = tmp_path / "o"
    assert (
        main(
            [
                "reconstruct",
                str(cm),
                "--units",
                "cm",
                "--no-pictures",
                "--guides",
                "none",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    face_cm = read_mesh(out / "face.ply", units="cm").mesh  # cm numbers, read back as mm
    face_mm = read_mesh(out / "face_mm.ply", units="mm").mesh
    np.testing.assert_allclose(face_cm.vertices, face_mm.vertices, atol=1e-6)
    skull_in_file = mesh.scaled(0.1)
    lo, hi = skull_in_file.bounds
    raw = read_mesh(out / "face.ply", scale=1.0).mesh.bounds
    assert raw[1][1] - raw[0][1] < 2 * (hi[1] - lo[1]) + 5  # the same scale as the skull file


def test_a_published_rule_replaces_the_classic_guide(inputs, tmp_path, capsys):
    out = tmp_path / "rynn"
    assert (
        main(
            [
                "reconstruct",
                str(inputs["skull"]),
                "--landmarks",
                str(inputs["landmarks"]),
                "--rule",
                "no_such_rule",
                "--no-pictures",
                "--out",
                str(out),
            ]
        )
        == 2
    )
    assert "no_such_rule" in capsys.readouterr().err
    assert (
        main(
            [
                "reconstruct",
                str(inputs["skull"]),
                "--landmarks",
                str(inputs["landmarks"]),
                "--rule",
                "nose_rynn2010_prn",
                "--no-pictures",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    report = read_report_json(out / "report.json")
    guides = {g["id"]: g for g in report["guides"]}
    assert guides["nose_tip"]["rule_id"] == "nose_rynn2010_prn"
    assert "Rynn" in guides["nose_tip"]["citation"]
    # the nose width keeps its default rule (guide_defaults.csv), not Kähler's
    assert guides["nose_width_l"]["rule_id"] == "nose_purkait2024_alar_width"
    assert guides["lip_upper_margin"]["rule_id"] == "kaehler_lip_upper"


def test_a_library_of_reference_packs_gives_their_median_face(inputs, tmp_path, head_male):
    from workbench.io.template_pack import export_template

    a = export_template(head_male, tmp_path / "a")[0].parent
    b = export_template(head_male, tmp_path / "b")[0].parent
    out = tmp_path / "lib"
    assert (
        main(
            [
                "reconstruct",
                str(inputs["skull"]),
                "--landmarks",
                str(inputs["landmarks"]),
                "--template",
                str(a),
                "--template",
                str(b),
                "--tissue",
                "reference",
                "--guides",
                "none",
                "--no-pictures",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    report = read_report_json(out / "report.json")
    assert [h["path"] for h in report["references"]["heads"]] == [str(a), str(b)]
    # two identical references: the median is either fit, and they agree
    assert report["references"]["spread_between_mm"]["p90"] < 1e-6
    assert report["tissue"]["model"] == "reference"


def test_a_doubted_registration_exits_3_after_writing(inputs, tmp_path, monkeypatch, capsys):
    """A self-check asking for a check: the outputs are written, CHECK comes first on
    stdout, one line on stderr, exit status 3 (not a plain success); confident: 0."""
    import workbench.cli.reconstruct_cmd as cmd

    reason = "the symmetry plane lies 14° off the midline (the orientation may be wrong)"
    check = {"outcome": "check", "reasons": [reason]}
    seen: list[Path] = []

    def fake_execute(skull, settings, out, **_kw):
        seen.append(out)
        cmd.print_self_check(check)
        return {"self_check": dict(check)}

    monkeypatch.setattr(cmd, "execute", fake_execute)
    args = ["reconstruct", str(inputs["skull"]), "--out", str(tmp_path / "r")]
    assert main(args) == 3
    captured = capsys.readouterr()
    assert captured.out.splitlines()[0] == f"CHECK: {reason}"
    assert "exit 3" in captured.err and reason in captured.err
    check["outcome"] = "confident"
    assert main(args) == 0
    assert "exit 3" not in capsys.readouterr().err
    assert seen == [tmp_path / "r"] * 2
