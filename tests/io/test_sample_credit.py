"""The NLM credit travels from the Visible Human CTs to the meshes made from them.

Real data only: the VHP NIfTI files in ``../shared/data`` (the 2 mm copy is
the small fixture), found by SHA-256 wherever they live; PLY header comments
carry the credit into mesh files and back.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from workbench.cli.main import main
from workbench.core.errors import InputError
from workbench.core.mesh import Mesh
from workbench.io import samples
from workbench.io.mesh_formats import ply
from workbench.io.meshes import read_mesh, write_mesh
from workbench.services.ct.ct_mesh import mesh_from_ct

NLM_CREDIT = "Courtesy of the U.S. National Library of Medicine"
FROZEN_NOTE = "This copy is a frozen snapshot and may not reflect the most current"


@pytest.fixture(scope="module")
def vhf_2mm(shared_data: Path) -> Path:
    path = shared_data / "vhp_female_head_ct" / "vhf_head_ct_2mm.nii.gz"
    if not path.is_file():
        pytest.fail(f"real test data not found: {path}", pytrace=False)
    return path


@pytest.fixture(scope="module")
def credit() -> str:
    value = samples.registry()["vhp_female"].credit
    assert value is not None
    return value


def _triangle() -> Mesh:
    return Mesh(
        np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [0.0, 10.0, 0.0]]), np.array([[0, 1, 2]])
    )


# ------------------------------------------------------------------ credit_for
def test_credit_for_the_vhp_nifti_files(shared_data: Path, credit: str, vhf_2mm: Path) -> None:
    female = shared_data / "vhp_female_head_ct"
    male = shared_data / "vhp_male_head_ct"
    assert samples.credit_for(female / "vhf_head_ct_1mm.nii.gz") == credit
    assert samples.credit_for(vhf_2mm) == credit  # an extra file of the same sample
    assert (
        samples.credit_for(male / "vhm_head_ct_1mm.nii.gz") == samples.registry()["vhp_male"].credit
    )
    assert NLM_CREDIT in credit and FROZEN_NOTE in credit


def test_credit_for_other_files_is_none(
    shared_data: Path, headsq_nhdr: Path, tmp_path: Path
) -> None:
    assert samples.credit_for(headsq_nhdr) is None  # a sample without a credit
    assert samples.credit_for(shared_data / "vhp_female_head_ct" / "PROVENANCE.md") is None
    assert samples.credit_for(tmp_path / "missing.nii.gz") is None
    assert samples.credit_for(tmp_path) is None  # an unrelated folder


def test_credit_follows_the_content_not_the_name(
    tmp_path: Path, vhf_2mm: Path, credit: str
) -> None:
    renamed = tmp_path / "case_17.nii.gz"
    shutil.copyfile(vhf_2mm, renamed)
    assert samples.credit_for(renamed) == credit
    data = bytearray(renamed.read_bytes())
    data[100] ^= 0xFF  # one changed byte: not the registered file any more
    renamed.write_bytes(bytes(data))
    assert samples.credit_for(renamed) is None


def test_credit_for_a_dicom_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, credit: str
) -> None:
    monkeypatch.setenv("WORKBENCH_DATA_DIR", str(tmp_path / "cache"))
    series = tmp_path / "cache" / "vhp_female_dicom"
    series.mkdir(parents=True)
    # the sample's own series folder in the cache
    assert samples.credit_for(series) == credit
    # another folder: a slice with a registered name but other content does not count
    other = tmp_path / "elsewhere"
    other.mkdir()
    (other / "vhf.1501.dcm").write_bytes(b"not the VHP slice")
    assert samples.credit_for(other) is None


# ------------------------------------------------------------------ PLY header comments
@pytest.mark.parametrize("binary", [True, False])
def test_ply_comments_round_trip(tmp_path: Path, binary: bool) -> None:
    mesh = _triangle()
    target = ply.write(
        tmp_path / "t.ply", mesh, binary=binary, comments=["credit: Courtesy of X", "case: 17"]
    )
    parsed = ply.read(target, target.read_bytes())
    assert parsed.comments == [
        "units: mm",
        "SPACE=RAS",
        "written by forensic-workbench",
        "credit: Courtesy of X",
        "case: 17",
    ]
    assert ply.header_comments(target) == parsed.comments
    np.testing.assert_array_equal(parsed.vertices, mesh.vertices)
    np.testing.assert_array_equal(read_mesh(target).mesh.faces, mesh.faces)


def test_plain_ply_writing_is_unchanged(tmp_path: Path) -> None:
    mesh = _triangle()
    assert ply.encode(mesh.vertices, mesh.faces) == ply.encode(
        mesh.vertices, mesh.faces, comments=()
    )
    target = write_mesh(tmp_path / "plain.ply", mesh)
    assert ply.header_comments(target) == [
        "units: mm",
        "SPACE=RAS",
        "written by forensic-workbench",
    ]
    assert samples.credit_for_mesh_file(target) is None


def test_bad_comments_and_files(tmp_path: Path) -> None:
    mesh = _triangle()
    for bad in ("two\nlines", "caf\u00e9", "x end_header"):
        with pytest.raises(ValueError):
            ply.encode(mesh.vertices, mesh.faces, comments=[bad])
    junk = tmp_path / "junk.ply"
    junk.write_bytes(b"solid nothing\n")
    with pytest.raises(InputError, match="not a PLY file"):
        ply.header_comments(junk)
    assert samples.credit_for_mesh_file(junk) is None
    assert samples.credit_for_mesh_file(tmp_path / "missing.ply") is None
    stl = write_mesh(tmp_path / "t.stl", mesh)
    assert samples.credit_for_mesh_file(stl) is None
    with pytest.raises(InputError, match="folder does not exist"):
        ply.write(tmp_path / "no" / "t.ply", mesh, comments=["a"])


def test_credit_for_mesh_file_reads_the_credit_comment(tmp_path: Path, credit: str) -> None:
    target = ply.write(
        tmp_path / "bone.ply", _triangle(), comments=[samples.credit_comment(credit)]
    )
    assert samples.credit_for_mesh_file(target) == credit


# ------------------------------------------------------------------ mesh-from-ct
def test_mesh_from_ct_records_the_credit(vhf_2mm: Path, headsq_nhdr: Path, credit: str) -> None:
    result = mesh_from_ct(vhf_2mm, "bone", target_triangles=5000)
    assert result.credit == credit and result.to_dict()["credit"] == credit
    assert result.frame == "RAS"
    assert mesh_from_ct(headsq_nhdr, "bone", target_triangles=2000).credit is None


def test_cli_mesh_from_ct_writes_the_credit_into_the_ply(
    tmp_path: Path, vhf_2mm: Path, credit: str, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "vhf_bone.ply"
    report = tmp_path / "vhf_bone.json"
    assert (
        main(
            [
                "mesh-from-ct",
                str(vhf_2mm),
                "--tissue",
                "bone",
                "--target-triangles",
                "20000",
                "--out",
                str(out),
                "--report",
                str(report),
                "--quiet",
            ]
        )
        == 0
    )
    assert f"credit: {credit}" in capsys.readouterr().out  # shown even with --quiet
    assert f"credit: {credit}" in ply.header_comments(out)
    assert samples.credit_for_mesh_file(out) == credit
    assert json.loads(report.read_text())["credit"] == credit
    # the mesh itself reads as before: a skull-sized bone surface in mm
    mesh = read_mesh(out, kind="skull").mesh
    assert abs(mesh.n_faces - 20000) < 0.05 * 20000
    assert 120 < mesh.extent.max() < 260
    # a format without header comments gets the note instead
    stl = tmp_path / "vhf_bone.stl"
    assert (
        main(
            [
                "mesh-from-ct",
                str(vhf_2mm),
                "--tissue",
                "bone",
                "--target-triangles",
                "5000",
                "--out",
                str(stl),
                "--quiet",
            ]
        )
        == 0
    )
    printed = capsys.readouterr().out
    assert f"credit: {credit}" in printed and "no header comments" in printed


def test_cli_mesh_from_ct_without_credit_writes_a_plain_ply(
    tmp_path: Path, headsq_nhdr: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "headsq.ply"
    assert (
        main(
            [
                "mesh-from-ct",
                str(headsq_nhdr),
                "--tissue",
                "bone",
                "--target-triangles",
                "5000",
                "--out",
                str(out),
                "--quiet",
            ]
        )
        == 0
    )
    assert "credit" not in capsys.readouterr().out
    # headsq is an NRRD in LPS: the tag says so, so 3D Slicer lays the bone on the CT
    assert ply.header_comments(out) == ["units: mm", "SPACE=LPS", "written by forensic-workbench"]
