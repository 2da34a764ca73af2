"""The checks behind the corpus, called directly (what scripts and the window get); mm.

Values that can only be judged after a fit (the face's size against the
skull's) are tested on small synthetic meshes instead of a full reconstruction.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from badinput._files import skull_mesh, sphere
from workbench.cli.main import main
from workbench.core import limits
from workbench.core.errors import InputError
from workbench.core.landmarks import LandmarkSet
from workbench.core.mesh import Mesh
from workbench.io.mesh_formats import ply
from workbench.io.meshes import read_mesh
from workbench.io.volumes import read_volume
from workbench.model.reconstruction_setup import MAX_DEPTH_MM, DowelSettings, parse_build
from workbench.services.case import input_checks
from workbench.services.reconstruction import fit_checks


def test_one_set_of_bounds() -> None:
    # the override bound of the case settings is the soft-tissue bound of core.limits
    assert MAX_DEPTH_MM == limits.MAX_TISSUE_DEPTH_MM == 60.0
    with pytest.raises(InputError, match="60"):
        DowelSettings(overrides={"g": 61.0})
    assert DowelSettings(overrides={"g": 60.0}).overrides["g"] == 60.0
    assert parse_build("-4") == -4.0
    for k in (99, -1e9, "4.5 SD"):
        with pytest.raises(InputError, match="4 SD"):
            parse_build(k)


def test_range_and_count_checks_name_the_option() -> None:
    assert limits.check_range(5, "--x", 0, 10) == 5.0
    with pytest.raises(InputError, match=r"--x: 0 is out of range: must be above 0"):
        limits.check_range(0, "--x", 0, 10, low_open=True)
    with pytest.raises(InputError, match="finite"):
        limits.check_range(float("nan"), "--x", 0, 10)
    assert limits.check_count(3.0, "--n", 0, 5) == 3
    with pytest.raises(InputError, match="whole number"):
        limits.check_count(2.5, "--n", 0, 5)
    with pytest.raises(InputError, match="--n: 9 is out of range: must be 0-5"):
        limits.check_count(9, "--n", 0, 5)


def test_face_must_fit_the_skull() -> None:
    skull = skull_mesh()  # 150 x 180 x 200 mm
    head = Mesh(skull.vertices * 1.1, skull.faces)
    fit_checks.check_face_fits_skull(head, skull)  # plausible: no error
    # a cut vault (half-height skull) still carries a whole reference head
    cut = Mesh(skull.vertices * np.array([1.0, 0.5, 1.0]), skull.faces)
    fit_checks.check_face_fits_skull(head, cut)
    flat_face = Mesh(skull.vertices * np.array([1.1, 1.1, 0.145]), skull.faces)  # 29 mm deep
    with pytest.raises(InputError, match=r"29\.0 mm against a skull of 150\.0 x 180\.0"):
        fit_checks.check_face_fits_skull(flat_face, skull)
    huge = Mesh(skull.vertices * 3.0, skull.faces)
    with pytest.raises(InputError, match="not a plausible face"):
        fit_checks.check_face_fits_skull(huge, skull)


def test_fit_settings_are_checked_before_the_fit(tmp_path: Path) -> None:
    fit_checks.check_fit_settings(DowelSettings(), ensemble=20)
    with pytest.raises(InputError, match="--ensemble: 501"):
        fit_checks.check_fit_settings(DowelSettings(), ensemble=501)
    with pytest.raises(InputError, match="--rule: unknown prediction rule"):
        fit_checks.check_fit_settings(DowelSettings(), rules=("nope",))
    table = tmp_path / "deep.csv"
    table.write_text("landmark_code,group,mean_mm,sd_mm,source\ng,adult,75,2,t\n", encoding="utf-8")
    with pytest.raises(InputError, match=r"deep\.csv: line 2: mean_mm 75 mm is implausible"):
        fit_checks.check_fit_settings(DowelSettings(table=str(table)))


def test_landmarks_off_the_skull_are_counted() -> None:
    skull = skull_mesh()
    centre = skull.vertices.mean(axis=0)
    on = {"g": skull.vertices[0], "n": skull.vertices[5], "pr": skull.vertices[9]}
    lms = LandmarkSet.from_points("skull", on)
    input_checks.check_landmarks_on_skull(skull, lms, "lm.csv")
    off = LandmarkSet.from_points(
        "skull", {c: p + 40.0 * (p - centre) / np.linalg.norm(p - centre) for c, p in on.items()}
    )
    with pytest.raises(
        InputError,
        match=r"lm\.csv: 3 of 3 skull landmarks are more than 10 mm "
        r"from the skull surface \(median 40\.0 mm",
    ):
        input_checks.check_landmarks_on_skull(skull, off, "lm.csv")


def test_skull_checks_for_scripts() -> None:
    skull = skull_mesh()
    input_checks.check_skull_mesh(skull, "s.ply")
    with pytest.raises(InputError, match=r"s\.ply: the skull is 15 x 18 x 20 mm after --units x"):
        input_checks.check_skull_mesh(skull.scaled(0.1), "s.ply", units_note="--units x")
    with pytest.raises(InputError, match="has only 8 triangles"):
        input_checks.check_skull_mesh(sphere(0).scaled(90.0), "s.ply")


def test_mesh_info_prints_valid_json_for_a_damaged_mesh(
    bad_files: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["mesh", "info", str(bad_files["nan_skull"])]) == 0
    data = json.loads(capsys.readouterr().out)
    json.dumps(data, allow_nan=False)  # no NaN anywhere: strict JSON
    assert data["validation"]["nonfinite_vertices"] == 3
    assert data["area_mm2"] is None
    assert any("NaN" in p for p in data["validation"]["problems"])


def test_readers_refuse_what_the_cli_refuses(bad_files: dict[str, Path]) -> None:
    with pytest.raises(InputError, match=r"nan_skull\.ply: 3 vertices of 1026 have NaN"):
        read_mesh(bad_files["nan_skull"])
    assert read_mesh(bad_files["nan_skull"], allow_nonfinite=True).mesh.n_vertices == 1026
    with pytest.raises(InputError, match="not both"):
        read_mesh(bad_files["skull"], units="cm", scale=10.0)
    with pytest.raises(InputError, match=r"ct_voxel0\.nii: the voxel size in the header is 0"):
        read_volume(bad_files["ct_voxel0"])
    with pytest.raises(InputError, match="27 voxels"):
        read_volume(bad_files["ct_nan_voxels"])
    assert read_volume(bad_files["ct_good"]).spacing_mm.tolist() == [8.0, 8.0, 8.0]


def test_face_ply_header_names_the_file_units(tmp_path: Path) -> None:
    from workbench.services.reconstruction.job import JobResult, JobSettings

    header = ply.encode(np.zeros((3, 3)), np.array([[0, 1, 2]]), units="cm")
    assert b"comment units: cm\n" in header and b"units: mm" not in header
    assert b"comment units: mm\n" in ply.encode(np.zeros((3, 3)), np.array([[0, 1, 2]]))
    job = JobResult(*([None] * 9))
    assert replace(job, settings=JobSettings(units="cm")).file_units_label == "cm"
    assert (
        replace(job, settings=JobSettings(scale=15.0)).file_units_label
        == "file units (1 unit = 15 mm)"
    )
    assert replace(job, settings=JobSettings()).file_units_label == "mm"
