"""The reconstruction report (issue 4, "Command and outputs"): schema, report.json, report.pdf.

Real data: the built-in reference head stands in for a reconstruction: its
cranium, mandible and teeth are the skull, its skull landmarks with 2023
T-Table dowels (:func:`workbench.services.tissue.dowels.plan_dowels`) the landmarks,
its skin the face.  The skin moved 2 mm outward is the "truth" of the
validation section.  The PDF is read back with pypdf.
"""

from __future__ import annotations

import copy
import json
import re
from pathlib import Path

import numpy as np
import pypdf
import pytest

from workbench.core.errors import InputError
from workbench.core.mesh import Mesh, concatenate
from workbench.core.normals import vertex_normals
from workbench.io.catalogue import load_catalogue
from workbench.io.markups import write_mrk_json
from workbench.io.meshes import write_mesh
from workbench.io.tables import load_depth_table, tables_dir
from workbench.model.evidence import file_sha256 as sha256_file
from workbench.reporting import pdf as pdf_module
from workbench.reporting.report import (
    read_report_json,
    utc_now,
    validate_report,
    write_report_json,
    write_report_pdf,
)
from workbench.services.templates.regions import face_regions
from workbench.services.tissue.dowels import DepthSettings, plan_dowels
from workbench.services.validation.compare import compare_surfaces

CASE_ID = "2024-Hx-0117"


def merge(*meshes: Mesh) -> Mesh:
    return concatenate(list(meshes))


def build_report(head, folder: Path, *, render: bool = True, size=(200, 240)) -> dict:
    """A complete report of the reference head as if it were a reconstruction, files in ``folder``."""
    m = head.meshes
    skull = merge(m["cranium"], m["mandible"], m["upper_teeth"], m["lower_teeth"])
    inputs = folder / "inputs"
    inputs.mkdir(parents=True, exist_ok=True)
    skull_path = write_mesh(inputs / "skull.ply", skull)
    landmarks_path = inputs / "skull.mrk.json"
    write_mrk_json(landmarks_path, head.skull_landmarks)
    settings = DepthSettings(
        overrides={"pg": 12.0}, excluded=frozenset({"ecm2s_l", "ecm2s_r"}), interpolate=True
    )
    plan = plan_dowels(skull, head.skull_landmarks, settings)
    table = load_depth_table(settings.table)
    catalogue = load_catalogue()
    status = {lm.code: lm.status for lm in head.skull_landmarks}
    landmarks = []
    for d in plan.dowels:
        entry = catalogue.get(d.code, "skull")
        landmarks.append(
            {
                "code": d.code,
                "name": entry.name if entry else "interpolated site",
                "status": status.get(d.code, "suggested"),
                "position_mm": d.origin,
                "skin_code": d.skin_code,
                "table_depth_mm": d.table_depth_mm,
                "sd_mm": d.sd_mm,
                "depth_mm": None if d.excluded else d.depth_mm,
                "source": "excluded" if d.excluded else d.source,
                "direction": d.direction,
                "note": (
                    "hollow cheeks with table depths (Kähler 2003, §8.6.8)"
                    if d.excluded
                    else "set by the examiner"
                    if d.source == "override"
                    else None
                ),
            }
        )
    for lm in head.skull_landmarks:  # no table value, no override: no dowel
        if lm.code not in plan.codes:
            landmarks.append(
                {
                    "code": lm.code,
                    "name": catalogue.entry(lm.code, "skull").name,
                    "status": lm.status,
                    "position_mm": lm.position,
                    "skin_code": None,
                    "table_depth_mm": None,
                    "sd_mm": None,
                    "depth_mm": None,
                    "source": "none",
                    "direction": None,
                }
            )
    report = {
        "@schema": "reconstruction-report-v1",
        "case_id": CASE_ID,
        "created": utc_now(),
        "examiner": "J. Kähler-Öztürk",
        "software": {"name": "workbench", "version": "0.1.0"},
        "template": {"id": head.template_id, "content_hash": head.content_hash},
        "frame": "input skull frame = head frame (x to the subject's left, y up, z forward; "
        "Frankfort Horizontal at y = 0)",
        "units": "mm",
        "inputs": [
            {
                "role": "skull",
                "path": str(skull_path),
                "sha256": sha256_file(skull_path),
                "units": "mm",
            },
            {
                "role": "landmarks",
                "path": str(landmarks_path),
                "sha256": sha256_file(landmarks_path),
                "units": "mm",
            },
            {
                "role": "table",
                "path": str(tables_dir() / "ttable_2023.csv"),
                "sha256": sha256_file(tables_dir() / "ttable_2023.csv"),
                "units": "mm",
            },
        ],
        "table": {
            "id": plan.table_id,
            "title": plan.table_title,
            "citation": plan.citation,
            "group": plan.group_label,
            "build": "normal",
            "caveats": list(table.meta.get("caveats", [])),
        },
        "landmarks": landmarks,
        "guides": [
            {
                "id": "nose_width",
                "label": "nose width: aperture + 5 mm per side",
                "kind": "vertical lines",
                "value": [-17.5, 17.5],
                "rule_id": "kaehler_nose_width",
                "citation": "Kähler 2003, §8.6.5",
                "source": "default",
                "enabled": True,
            },
            {
                "id": "pronasale",
                "label": "nose tip (Krogman)",
                "kind": "point",
                "value": [0.0, -8.5, 98.0],
                "rule_id": "krogman_3x_spine",
                "citation": "Taylor 2001, p. 443",
                "source": "user",
                "enabled": False,
            },
        ],
        "predictions": [
            {
                "rule_id": "rynn_2010_nose",
                "label": "pronasale projection",
                "value_mm": 21.4,
                "citation": "Rynn, Wilkinson & Peters 2010",
            }
        ],
        "fit": {
            "iterations": 3,
            "max_tip_error_mm": 0.04,
            "min_tissue_mm": 2.1,
            "penetrating_vertices": 0,
            "seconds": 1.7,
            "extra_constraints": 12,
        },
        "ensemble": {"n": 20, "spread_mm": {"median": 0.9, "p90": 2.1, "max": 3.6}},
        "validation": None,
        "pictures": {},
        "warnings": list(plan.warnings)
        + ["the skull is the reference head's own skull (test case) – depths ± 1 SD"],
    }
    skin = head.skin
    truth = skin.with_vertices(skin.vertices + 2.0 * vertex_normals(skin))
    cmp = compare_surfaces(skin, truth, recon_regions=face_regions(head))
    report["validation"] = {
        **cmp.figures,
        "truth": "skin + 2 mm (test)",
        "region": cmp.region,
        "regions": cmp.regions,
    }
    if render:
        from workbench.render.reconstruction import render_reconstruction

        active = plan.active()
        spread = np.abs(skin.vertices[:, 2]) / 40.0
        pictures = render_reconstruction(
            skull,
            skin,
            (np.array([d.origin for d in active]), np.array([d.tip for d in active])),
            folder / "pictures",
            spread=spread,
            eyes=m["eyes"],
            size=size,
        )
        report["pictures"] = {k: str(p.relative_to(folder)) for k, p in pictures.items()}
    return report


@pytest.fixture(scope="module")
def head(head_male):
    return head_male


@pytest.fixture(scope="module")
def written(head, tmp_path_factory):
    folder = tmp_path_factory.mktemp("case")
    report = build_report(head, folder)
    return (
        report,
        write_report_json(report, folder / "report.json"),
        write_report_pdf(report, folder / "report.pdf"),
    )


def pdf_text(path: Path) -> tuple[str, object]:
    reader = pypdf.PdfReader(str(path))
    return "\n".join(page.extract_text() for page in reader.pages), reader


def test_schema_file_is_a_valid_json_schema() -> None:
    import jsonschema

    from workbench.reporting.report import schema_path

    schema = json.loads(schema_path().read_text(encoding="utf-8"))
    jsonschema.Draft202012Validator.check_schema(schema)
    assert schema["$id"] == "reconstruction-report-v1"


def test_report_json_round_trips_and_validates(written) -> None:
    report, json_path, _ = written
    doc = read_report_json(json_path)
    assert doc["case_id"] == CASE_ID
    assert [lm["code"] for lm in doc["landmarks"]] == [lm["code"] for lm in report["landmarks"]]
    assert doc["examiner"] == "J. Kähler-Öztürk"  # UTF-8, not escaped away
    sources = {lm["source"] for lm in doc["landmarks"]}
    assert sources == {"table", "override", "excluded", "interpolated", "none"}
    # numpy arrays became lists of 3 numbers; NaN coverage (if any) became null
    assert all(len(lm["position_mm"]) == 3 for lm in doc["landmarks"])
    assert doc["validation"]["pct_within_2_5mm"] > 50.0
    assert "NaN" not in json_path.read_text(encoding="utf-8")


def test_pdf_holds_the_case_file_facts(written) -> None:
    report, _, pdf_path = written
    text, reader = pdf_text(pdf_path)
    flat = re.sub(r"\s+", "", text)
    assert len(reader.pages) >= 2
    assert CASE_ID in text
    assert "Hona" in text  # the table's citation
    assert report["inputs"][0]["sha256"] in flat  # the skull's SHA-256
    assert report["template"]["content_hash"] in flat
    for lm in report["landmarks"]:
        assert lm["code"] in text, lm["code"]
    assert "Kähler" in text and "±" in text and "–" in text  # unicode survives
    assert f"page 1 of {len(reader.pages)}" in text  # footer with page numbers
    assert text.count(f"Case {CASE_ID}") >= len(reader.pages)  # footer on every page
    assert "Validation" in text and "Uncertainty" in text and "Guides" in text
    images = sum(len(page.images) for page in reader.pages)
    assert images == len(report["pictures"]) == 10


def test_pictures_are_not_blank(written) -> None:
    from PIL import Image

    report, json_path, _ = written
    for key, rel in report["pictures"].items():
        image = np.asarray(Image.open(json_path.parent / rel).convert("RGB"), float)
        assert image.std() > 20.0, key
        assert (np.abs(image - 255).sum(axis=2) > 30).mean() > 0.1, key


def test_missing_key_fails_with_its_name(written) -> None:
    report = copy.deepcopy(written[0])
    del report["table"]["citation"]
    with pytest.raises(InputError, match=r"citation") as info:
        validate_report(report)
    assert "$.table" in str(info.value)
    report = copy.deepcopy(written[0])
    del report["case_id"]
    with pytest.raises(InputError, match="case_id"):
        write_report_json(report, Path("/nonexistent/never/written.json"))


@pytest.mark.parametrize(
    ("path", "value", "where"),
    [
        (("landmarks", 0, "depth_mm"), -3.0, r"\$\.landmarks\[0\]\.depth_mm"),
        (("landmarks", 1, "source"), "guessed", r"\$\.landmarks\[1\]\.source"),
        (("inputs", 0, "sha256"), "abc", r"\$\.inputs\[0\]\.sha256"),
        (("units",), "cm", r"\$\.units"),
        (("created",), "yesterday", r"\$\.created"),
        (("fit", "seconds"), float("inf"), r"\$\.fit\.seconds"),
    ],
)
def test_bad_values_are_named_by_json_path(written, path, value, where) -> None:
    report = copy.deepcopy(written[0])
    target = report
    for key in path[:-1]:
        target = target[key]
    target[path[-1]] = value
    with pytest.raises(InputError, match=where):
        validate_report(report)


def test_excluded_landmark_has_no_used_depth_and_codes_are_unique(written) -> None:
    report = copy.deepcopy(written[0])
    excluded = next(i for i, lm in enumerate(report["landmarks"]) if lm["source"] == "excluded")
    report["landmarks"][excluded]["depth_mm"] = 9.0
    with pytest.raises(InputError, match=rf"landmarks\[{excluded}\]"):
        validate_report(report)
    report = copy.deepcopy(written[0])
    report["landmarks"].append(copy.deepcopy(report["landmarks"][0]))
    with pytest.raises(InputError, match="duplicate code"):
        validate_report(report)


def test_minimal_report_and_missing_picture(head, tmp_path: Path, written) -> None:
    """Optional sections absent: the PDF still builds; a listed picture that is gone is noted."""
    full = written[0]
    report = {
        k: copy.deepcopy(full[k])
        for k in (
            "@schema",
            "case_id",
            "created",
            "software",
            "template",
            "frame",
            "units",
            "inputs",
            "table",
        )
    }
    report["landmarks"] = copy.deepcopy(full["landmarks"][:3])
    report["pictures"] = {"face_front": "pictures/gone.png"}
    report.update(ensemble=None, validation=None, guides=[], warnings=None)
    path = write_report_pdf(report, tmp_path / "out" / "report.pdf")
    text, reader = pdf_text(path)
    assert "picture not found" in text
    assert "Validation" not in text and "Guides" not in text and "Uncertainty" not in text
    assert sum(len(page.images) for page in reader.pages) == 0
    assert not list(path.parent.glob("*.tmp"))  # atomic: no temporary left


def test_core_font_fallback_transliterates(written, tmp_path: Path, monkeypatch) -> None:
    assert pdf_module.transliterate("Kähler – ± ≤ 2.5 mm “x”") == 'Kähler - ± <= 2.5 mm "x"'
    monkeypatch.setattr(pdf_module, "find_fonts", lambda: None)
    report = copy.deepcopy(written[0])
    report["pictures"] = {}
    text, _ = pdf_text(write_report_pdf(report, tmp_path / "core.pdf"))
    assert CASE_ID in text and "Kähler" in text and "Hona" in text


def test_a_long_table_wraps_its_cells_and_repeats_its_heading_on_each_page(tmp_path) -> None:
    """The report's own table drawing: words wrap inside their column (a word wider than
    the column is cut), the heading row comes again at the top of every page the table
    runs on, and no text is lost."""
    doc = pdf_module.ReportPDF("case-1", "2026-12-05", "workbench test")
    doc.add_page()
    long_word = "x" * 120
    rows = [
        (f"row{i:03d}", f"the {i}th value with a few words to wrap", long_word if i == 5 else "-")
        for i in range(120)
    ]
    doc.grid(("code", "description", "note"), rows, (20, 40, 30))
    path = tmp_path / "t.pdf"
    doc.output(str(path))
    reader = pypdf.PdfReader(path)
    assert len(reader.pages) >= 3
    texts = [page.extract_text() for page in reader.pages]
    for text in texts:  # the heading row at the top of each page
        assert text.lstrip().startswith("code")
    flat = " ".join(" ".join(texts).split())
    for i in range(120):
        assert f"row{i:03d}" in flat and f"the {i}th value" in flat
    assert flat.replace(" ", "").count("x" * 120) == 1  # cut into pieces, all of them kept


def test_the_appearance_section_says_the_hair_is_not_evidence(head, tmp_path) -> None:
    """A case with chosen colours and hair (issue 34): report.json carries them under
    ``appearance`` (schema-valid) and the PDF has the section, the note and the portraits."""
    from PIL import Image

    report = build_report(head, tmp_path, render=False)
    pictures = dict(report.get("pictures") or {})
    for i, view in enumerate(("front", "three_quarter", "profile")):
        path = tmp_path / "pictures" / f"portrait_{view}.png"
        path.parent.mkdir(parents=True, exist_ok=True)
        Image.new("RGB", (120, 120), (90 + 40 * i, 70, 60)).save(path)
        pictures[f"portrait_{view}"] = str(path.relative_to(tmp_path))
    report["pictures"] = pictures
    report["appearance"] = {
        "summary": "skin tone mst4; iris blue; hair short (artistic additions, not evidence).",
        "note": "Colours are an artistic choice, not evidence.",
        "artistic_additions": {
            "hair_and_brows": {"hair": "short", "beard": "full"},
            "note": "Hair, brows and beard are artistic additions, not evidence.",
        },
    }
    validate_report(report)
    pdf = write_report_pdf(report, tmp_path / "report.pdf")
    text, _ = pdf_text(pdf)
    assert "Appearance: an artistic presentation" in text
    assert "hair short, beard full" in text and "Not evidence" in text
    assert "Portraits in the chosen appearance" in text
    bad = copy.deepcopy(report)
    bad["appearance"]["colour"] = "red"
    with pytest.raises(InputError):
        validate_report(bad)
