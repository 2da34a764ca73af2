"""The age-change PDF (issue 15): highlights, the measurement table, references, credits.

Real data: the built-in male head aged 18 -> 3 y with the shipped norms
(Frankfort frame, mm).  The pictures are plain PNGs drawn with PIL (this
layer never renders); the PDF is read back with pypdf.
"""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import pypdf
import pytest
from PIL import Image

from workbench.reporting.age_report import (
    HIGHLIGHT_FILL,
    Z_LIMIT,
    chart_references,
    highlighted_rows,
    measurement_table,
    provenance_credits,
    source_keys,
    write_age_report,
    z_out_of_range,
)
from workbench.services.age.change import AgeResult, MeasurementRow, age_head


def row(z_before: float, z_after: float, constraint: str = "norms") -> MeasurementRow:
    """A measurement whose z-scores are the given ones (mean 50 mm, SD 4 mm at both ages)."""
    return MeasurementRow(
        "m",
        "M",
        "euclidean",
        "a",
        "b",
        constraint,
        before_mm=50.0 + 4.0 * z_before,
        after_mm=50.0 + 4.0 * z_after,
        target_mm=50.0 + 4.0 * z_after,
        mean_from=50.0,
        sd_from=4.0,
        mean_to=50.0,
        sd_to=4.0,
        source="weinberg2016",
    )


def test_rows_outside_two_sd_are_highlighted_and_only_those() -> None:
    rows = [
        row(0.3, 0.31),
        row(2.5, 2.49),  # both out
        row(1.9, -2.1),  # after out
        row(-2.01, 0.0),  # before out
        row(Z_LIMIT, -Z_LIMIT),  # on the limit: inside
        row(5.0, 5.0, constraint="scale"),  # no norms, no z-score
        replace(row(0.0, 0.0), after_mm=float("nan")),  # not measured after
    ]
    assert highlighted_rows(rows) == [False, True, True, True, False, False, False]
    assert z_out_of_range(rows[2]) == (False, True)
    assert z_out_of_range(rows[3]) == (True, False)
    assert highlighted_rows(rows, limit=1.0) == [False, True, True, True, True, False, False]


def test_source_keys_split_joined_sources_and_charts_are_read_from_the_figures() -> None:
    a = replace(row(0, 0), source="farkas1981; weinberg2016")
    b = replace(row(0, 0), source="weinberg2016")
    c = replace(row(0, 0), source="", constraint="scale")
    fig = {"head_circumference_mm": {"chart": "UK90 at 18 y, WHO2006 at 3 y"}}
    res = [
        AgeResult(None, 18.0, 3.0, "male", (a, c), fig),  # type: ignore[arg-type]
        AgeResult(
            None, 18.0, 8.0, "male", (b,), {"head_circumference_mm": {"chart": "UK90 at 8 y"}}
        ),  # type: ignore[arg-type]
    ]
    assert source_keys(res) == ["farkas1981", "weinberg2016"]
    assert chart_references(res) == ["UK90", "WHO2006"]


def test_provenance_credits_find_a_sample_anywhere_in_the_provenance() -> None:
    nlm = "Courtesy of the U.S. National Library of Medicine."
    credited = {"bc633e45e6af" * 5: nlm, "vhm_head_ct_1mm.nii.gz": nlm, "visible human": nlm}
    built = {
        "built_from": [{"role": "skin", "file": "/data/VHM_head_CT_1mm.nii.gz", "sha256": "f" * 64}]
    }
    assert provenance_credits(built, credited) == [nlm]
    nested = {"age_change": {"base": {"note": "from the Visible Human male"}}}
    assert provenance_credits(nested, credited) == [nlm]
    assert provenance_credits({"built_from": [{"file": "scan.ply"}]}, credited) == []
    assert provenance_credits({}, credited) == []


@pytest.fixture(scope="module")
def aged(head_male) -> AgeResult:
    return age_head(head_male, sex="male", from_age=18.0, to_age=3.0)


def png(path: Path, colour: tuple[int, int, int]) -> Path:
    Image.new("RGB", (400, 120), colour).save(path)
    return path


def pdf_text(path: Path) -> str:
    return "\n".join(page.extract_text() for page in pypdf.PdfReader(path).pages)


def highlight_fills(path: Path) -> int:
    """How often the highlight fill colour is set in the PDF's page content."""
    g, b = (f"{c / 255:.4f}".rstrip("0") for c in HIGHLIGHT_FILL[1:])
    pattern = re.compile(rf"1(\.0+)? {re.escape(g)}\d* {re.escape(b)}\d* rg".encode())
    return sum(
        len(pattern.findall(page.get_contents().get_data())) for page in pypdf.PdfReader(path).pages
    )


def test_report_pdf_has_every_measurement_with_its_z_scores(
    aged: AgeResult, head_male, tmp_path: Path
) -> None:
    pictures = {
        "compare_3y": png(tmp_path / "compare_3y.png", (200, 160, 140)),
        "growth_3y": png(tmp_path / "growth_3y.png", (90, 120, 200)),
    }
    citation = "Weinberg SM et al. (2016) The 3D Facial Norms Database, test citation."
    path = write_age_report(
        tmp_path / "out",
        head_male,
        [aged],
        pictures,
        notes=["a note for the reader"],
        software="workbench test",
        citations={"weinberg2016": citation},
        credits=["Courtesy of the U.S. National Library of Medicine."],
    )
    assert path == tmp_path / "out" / "report.pdf"
    assert path.read_bytes().startswith(b"%PDF")
    assert not (tmp_path / "out" / "report.pdf.part").exists()
    text = pdf_text(path)
    flat = " ".join(text.split())
    normed = [r for r in aged.rows if r.constraint == "norms"]
    assert len(normed) > 10
    for r in normed:
        assert r.name in flat
        line = next(ln for ln in text.splitlines() if ln.startswith(r.name + " "))
        # the report writes a z that rounds to zero as +0.00, never -0.00
        z0, z1 = (f"{z:+.2f}".replace("-0.00", "+0.00") for z in (r.z_before, r.z_after))
        assert z0 in line and z1 in line
        assert f"{r.mean_from:.1f} ± {r.sd_from:.1f}" in line
    # summary figures, the chart, references, credit, note, the pictures embedded
    fig = aged.figures
    assert f"{fig['global_scale']:.4f}" in flat
    assert f"{fig['head_circumference_mm']['before']:.1f}" in flat
    assert "WHO2006" in flat and "UK90" in flat
    assert citation in flat
    assert "National Library of Medicine" in flat
    assert "a note for the reader" in flat
    assert "growth displacement" in flat.lower()
    images = sum(len(page.images) for page in pypdf.PdfReader(path).pages)
    assert images == 2
    # the reference head's z-scores all lie within ±2: nothing highlighted
    assert not any(highlighted_rows(aged.rows))
    assert f"0 of {len(normed)} measurements with norms have a z-score outside ±2" in flat
    assert highlight_fills(path) == 0


def test_out_of_range_rows_print_highlighted(aged: AgeResult, head_male, tmp_path: Path) -> None:
    rows = list(aged.rows)
    picks = [i for i, r in enumerate(rows) if r.constraint == "norms"][:2]
    for i in picks:  # the norms' means moved so that the head lies 3 SD off them
        r = rows[i]
        rows[i] = replace(
            r, mean_from=r.before_mm - 3.0 * r.sd_from, mean_to=r.after_mm + 3.0 * r.sd_to
        )
    odd = replace(aged, rows=tuple(rows))
    body, flags = measurement_table(odd)
    assert [i for i, f in enumerate(flags) if f] == picks
    assert body[picks[0]][7] == "+3.00" and body[picks[0]][8] == "-3.00"
    path = write_age_report(tmp_path, head_male, [odd], {})
    flat = " ".join(pdf_text(path).split())
    n_norms = sum(r.constraint == "norms" for r in rows)
    assert f"2 of {n_norms} measurements with norms have a z-score outside ±2" in flat
    # each highlighted row sets the highlight fill (once per cell)
    assert highlight_fills(path) >= 2


def test_unconstrained_measurements_are_listed_with_the_reason(
    aged: AgeResult, head_male, tmp_path: Path
) -> None:
    rows = list(aged.rows)
    i = next(i for i, r in enumerate(rows) if r.constraint == "norms")
    rows[i] = replace(
        rows[i],
        constraint="unconstrained",
        before_mm=float("nan"),
        after_mm=float("nan"),
        note="landmark zz_l missing on the head",
    )
    path = write_age_report(tmp_path, head_male, [replace(aged, rows=tuple(rows))], {})
    flat = " ".join(pdf_text(path).split())
    assert "unconstrained: landmark zz_l missing on the head" in flat
    assert f"{rows[i].name} ({rows[i].a}–{rows[i].b})" in flat
    body, _ = measurement_table(replace(aged, rows=tuple(rows)))
    assert body[i][3] == "unconstrained" and body[i][4] == "–" and body[i][7] == "–"
