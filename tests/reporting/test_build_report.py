"""The report's "Three builds" and "Uncertainty band" sections (``report["builds"]``).

A small report dict in the schema's layout with the ``builds`` entry of
:meth:`workbench.services.reconstruction.build_faces.BuildFaces.summary` (as
``build_report`` writes it) and stand-in PNGs of the pictures'
proportions (no rendering here).  The PDF is read back with pypdf.
"""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pypdf
import pytest
from PIL import Image

from workbench.reporting.pdf import ReportPDF
from workbench.reporting.report import utc_now, validate_report, write_report_pdf

SHA = "0123456789abcdef" * 4
BUILDS = {
    "model": "regional_bmi_2026",
    "main": "average",
    "builds": {
        "slender": {
            "bmi": 19.0,
            "z": -1.18,
            "offset_mm": {"p5": -4.6, "median": -2.3, "p95": -0.7},
        },
        "average": {"bmi": 24.3, "z": 0.0, "offset_mm": {"p5": 0.0, "median": 0.0, "p95": 0.0}},
        "heavy": {"bmi": 34.0, "z": 2.16, "offset_mm": {"p5": 1.6, "median": 4.4, "p95": 8.5}},
    },
    "band_half_width_mm": {"median": 9.77, "p90": 13.28},
    "files": ["face_slender.ply", "face_average.ply", "face_heavy.ply", "face_band_mm.npy"],
    "note": "the skull cannot tell the build",
}


def picture(path: Path, size: tuple[int, int]) -> str:
    """A stand-in PNG (a grey block on white) of ``size`` pixels."""
    path.parent.mkdir(parents=True, exist_ok=True)
    image = np.full((size[1], size[0], 3), 255, np.uint8)
    image[size[1] // 5 : -size[1] // 5, size[0] // 5 : -size[0] // 5] = 120
    Image.fromarray(image).save(path)
    return str(path.relative_to(path.parent.parent))


def report_dict(folder: Path, *, builds: bool = True, pictures: bool = True, warnings=()) -> dict:
    report = {
        "@schema": "reconstruction-report-v1",
        "case_id": "case-builds-1",
        "created": utc_now(),
        "software": {"name": "workbench", "version": "0.1.0"},
        "template": {"id": "reference/male", "content_hash": SHA},
        "frame": "input skull frame",
        "units": "mm",
        "inputs": [{"role": "skull", "path": "skull.ply", "sha256": SHA, "units": "mm"}],
        "table": {
            "id": "ttable_2023",
            "title": "T-Table",
            "citation": "Stephan 2023",
            "group": "adult",
            "build": "normal",
        },
        "landmarks": [
            {
                "code": "g",
                "name": "glabella",
                "status": "placed",
                "position_mm": [0.0, 10.0, 90.0],
                "skin_code": "g'",
                "table_depth_mm": 5.5,
                "sd_mm": 1.2,
                "depth_mm": 5.5,
                "source": "table",
                "direction": [0.0, 0.0, 1.0],
            }
        ],
        "warnings": list(warnings),
        "pictures": {},
    }
    if pictures:
        report["pictures"] = {
            "face_front": picture(folder / "pictures" / "recon_face_front.png", (300, 350)),
            "builds_front": picture(folder / "pictures" / "builds_front.png", (900, 350)),
            "builds_side": picture(folder / "pictures" / "builds_side.png", (900, 350)),
            "band": picture(folder / "pictures" / "band.png", (900, 350)),
        }
    if builds:
        report["builds"] = copy.deepcopy(BUILDS)
    return report


def read(path: Path) -> tuple[list[str], pypdf.PdfReader]:
    reader = pypdf.PdfReader(str(path))
    return [" ".join(page.extract_text().split()) for page in reader.pages], reader


def test_builds_lead_the_first_page_and_the_band_has_its_section(tmp_path: Path) -> None:
    report = report_dict(tmp_path)
    validate_report(report)
    texts, reader = read(write_report_pdf(report, tmp_path / "report.pdf"))
    first = texts[0]
    assert "Three builds" in first
    assert "cannot tell how heavy" in first
    for phrase in ("slender (BMI 19)", "average (BMI 24.3)", "heavy (BMI 34)"):
        assert phrase in first, phrase
    assert "face.ply is the average face" in first
    assert "median half-width 9.8 mm" in first and "19.5 mm thick" in first
    assert "z-score" not in " ".join(texts)
    # the builds picture is on the first page, the section before the input files
    assert len(reader.pages[0].images) == 1
    later = " ".join(texts)
    assert later.index("Three builds") < later.index("Input files")
    # the band: its own section with median and 90th percentile, and its picture
    band_page = next(i for i, t in enumerate(texts) if "Uncertainty band Where" in t)
    assert "median 9.8 mm, 90th percentile 13.3 mm" in texts[band_page]
    assert "face_band_mm.npy" in texts[band_page]
    # every picture once: face_front, the builds side view with the others, the band map
    assert sum(len(page.images) for page in reader.pages) == 4
    assert "The three builds" in " ".join(texts)
    assert not any("Other pictures" in t for t in texts)


def test_old_report_without_builds_still_lays_out(tmp_path: Path) -> None:
    """No ``builds`` key, or ``null``: no build sections; build pictures would go to
    "Other pictures" rather than be lost."""
    for value in ("absent", None):
        folder = tmp_path / str(value)
        report = report_dict(folder, builds=False)
        if value is None:
            report["builds"] = None
        texts, reader = read(write_report_pdf(report, folder / "report.pdf"))
        text = " ".join(texts)
        assert "Three builds" not in text and "Uncertainty band" not in text
        assert "Other pictures" in text
        assert sum(len(page.images) for page in reader.pages) == 4
    plain = report_dict(tmp_path / "plain", builds=False, pictures=False)
    texts, _ = read(write_report_pdf(plain, tmp_path / "plain" / "report.pdf"))
    assert "case-builds-1" in texts[0] and "Three builds" not in " ".join(texts)


def test_builds_without_pictures_or_figures(tmp_path: Path) -> None:
    """``--no-pictures``: the text alone; a sparse ``builds`` entry does not break the PDF."""
    report = report_dict(tmp_path, pictures=False)
    texts, reader = read(write_report_pdf(report, tmp_path / "report.pdf"))
    assert "Three builds" in texts[0] and "heavy (BMI 34)" in texts[0]
    assert any("Uncertainty band Where" in t for t in texts)
    assert sum(len(page.images) for page in reader.pages) == 0
    report["builds"] = {"main": "BMI 27.5"}
    texts, _ = read(write_report_pdf(report, tmp_path / "sparse.pdf"))
    assert "face.ply is a face for BMI 27.5" in texts[0]


def test_long_warnings_keep_the_builds_picture(tmp_path: Path) -> None:
    """Many warnings: the builds picture is shrunk to stay on page 1, or moves whole to
    page 2 — never lost, never over the footer."""
    for n, page in ((12, 0), (40, 1)):
        folder = tmp_path / str(n)
        warnings = [f"warning {i}: a note of some length about the input" for i in range(n)]
        report = report_dict(folder, warnings=warnings)
        texts, reader = read(write_report_pdf(report, folder / "report.pdf"))
        images = [len(p.images) for p in reader.pages]
        assert images[page] >= 1, (n, images)
        assert sum(images) == 4


@pytest.mark.parametrize(
    ("y", "page", "shrunk"), [(40.0, 1, False), (225.0, 1, True), (250.0, 2, False)]
)
def test_one_picture_shrinks_to_stay_on_its_page(tmp_path: Path, y, page, shrunk) -> None:
    path = tmp_path / "p.png"
    picture(path, (900, 350))
    doc = ReportPDF("c", "2026-01-01", "workbench test")
    doc.add_page()
    doc.set_y(y)
    top = doc.get_y() if page == 1 else doc.t_margin
    doc.picture("caption", path)
    assert doc.page_no() == page
    width = doc.w - doc.l_margin - doc.r_margin
    height = doc.get_y() - 6.0 - top
    assert doc.get_y() <= doc.page_break_trigger + 1e-6
    assert (height < width * 350 / 900 - 1.0) == shrunk, height
