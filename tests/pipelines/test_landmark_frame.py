"""The landmark files and the report state one frame and give the same numbers (issue 33 item 5).

Real data: the built-in female reference skull and its skull landmarks,
turned from the head frame into RAS and written as a mesh tagged ``SPACE=LPS`` (3D Slicer's default, and what
``workbench mesh-from-ct`` writes for a DICOM or NRRD CT) and an LPS
``.mrk.json``.  After one reconstruction (no pictures, the meshes again as
OBJ so the ``.fcsv`` is written too):

* ``skull_landmarks.mrk.json`` and ``.fcsv`` name :data:`OUTPUT_SYSTEM`
  (RAS) in their headers, the ``.mrk.json`` with :data:`OUTPUT_FRAME` in words;
* ``report.json`` names the same frame, and the PDF's landmark section says it;
* each landmark has the same position (mm) in ``report.json`` and both files;
* the positions are RAS indeed: on the skull as 3D Slicer lays the LPS file
  (x and y of its numbers negated), the right porion at larger x than the
  left, the nasion at larger y (forward) than the porions.
"""

from __future__ import annotations

import json

import numpy as np
import pypdf
import pytest

from workbench.core.frame import RAS_TO_HEAD, apply_transform
from workbench.core.mesh import Mesh
from workbench.core.spatial import MeshIndex
from workbench.io.markups import (
    OUTPUT_FRAME,
    OUTPUT_FRAME_NAME,
    OUTPUT_SYSTEM,
    read_fcsv,
    write_mrk_json,
)
from workbench.io.meshes import LPS_TO_RAS, write_mesh
from workbench.pipelines.reconstruct import write_reconstruction
from workbench.reporting.report import read_report_json
from workbench.services.reconstruction.job import JobSettings, run_reconstruction
from workbench.services.templates.reference_parts import skull_surface


@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory, head_female) -> dict:
    folder = tmp_path_factory.mktemp("frame")
    head_to_ras = np.linalg.inv(RAS_TO_HEAD)  # the reference lies in the head frame
    skull = skull_surface(head_female)
    skull = Mesh(apply_transform(head_to_ras, skull.vertices), skull.faces)  # RAS numbers
    lps = Mesh(skull.vertices * LPS_TO_RAS, skull.faces)  # the same skull in LPS numbers
    skull_path = write_mesh(folder / "skull_lps.ply", lps, space="LPS")
    landmarks = folder / "skull.mrk.json"
    lms = head_female.skull_landmarks.transformed(head_to_ras)
    write_mrk_json(landmarks, lms, coordinate_system="LPS")
    result = run_reconstruction(
        skull_path, JobSettings(landmarks=landmarks, sex="female", guides="none")
    )
    out = folder / "out"
    out.mkdir()
    files = write_reconstruction(result, out, pictures=False, formats=("obj",))
    return {"skull": skull, "out": out, "files": files}


def test_the_files_and_the_report_name_one_frame(written) -> None:
    out = written["out"]
    assert OUTPUT_SYSTEM == "RAS"
    markup = json.loads((out / "skull_landmarks.mrk.json").read_text())["markups"][0]
    assert markup["coordinateSystem"] == OUTPUT_SYSTEM and markup["coordinateUnits"] == "mm"
    assert markup["workbench"]["frame"] == OUTPUT_FRAME
    header = (out / "skull_landmarks.fcsv").read_text().splitlines()[:3]
    assert f"# CoordinateSystem = {OUTPUT_SYSTEM}" in header
    report = read_report_json(out / "report.json")
    assert report["frame"].startswith(OUTPUT_FRAME)
    text = " ".join(page.extract_text() for page in pypdf.PdfReader(str(out / "report.pdf")).pages)
    words = " ".join(text.split())  # the PDF wraps lines
    assert "skull_landmarks.mrk.json" in words
    assert f"all in one frame: {OUTPUT_FRAME_NAME}" in words


def test_report_and_files_give_the_same_ras_positions(written) -> None:
    out = written["out"]
    report = read_report_json(out / "report.json")
    in_report = {
        lm["code"]: np.array(lm["position_mm"], float)
        for lm in report["landmarks"]
        if lm.get("position_mm") is not None and lm["code"] in {"n", "pr", "po_l", "po_r", "or_l"}
    }
    assert len(in_report) == 5
    markup = json.loads((out / "skull_landmarks.mrk.json").read_text())["markups"][0]
    in_mrk = {
        cp["label"]: np.array(cp["position"], float)
        for cp in markup["controlPoints"]
        if cp["positionStatus"] == "defined"
    }
    in_fcsv = read_fcsv(out / "skull_landmarks.fcsv", "skull").landmarks.as_dict()
    for code, position in in_report.items():
        np.testing.assert_allclose(in_mrk[code], position, atol=1e-9, err_msg=code)
        np.testing.assert_allclose(in_fcsv[code], position, atol=1e-9, err_msg=code)
    points = np.array(list(in_report.values()))
    on_ras = MeshIndex(written["skull"]).closest_points(points).distances
    assert on_ras.max() < 1.0, on_ras  # on the skull where Slicer shows it
    # RAS, not the file's own LPS numbers: x to the subject's right, y forward
    n, po_l, po_r = in_report["n"], in_report["po_l"], in_report["po_r"]
    assert po_r[0] > po_l[0] + 50.0 and n[1] > (po_l[1] + po_r[1]) / 2 + 50.0
