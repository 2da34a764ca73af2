"""The fit-scan PDF (issue 13): summary dict, pictures (distance maps, histogram) and the PDF.

Real data, no fit: the built-in male head stands in for the fitted head and
its skin with a hole punched at the left cheek for the scan (head frame, mm);
the distances are made up per vertex (a ramp over the face, NaN = not
counted elsewhere).  The PDF is read back with pypdf.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pypdf
import pytest
from PIL import Image

from workbench.core.mesh import Mesh
from workbench.reporting.fit_scan_report import fit_scan_summary, write_fit_scan_pdf

SHA = "0123456789abcdef" * 4


def _figures(n_counted: int, *, bone: bool, user: bool) -> dict:
    fig = {
        "scan_vertices": 4800,
        "scan_triangles": 9400,
        "face_region_vertices": n_counted,
        "face_region_not_head_vertices": 0,
        "face_region_hidden_vertices": 3,
        "face_within_1mm_fraction": 0.962,
        "face_within_2_5mm_fraction": 0.985,
        "face_mean_distance_mm": 0.31,
        "face_median_distance_mm": 0.12,
        "face_skin_to_scan_mm": {
            "n": 2700,
            "mean": 0.2,
            "p95": 0.9,
            "max": 3.0,
            "within_2_5mm_fraction": 0.99,
        },
        "face_on_scan_fraction": 0.87,
        "fold_overs": 0,
        "skin_landmark_to_scan_mm": {"mean": 0.25, "max": 3.1, "n": 80, "absent": ["chk_l"]},
        "tissue_depths": {
            "table": "ttable_2023",
            "group": "adult pooled, mean",
            "pairs": 2,
            "mean_abs_diff_mm": 0.1,
            "max_abs_diff_mm": 0.83,
            "per_landmark": {
                "g": {"table_mm": 5.5, "fitted_mm": 5.61},
                "n": {"table_mm": 6.5, "fitted_mm": 6.4},
            },
        },
        "face_skin_inside_skull_vertices": 0,
        "orientation": {
            "method": "seeds",
            "handedness": "from landmarks",
            "mirrored": True,
            "reference_scale": 0.95,
            "matched_fraction": 0.52,
            "cost": 0.1,
        },
        "seconds": {"orientation": 2.4, "skin": 1.6, "inside": 0.1, "total": 4.2},
        "detail": {
            "levels": 2,
            "fine_vertices": 77358,
            "fine_triangles": 154112,
            "face_within_1mm_fraction": 0.991,
            "face_within_2_5mm_fraction": 0.996,
            "face_mean_distance_mm": 0.12,
            "face_observed_fraction": 0.93,
            "face_over_skin_openings_vertices": 40,
            "face_within_2_5mm_fraction_off_openings": 0.998,
            "face_displacement_mm": {"mean_abs": 0.2, "p95_abs": 0.7, "max_abs": 3.1},
            "fold_overs": 0,
            "new_crossings": 2,
        },
    }
    if bone:
        fig["skull_vs_bone"] = {
            "face_skull_vertices": 5000,
            "mean_abs_mm": 4.1,
            "median_abs_mm": 3.0,
            "within_2_5mm_fraction": 0.41,
            "uniform_offset_baseline": {
                "depth_mm": 6.0,
                "face_skin_vertices": 1800,
                "mean_abs_mm": 5.7,
                "within_2_5mm_fraction": 0.397,
            },
        }
    if user:
        fig["skin_landmark_to_user_mm"] = {
            "mean": 1.5,
            "max": 2.75,
            "per_landmark": {"prn": 0.25, "pg": 2.75},
        }
    return fig


@pytest.fixture(scope="module")
def fake_fit(head_male):
    """A ScanFit look-alike: the male skin with a cheek hole as the scan, a made-up distance."""
    skin = head_male.skin
    at = head_male.skin_landmarks.as_dict()
    centres = skin.vertices[skin.faces].mean(axis=1)
    scan = Mesh(skin.vertices, skin.faces[np.linalg.norm(centres - at["chk_l"], axis=1) > 12.0])
    v = scan.vertices
    face = (v[:, 2] > np.percentile(v[:, 2], 60)) & (v[:, 1] > np.percentile(v[:, 1], 25))
    distance = np.full(scan.n_vertices, np.nan)
    distance[face] = np.clip((v[face, 1] - v[face, 1].min()) / np.ptp(v[face, 1]) * 3.0, 0, 3)
    prov = {
        **(head_male.provenance or {}),
        "built_from": [{"role": "scan", "file": "face.ply", "sha256": SHA}],
        "base_template": {"template_id": head_male.template_id, "content_hash": "c0ffee"},
    }
    head = replace(head_male, template_id="ref/scan/abc123", provenance=prov)
    return SimpleNamespace(
        head=head,
        scan=scan,
        scan_distance=distance,
        figures=_figures(int(face.sum()), bone=True, user=True),
        warnings=("table ttable_2023 has no male-specific depths: using sexes pooled",),
        mirrored_input=True,
    )


def test_summary_maps_the_figures_beside_the_targets(fake_fit):
    import json

    s = fit_scan_summary(fake_fit, "face.ply")
    json.dumps(s)  # plain data
    rows = {r["figure"]: r for r in s["rows"]}
    assert rows["Within 1 mm of the fitted skin"]["value"] == "96.2 %"
    assert rows["Within 1 mm of the fitted skin"]["met"] is True  # target 95 %
    assert rows["Within 2.5 mm of the fitted skin"]["met"] is False  # 98.5 % < 99 %
    assert rows["Fold-overs (triangles turned over)"]["met"] is True
    assert "4.10 mm" in rows["Estimated skull vs true bone (face region)"]["value"]
    assert "41.0 %" in rows["Estimated skull vs true bone (face region)"]["value"]
    baseline = rows["Baseline: face skin 6 mm inward vs true bone"]
    assert "5.70 mm" in baseline["value"] and "39.7 %" in baseline["value"]
    assert baseline["met"] is True  # 41.0 % beats 39.7 %
    assert "chk_l" in rows["Skin landmarks → scan"]["value"]
    assert "2.75 mm" in rows["Skin landmarks → user-placed"]["value"]
    assert "ttable_2023" in rows["Tissue depths vs the table"]["value"]
    assert rows["Mirrored input"]["value"] == "yes"
    fine = rows["Fine detail (skin_detailed.ply): within 1 / 2.5 mm"]
    assert fine["value"].startswith("99.1 % / 99.6 %") and fine["met"] is True
    assert rows["… fold-overs / crossings it added"]["met"] is False  # 2 crossings
    assert "99.8 %" in rows["… scan over the skin's eye, mouth, nostril openings"]["value"]
    assert rows["Seconds"]["value"].startswith("4.2")
    assert s["inputs"] == [{"role": "scan", "file": "face.ply", "sha256": SHA}]
    assert s["template_id"] == "ref/scan/abc123"
    assert [d["code"] for d in s["depths"]] == ["g", "n"]
    assert s["user_landmarks"][1] == {"code": "pg", "mm": 2.75}


def test_summary_without_bone_or_user_landmarks(fake_fit):
    bare = SimpleNamespace(**{**vars(fake_fit), "mirrored_input": False})
    bare.figures = _figures(100, bone=False, user=False)
    rows = {r["figure"]: r["value"] for r in fit_scan_summary(bare, "s.ply")["rows"]}
    assert rows["Estimated skull vs true bone (face region)"] == "no bone given"
    assert rows["Skin landmarks → user-placed"] == "none placed"
    assert rows["Mirrored input"] == "no"


def _ink(path: Path) -> np.ndarray:
    """RGB pixels that are not the white background, (k, 3) ints."""
    rgb = np.asarray(Image.open(path).convert("RGB"), dtype=int)
    px = rgb.reshape(-1, 3)
    return px[(px < 235).any(axis=1)]


@pytest.fixture(scope="module")
def pictures(fake_fit, tmp_path_factory):
    from workbench.render.scan_fit_pictures import render_scan_fit_pictures

    folder = tmp_path_factory.mktemp("fit-scan-pictures")
    pics, notes = render_scan_fit_pictures(fake_fit, folder, size=(220, 260))
    return pics, notes


def test_pictures_exist_and_are_not_blank(pictures):
    pics, notes = pictures
    assert notes == []
    assert list(pics) == ["distance", "signed", "histogram"]
    for path in pics.values():
        assert path.is_file()
        rgb = np.asarray(Image.open(path).convert("RGB"), dtype=float)
        assert rgb.std() > 20.0, path  # not a flat image
        assert len(_ink(path)) > 0.05 * rgb.shape[0] * rgb.shape[1]


def test_distance_map_colours_and_grey_where_not_counted(fake_fit, tmp_path):
    from workbench.render.scan_fit_pictures import render_distance_views

    scan = fake_fit.scan
    kw = {"views": ("front",), "size": (200, 240), "title": ""}
    grey = render_distance_views(scan, np.full(scan.n_vertices, np.nan), tmp_path / "g.png", **kw)
    hot = render_distance_views(scan, np.full(scan.n_vertices, 3.0), tmp_path / "h.png", **kw)
    # the scalar bar is coloured too: look at the head only (left four fifths of the panel)
    g = np.asarray(Image.open(grey).convert("RGB"), dtype=int)[:, :150].reshape(-1, 3)
    h = np.asarray(Image.open(hot).convert("RGB"), dtype=int)[:, :150].reshape(-1, 3)
    g, h = g[(g < 235).any(axis=1)], h[(h < 235).any(axis=1)]
    spread_g = g.max(axis=1) - g.min(axis=1)
    spread_h = h.max(axis=1) - h.min(axis=1)
    assert np.median(spread_g) < 12  # grey: R ≈ G ≈ B
    assert np.median(spread_h) > 30  # 2.5 mm and beyond: dark red
    assert np.median(h[:, 0] - h[:, 2]) > 30  # red over blue (dark red, shaded)


def test_signed_distance_takes_the_side_of_the_skin(head_male):
    from workbench.render.scan_fit_pictures import signed_scan_distance

    skin = head_male.skin
    n = skin.vertex_normals
    ids = np.arange(0, skin.n_vertices, 50)
    points = np.concatenate([skin.vertices[ids] + 1.5 * n[ids], skin.vertices[ids] - 1.5 * n[ids]])
    scan = Mesh(points)
    distance = np.full(len(points), 1.5)
    distance[0] = np.nan
    signed = signed_scan_distance(scan, skin, distance)
    half = len(ids)
    assert np.isnan(signed[0])
    assert np.mean(signed[1:half] > 0) > 0.95  # outside the skin
    assert np.mean(signed[half:] < 0) > 0.95  # inside


def test_histogram_without_values_is_still_a_picture(tmp_path):
    from workbench.render.scan_fit_pictures import render_distance_histogram

    path = render_distance_histogram(np.full(10, np.nan), tmp_path / "h.png")
    assert Image.open(path).size[0] > 500


def test_pdf_holds_the_figures_and_the_pictures(fake_fit, pictures, tmp_path):
    pics, _ = pictures
    out = write_fit_scan_pdf(
        fit_scan_summary(fake_fit, "face.ply"), tmp_path / "fit_report.pdf", pics
    )
    data = out.read_bytes()
    assert data.startswith(b"%PDF")
    assert not (tmp_path / "fit_report.pdf.part").exists()
    reader = pypdf.PdfReader(out)
    text = " ".join(page.extract_text() for page in reader.pages)
    flat = " ".join(text.split())
    for words in (
        "face.ply",
        "96.2 %",
        "98.5 %",
        "not met",
        "ttable_2023",
        "ref/scan/abc123",
        SHA,
        "4.10 mm",
        "Mirrored input",
        "Grey: not counted",
        "head frame",
    ):
        assert words in flat, words
    images = sum(len(page.images) for page in reader.pages)
    assert images == 3


def test_pdf_without_pictures_says_why(fake_fit, tmp_path):
    out = write_fit_scan_pdf(
        fit_scan_summary(fake_fit, "face.ply"),
        tmp_path / "r.pdf",
        {},
        notes=["no pictures (no OpenGL)"],
    )
    reader = pypdf.PdfReader(out)
    text = " ".join(page.extract_text() for page in reader.pages)
    assert "no OpenGL" in text
    assert sum(len(p.images) for p in reader.pages) == 0


def test_summary_says_where_the_face_was_laid(fake_fit):
    placed = SimpleNamespace(**vars(fake_fit))
    placed.figures = _figures(100, bone=False, user=False)
    placed.figures["orientation"] = {
        "method": "hint + face placement",
        "handedness": "assumed",
        "reference_scale": 0.9,
        "matched_fraction": 0.58,
        "cost": 0.26,
        "face_placement": {"moved": True, "face_within_5mm_fraction": 0.81},
    }
    rows = {r["figure"]: r for r in fit_scan_summary(placed, "bust.obj")["rows"]}
    laid = rows["Reference face laid on the scan"]
    assert (
        laid["value"]
        == "81.0 % of its vertices within 5 mm of the scan (moved from the search's pose)"
    )
    assert laid["met"] is True
    assert rows["Orientation"]["value"].startswith("hint + face placement")
    # a fit from landmarks has no placement row
    rows = {r["figure"] for r in fit_scan_summary(fake_fit, "face.ply")["rows"]}
    assert "Reference face laid on the scan" not in rows
