"""Page 1 of the reports leads with the result; every note closes the PDF (issue 33).

The reconstruction report: a report dict in the schema's layout whose
warnings are those of a real reconstruction (the head-squared skull of the
sample data, ``workbench reconstruct``), with stand-in PNGs of the real
pictures' proportions (no rendering).  The age and scan-fit reports: small
hand-made results.  Every PDF is read back with pypdf; a note is looked for
with its spaces and line breaks taken out and in lower case (the appendix
prints it as a sentence: capital first letter, full stop).
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import numpy as np
import pypdf
import pytest
from PIL import Image

from workbench.pipelines.reconstruct import FIT_FIGURES
from workbench.reporting.first_page import KEY_FIGURES, before_use, note_groups
from workbench.reporting.pdf import sentence
from workbench.reporting.report import utc_now, validate_report, write_report_pdf

SHA = "0123456789abcdef" * 4
APPENDIX = "Appendix: technical notes"
#: the warnings of a real reconstruction's report.json (and two guide notes of another)
WARNINGS = [
    "skull mesh: 7 holes (boundary loops of 196, 184, 40, 22, 22, ... edges)",
    "21 % of the bone surface lies far from any skull part (C-spine, hyoid, apparatus, "
    "debris) and was ignored",
    "table ttable_2023 has no male-specific depths: using sexes pooled",
    "no dowel for v, op, iC_l: marked absent",
    "no dowel for iC_r (4.2 mm), mr_l (3.1 mm): farther than 3 mm from the skull surface "
    "(missing bone, or a misplaced landmark?)",
    "no depth in table ttable_2023 for d_l, d_r, ec_l, ec_r, or_l, or_r, lo_l, lo_r, im_l, "
    "im_r, ol_l, ol_r, sgl_l, sgl_r, po_l, po_r, ms_l, ms_r: no dowels there (set an override "
    "to add one)",
    "interpolated dowels skipped: "
    + "; ".join(f"i:v-g:0.{k}: v not placed" for k in (25, 50, 75))
    + "; "
    + "; ".join(f"i:op-mso_l:0.{k}: op not placed" for k in (25, 50, 75)),
    "10 % of the face lies over missing bone and is inferred from the reference head "
    "(marked in the head pack, the report and the pictures)",
    "nose tip guide not derived (spine_projection: no anterior nasal spine ans; ans_y: not "
    "measured; ans_z: not measured)",
    "upper lip margin guide not derived (upper_cej_y: no upper incisor crowns on the skull mesh)",
    "default rule mouth_75pct_rule not applied (not computed, missing intercanine_width); "
    "the classic guide kaehler_mouth_width stays where it could be measured",
    "one face only: a uniform mean + k SD build (use slender, average, heavy or bmi:X for "
    "the build model's three faces and band)",
]
FIT = {
    "max_tip_error_mm": 0.543,
    "min_tissue_mm": 0.339,
    "penetrating_vertices": 0,
    "thin_vertices": 6,
    "refits": 3,
    "correspondences": 1616,
    "seconds": 2.245,
    "snapped_landmarks": 15,
    "face_observed_fraction": 0.9013,
    "suggested_landmarks": 54,
    "placed_landmarks": 0,
    "absent_landmarks": 8,
}
BUILDS = {
    "model": "regional_bmi_2026",
    "main": "average",
    "builds": {"slender": {"bmi": 19.0}, "average": {"bmi": 24.3}, "heavy": {"bmi": 34.0}},
    "band_half_width_mm": {"median": 9.77, "p90": 13.28},
    "files": ["face_band_mm.npy"],
}


def picture(path: Path, size: tuple[int, int]) -> str:
    """A stand-in PNG (a grey block on white) of ``size`` pixels; its path from the report."""
    path.parent.mkdir(parents=True, exist_ok=True)
    image = np.full((size[1], size[0], 3), 255, np.uint8)
    image[size[1] // 5 : -size[1] // 5, size[0] // 5 : -size[0] // 5] = 120
    Image.fromarray(image).save(path)
    return str(path.relative_to(path.parent.parent))


def report_dict(folder: Path, *, builds: bool, warnings=WARNINGS) -> dict:
    pics = folder / "pictures"
    report: dict[str, Any] = {
        "@schema": "reconstruction-report-v1",
        "case_id": "case-first-page",
        "created": utc_now(),
        "examiner": "J. Kähler-Öztürk",
        "software": {"name": "workbench", "version": "0.1.0"},
        "template": {"id": "reference/male", "content_hash": SHA},
        "frame": "input frame of the skull file (mm)",
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
                "status": "suggested",
                "position_mm": [0.0, 10.0, 90.0],
                "skin_code": "g'",
                "table_depth_mm": 5.5,
                "sd_mm": 1.2,
                "depth_mm": 5.5,
                "source": "table",
                "direction": [0.0, 0.0, 1.0],
            }
        ],
        "fit": dict(FIT),
        "self_check": {"outcome": "confident", "reasons": [], "measures": {}},
        "inferred": {"face_observed_fraction": FIT["face_observed_fraction"], "note": "n"},
        "credits": ["Courtesy of a test data set."],
        "warnings": list(warnings),
        "pictures": {
            "face_front": picture(pics / "recon_face_front.png", (300, 350)),
            "face_side": picture(pics / "recon_face_side.png", (300, 350)),
        },
    }
    if builds:
        report["builds"] = copy.deepcopy(BUILDS)
        for key in ("builds_front", "builds_side", "band"):
            report["pictures"][key] = picture(pics / f"{key}.png", (900, 350))
    validate_report(report)
    return report


def read(path: Path) -> tuple[list[str], pypdf.PdfReader]:
    reader = pypdf.PdfReader(str(path))
    return [" ".join(page.extract_text().split()) for page in reader.pages], reader


def squash(text: str) -> str:
    return "".join(text.split()).lower()


def after_appendix(texts: list[str]) -> str:
    """The squashed text from the appendix's heading to the end (the heading on one page)."""
    start = next(i for i, t in enumerate(texts) if APPENDIX in t)
    rest = " ".join(texts[start:])
    return squash(rest[rest.index(APPENDIX) :])


@pytest.mark.parametrize("builds", [True, False], ids=["three builds", "one face"])
def test_page_1_leads_with_the_face_and_every_note_is_in_the_appendix(
    tmp_path: Path, builds: bool
) -> None:
    report = report_dict(tmp_path, builds=builds)
    texts, reader = read(write_report_pdf(report, tmp_path / "report.pdf"))
    first = texts[0]
    # the title block, then the picture (its caption) and the key figures, then the notes
    assert first.index("Examiner J. Kähler-Öztürk") < first.index("front view")
    assert len(reader.pages[0].images) == 1
    assert first.index("front view") < first.index("Before use")
    assert first.index("Before use") < first.index("12 technical notes")
    for note in WARNINGS:  # no note on page 1, each in full in the appendix
        assert squash(note) not in squash(first), note
    tail = after_appendix(texts)
    for note in WARNINGS:
        assert squash(note) in tail, note
    whole = squash(" ".join(texts))
    for note in WARNINGS:  # once: the appendix does not repeat a note
        assert whole.count(squash(note)) == 1, note
    # the credits are kept, and the appendix closes the report
    assert "Courtesy of a test data set." in " ".join(texts)
    assert APPENDIX in " ".join(texts[-2:])
    assert texts[-1].rstrip().endswith(f"page {len(texts)} of {len(texts)}")
    # every picture once: the face's front view leads page 1 when there are no builds
    assert sum(len(p.images) for p in reader.pages) == len(report["pictures"])


def test_every_note_of_a_long_report_survives(tmp_path: Path) -> None:
    """Sixty notes: the appendix runs over pages, none is dropped, page 1 keeps its picture."""
    notes = [f"note {i:02d}: the input had something worth a line of text" for i in range(60)]
    report = report_dict(tmp_path, builds=True, warnings=notes)
    texts, reader = read(write_report_pdf(report, tmp_path / "report.pdf"))
    assert len(reader.pages[0].images) == 1
    tail = after_appendix(texts)
    assert all(squash(n) in tail for n in notes)
    assert "60 technical notes" in texts[0]


def test_key_figures_on_page_1_are_the_fits_main_numbers(tmp_path: Path) -> None:
    shown = {key for key, _, _ in KEY_FIGURES} | {
        f"{k}_landmarks" for k in ("placed", "suggested", "absent")
    }
    assert set(FIT_FIGURES) <= shown
    texts, _ = read(write_report_pdf(report_dict(tmp_path, builds=True), tmp_path / "r.pdf"))
    first = texts[0]
    assert first.index("Three builds") < first.index("Key figures")
    for phrase in (
        "largest dowel-tip miss 0.54 mm",
        "thinnest soft tissue 0.34 mm",
        "skin vertices inside bone 0",
        "refits (skin out of bone) 3",
        "0 placed, 54 suggested, 8 absent",
        "90 % (10 % inferred)",
        "self-check confident",
    ):
        assert phrase in first, phrase


def test_before_use_holds_the_self_checks_doubt_and_at_most_three_more(tmp_path: Path) -> None:
    report = report_dict(tmp_path, builds=False)
    reasons = ["the symmetry plane lies 14° off the midline", "41 % of the facial skeleton"]
    report["self_check"] = {"outcome": "check", "reasons": reasons, "measures": {}}
    report["fit"].update(penetrating_vertices=12, max_tip_error_mm=3.2)
    report["inferred"]["face_observed_fraction"] = 0.7
    items, doubt = before_use(report)
    assert doubt and len(items) == 4
    assert all(r in items[0] for r in reasons)
    texts, _ = read(write_report_pdf(report, tmp_path / "check.pdf"))
    first = texts[0]
    assert "CHECK THIS RECONSTRUCTION" in first and "self-check CHECK (see Before use)" in first
    for phrase in ("14° off the midline", "12 skin vertices", "30 % of the face", "3.2 mm"):
        assert phrase in first, phrase
    # nothing to act on: no box at all, only the line pointing to the appendix
    calm = report_dict(tmp_path / "calm", builds=False)
    calm["inferred"]["face_observed_fraction"] = 0.97
    assert before_use(calm) == ([], False)
    texts, _ = read(write_report_pdf(calm, tmp_path / "calm.pdf"))
    assert "Before use" not in texts[0] and "12 technical notes" in texts[0]


def test_notes_read_as_sentences_in_groups() -> None:
    assert sentence("table ttable_2023 has no depths") == "Table ttable_2023 has no depths."
    assert sentence("pg moved 2 mm") == "pg moved 2 mm."  # a landmark code keeps its case
    assert sentence("iC_r: far from the bone.") == "iC_r: far from the bone."
    assert sentence("no dowel for v") == "No dowel for v."
    groups = dict(note_groups(WARNINGS))
    assert sum(len(v) for v in groups.values()) == len(WARNINGS)
    assert groups["The skull file"][0].startswith("skull mesh")
    assert all("guide" in n or "rule" in n for n in groups["Guides and feature rules"])


def test_age_and_scan_fit_reports_close_with_their_notes(tmp_path: Path) -> None:
    from workbench.reporting.age_report import write_age_report
    from workbench.reporting.fit_scan_report import write_fit_scan_pdf
    from workbench.services.age.change import AgeResult

    age_notes = ("3 landmarks moved more than 2 mm", "fold-overs near the ears")
    aged = AgeResult(
        None,  # type: ignore[arg-type]
        18.0,
        3.0,
        "male",
        (),
        {"global_scale": 0.81, "head_circumference_mm": {"chart": "UK90"}},
        age_notes,
    )
    head = type("Head", (), {"template_id": "reference/male", "content_hash": SHA})()
    texts, _ = read(write_age_report(tmp_path / "age", head, [aged]))
    assert "Summary per target age" in texts[0] and "2 technical notes" in texts[0]
    tail = after_appendix(texts)
    for note in age_notes:
        assert squash(note) not in squash(texts[0]) and squash(f"3 y: {note}") in tail
    scan_notes = ["table ttable_2023 has no male-specific depths: using sexes pooled"]
    summary = {
        "scan": "face.ply",
        "template_id": "ref/scan/1",
        "base_template": "reference/male",
        "mirrored_input": False,
        "units": "mm",
        "frame": "head frame",
        "inputs": [{"role": "scan", "file": "face.ply", "sha256": SHA}],
        "warnings": scan_notes,
        "rows": [{"figure": "Within 1 mm", "value": "96.2 %", "target": "95 %", "met": True}],
        "depths": [],
        "user_landmarks": [],
    }
    texts, _ = read(write_fit_scan_pdf(summary, tmp_path / "fit.pdf"))
    # a short report: all on one page, the note after the key figures, in the appendix
    first = texts[0]
    assert first.index("Key figures") < first.index("1 technical note") < first.index(APPENDIX)
    assert squash(scan_notes[0]) not in squash(first[: first.index(APPENDIX)])
    assert squash(scan_notes[0]) in after_appendix(texts)
