"""The PDF of ``workbench age`` (issue 15): the age change, every measurement's z-scores, pictures.

Units mm (lengths), years (ages); z-scores against the norms of the sex and
ethnicity.  Frame: each head's Frankfort frame (x to the subject's left,
x = 0 midsagittal, y up, z toward the face, origin between the porions),
where the axis-aligned measurements are read (horizontal = x, vertical =
y, depth = z), as in :mod:`workbench.services.age.change`.

This module lays out what the caller hands it and imports neither the
render layer nor ``workbench.io``: the pictures arrive as PNG paths (drawn by
:mod:`workbench.render.age_pictures`), the norms' citations as a mapping of
source key to text (from ``GrowthNorms.citation`` and
``HeadCircumferenceReference.citation``) and the data credit lines as text
(see :func:`provenance_credits`).

Pure parts, testable without a PDF: :func:`highlighted_rows` (which rows
print highlighted: a z-score outside ±2, the norms' usual range),
:func:`measurement_table` (one age's table as text), :func:`source_keys`,
:func:`chart_references` and :func:`provenance_credits`.

Page 1 holds the provenance and the summary per target age; the warnings
close the PDF in full, in "Appendix: technical notes" (issue 33).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

if TYPE_CHECKING:
    from workbench.reporting.pdf import ReportPDF

#: |z| above this is outside the norms' usual range (about 95 % of people lie within ±2 SD)
Z_LIMIT: Final = 2.0
UNITS: Final = "mm (every length), years (ages); z-scores in SD of the norms"
FRAME: Final = (
    "each head's Frankfort frame: x to the subject's left, x = 0 midsagittal, y up, z toward "
    "the face, origin between the porions; horizontal / vertical / depth measurements are "
    "read along x / y / z"
)
METHOD: Final = (
    "Kähler 2003 §8.5: every measurement with norms at both ages keeps its z-score, "
    "d_t = μ_t + (σ_t/σ_c)(d_c − μ_c), as a hard constraint; Table 8.2 measurements without "
    "norms here and nearby landmark pairs follow the head-circumference scale; per-axis least "
    "squares with a condition clamp, translation anchored at the tragia; arcs after the "
    "solve; the whole head warped, the source tissue depths kept."
)
NOTES_INTRO: Final = (
    "Everything the software noted while changing the head's age, in full, each with the "
    "target age it concerns."
)
TABLE_HEADERS: Final = (
    "measurement",
    "landmarks",
    "kind",
    "constraint",
    "before",
    "norm at source age (mean ± SD)",
    "norm at target age (mean ± SD)",
    "z before",
    "z after",
    "target",
    "after",
    "residual",
)
TABLE_WIDTHS: Final = (62, 22, 17, 19, 15, 27, 27, 14, 14, 15, 15, 16)
TABLE_ALIGNS: Final = ("L", "L", "L", "L", "R", "R", "R", "R", "R", "R", "R", "R")
#: what the constraint column means
CONSTRAINTS: Final = {
    "norms": "hard constraint: keeps its z-score (norms at both ages)",
    "scale": "no norms at both ages: follows the head-circumference scale",
    "unconstrained": "not measurable on this head (a landmark is missing)",
}
#: fill and text colour of a highlighted row (|z| > 2)
HIGHLIGHT_FILL: Final = (255, 226, 196)
HIGHLIGHT_TEXT: Final = (150, 40, 0)


def _finite(value: Any) -> bool:
    try:
        return math.isfinite(float(value))
    except (TypeError, ValueError):
        return False


def z_out_of_range(row: Any, limit: float = Z_LIMIT) -> tuple[bool, bool]:
    """``(z before out of range, z after out of range)`` of a measurement row.

    Only rows constrained by norms have z-scores; ``|z| > limit`` (strictly)
    is out of the norms' usual range.
    """
    if getattr(row, "constraint", None) != "norms":
        return False, False
    out = []
    for name in ("z_before", "z_after"):
        z = getattr(row, name)
        out.append(_finite(z) and abs(float(z)) > limit)
    return out[0], out[1]


def highlighted_rows(rows: Iterable[Any], limit: float = Z_LIMIT) -> list[bool]:
    """Per row: highlight it in the table (either z-score outside ``±limit``)."""
    return [any(z_out_of_range(r, limit)) for r in rows]


def _mm(value: Any, digits: int = 1) -> str:
    if not _finite(value):
        return "–"
    text = f"{float(value):.{digits}f}"
    return text[1:] if text.startswith("-") and not text.strip("-0.") else text  # no "-0.00"


def _z(value: Any) -> str:
    if not _finite(value):
        return "–"
    text = f"{float(value):+.2f}"
    return "+" + text[1:] if not text.strip("+-0.") else text


def _norm(mean: Any, sd: Any) -> str:
    return f"{float(mean):.1f} ± {float(sd):.1f}" if _finite(mean) and _finite(sd) else "–"


def measurement_table(result: Any) -> tuple[list[tuple[str, ...]], list[bool]]:
    """One age's measurement rows as text (mm, z) and which print highlighted.

    Columns as :data:`TABLE_HEADERS`; rows in the result's order.  Norms,
    z-scores exist only for rows constrained by norms ("–" elsewhere).
    """
    body: list[tuple[str, ...]] = []
    for r in result.rows:
        normed = r.constraint == "norms"
        body.append(
            (
                r.name,
                f"{r.a}–{r.b}",
                r.kind,
                r.constraint,
                _mm(r.before_mm),
                _norm(r.mean_from, r.sd_from) if normed else "–",
                _norm(r.mean_to, r.sd_to) if normed else "–",
                _z(r.z_before) if normed else "–",
                _z(r.z_after) if normed else "–",
                _mm(r.target_mm),
                _mm(r.after_mm),
                _mm(r.residual_mm, 2) if _finite(r.residual_mm) else "–",
            )
        )
    return body, highlighted_rows(result.rows)


def source_keys(results: Iterable[Any]) -> list[str]:
    """The norms' source keys the rows cite (``row.source``, ``;``-separated), first use first."""
    keys: dict[str, None] = {}
    for r in results:
        for row in r.rows:
            for key in str(getattr(row, "source", "") or "").split(";"):
                if key.strip():
                    keys.setdefault(key.strip(), None)
    return list(keys)


def chart_references(results: Iterable[Any]) -> list[str]:
    """Head-circumference charts used (``"UK90"``, ``"WHO2006"``), from the figures' chart text."""
    refs: dict[str, None] = {}
    for r in results:
        chart = str((r.figures.get("head_circumference_mm") or {}).get("chart", ""))
        for part in chart.split(","):
            name = part.strip().split(" at ")[0].strip()
            if name:
                refs.setdefault(name, None)
    return list(refs)


def _strings(value: Any) -> Iterable[str]:
    if isinstance(value, str):
        yield value
    elif isinstance(value, Mapping):
        for k, v in value.items():
            yield str(k)
            yield from _strings(v)
    elif isinstance(value, list | tuple):
        for v in value:
            yield from _strings(v)


def provenance_credits(provenance: Mapping[str, Any], credited: Mapping[str, str]) -> list[str]:
    """The credit lines a head's provenance calls for.

    ``credited`` maps a needle (a SHA-256, a file name, a sample name or a
    phrase such as "visible human", matched case-insensitively as a
    substring of any string or key in the provenance, nested anywhere) to
    the credit line that data must carry.  Returns each credit once, in the
    order of ``credited``.
    """
    text = "\n".join(_strings(provenance)).lower()
    out: dict[str, None] = {}
    for needle, credit in credited.items():
        if needle and needle.lower() in text:
            out.setdefault(credit, None)
    return list(out)


def _ages_text(results: Sequence[Any]) -> str:
    return ", ".join(f"{r.to_age:g}" for r in results) + " y"


def _summary_rows(results: Sequence[Any]) -> list[tuple[str, ...]]:
    rows: list[tuple[str, ...]] = []
    for r in results:
        f = r.figures
        hc = f.get("head_circumference_mm") or {}
        res = f.get("hard_residual_mm") or {}
        inside = f.get("face_skin_inside_skull_vertices")
        inside_after = inside.get("after") if isinstance(inside, Mapping) else inside
        rows.append(
            (
                f"{r.from_age:g} → {r.to_age:g}",
                f"{float(f['global_scale']):.4f}" if _finite(f.get("global_scale")) else "–",
                f"{_mm(hc.get('before'))} → {_mm(hc.get('after'))} ({_mm(hc.get('target'))})",
                f"{_z(hc.get('z_before'))} → {_z(hc.get('z_after'))}",
                str(hc.get("chart", "–")),
                f"{_mm(res.get('median'), 3)} / {_mm(res.get('max'), 3)}",
                f"{float(f['z_change_max']):.3f}" if _finite(f.get("z_change_max")) else "–",
                f"{f.get('fold_overs', '–')} / {'–' if inside_after is None else inside_after}",
            )
        )
    return rows


def _without_norms(result: Any) -> list[tuple[str, list[str]]]:
    """Rows not constrained by norms, grouped by the reason (note), the unconstrained first."""
    groups: dict[tuple[int, str], list[str]] = {}
    for row in result.rows:
        if row.constraint == "norms":
            continue
        first = 0 if row.constraint == "unconstrained" else 1
        why = row.note or CONSTRAINTS.get(row.constraint, row.constraint)
        label = "unconstrained: " + why if first == 0 else why
        named = row.name if ":" in row.name else f"{row.name} ({row.a}–{row.b})"
        groups.setdefault((first, label), []).append(named)
    return [(label, names) for (_, label), names in sorted(groups.items())]


def write_age_report(
    folder: str | Path,
    source_head: Any,
    results: Sequence[Any],
    pictures: Mapping[str, Path] | None = None,
    notes: Sequence[str] = (),
    software: str = "workbench",
    *,
    citations: Mapping[str, str] | None = None,
    credits: Sequence[str] = (),
    created: str | None = None,
) -> Path:
    """Write ``folder/report.pdf`` for ``results`` (:class:`~workbench.services.age.change.AgeResult`).

    ``source_head`` is the head before the change (its ``template_id`` and
    ``content_hash`` are printed); ``pictures`` maps ``compare_<age>y`` and
    ``growth_<age>y`` (from :func:`workbench.render.age_pictures.render_age_pictures`)
    to PNG files; ``notes`` (e.g. "no OpenGL: no pictures") print where the
    pictures would be; ``citations`` maps each norms source key and chart
    name to its full citation (a key without one prints as the key);
    ``credits`` are data credit lines the source head must carry.  Written
    atomically (``report.pdf.part`` then renamed).
    """
    from workbench.reporting.pdf import ReportPDF
    from workbench.reporting.report import utc_now

    if not results:
        raise ValueError("no age results to report")
    created = created or utc_now()
    case = str(getattr(source_head, "template_id", "head"))
    pdf = ReportPDF(case, created, software)
    pdf.set_title(f"Age change report, {case}")
    _title_page(pdf, source_head, results, case, created, software)
    _summary_section(pdf, results)
    # the warnings close the report, in full; page 1 says how many there are
    warnings = list(dict.fromkeys(f"{r.to_age:g} y: {w}" for r in results for w in r.warnings))
    link = pdf.add_link()
    pdf.notes_pointer(len(warnings), link, " on the change in age")
    _measurement_pages(pdf, results)
    _picture_pages(pdf, results, dict(pictures or {}), notes)
    _references(pdf, results, dict(citations or {}), credits)
    if warnings:
        pdf.notes_appendix([("", warnings)], NOTES_INTRO, link)
    path = Path(folder) / "report.pdf"
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".part")
    pdf.output(str(tmp))
    tmp.replace(path)
    return path


def _title_page(
    pdf: ReportPDF,
    source_head: Any,
    results: Sequence[Any],
    case: str,
    created: str,
    software: str,
) -> None:
    """First page: title, the change in ages, provenance, units, frame and method."""
    from workbench.reporting.pdf import ACCENT, DARK

    first = results[0]
    fig0 = first.figures
    pdf.add_page()
    pdf.font(17, "B")
    pdf.set_text_color(*ACCENT)
    pdf.cell(0, 9, pdf.t("Age change of a head"), new_x="LMARGIN", new_y="NEXT")
    pdf.font(12)
    pdf.set_text_color(*DARK)
    pdf.cell(
        0,
        7,
        pdf.t(f"{first.sex}, {first.from_age:g} y → {_ages_text(results)}"),
        new_x="LMARGIN",
        new_y="NEXT",
    )
    pdf.ln(2)
    pairs: list[tuple[str, Any]] = [
        ("Source head", case),
        ("Content hash", str(getattr(source_head, "content_hash", "–"))),
        ("Sex", first.sex),
        ("Source age", f"{first.from_age:g} y"),
        ("Target age(s)", _ages_text(results)),
        ("Norms", f"{fig0.get('norms', '–')}, ethnicity {fig0.get('ethnicity', '–')}"),
        ("Created (UTC)", created),
        ("Software", software),
        ("Units", UNITS),
        ("Frame", FRAME),
        ("Method", METHOD),
    ]
    pdf.key_values(pairs, key_width=30, mono_keys=frozenset({"Content hash"}))


def _summary_section(pdf: ReportPDF, results: Sequence[Any]) -> None:
    """The table of key figures per target age (mm, z) and what they mean."""
    from workbench.reporting.pdf import GREY

    pdf.heading("Summary per target age")
    pdf.grid(
        (
            "age (y)",
            "global scale",
            "head circ. before → after (target), mm",
            "z head circ.",
            "chart",
            "hard residual median / max, mm",
            "max |Δz|",
            "fold-overs / skin in skull",
        ),
        _summary_rows(results),
        (15, 15, 36, 22, 28, 24, 14, 26),
        aligns=("L", "R", "R", "R", "L", "R", "R", "R"),
        size=7.5,
    )
    pdf.para(
        "Global scale: the head circumference's change at its kept z-score; measurements "
        "without norms follow it. Hard residual: |after − target| over the measurements with "
        "norms (the issue's target: median ≤ 0.5 mm, max ≤ 2 mm). max |Δz|: the largest change "
        "of a z-score between the ages (target ≤ 0.1). Skin in skull: face skin vertices "
        "inside the aged skull.",
        size=7.5,
        color=GREY,
    )


def _measurement_pages(pdf: ReportPDF, results: Sequence[Any]) -> None:
    """The measurement tables, one per target age, on landscape pages (mm, z-scores).

    Rows with a z-score outside ±:data:`Z_LIMIT` print highlighted; the rows
    without norms at both ages are listed after each table with the reason.
    """
    from fpdf import FontFace

    from workbench.reporting.pdf import GREY

    fig0 = results[0].figures
    marked = FontFace(
        family=pdf.sans,
        emphasis="B" if "B" in pdf.styles else None,
        color=HIGHLIGHT_TEXT,
        fill_color=HIGHLIGHT_FILL,
    )
    for r in results:
        pdf.add_page(orientation="L")
        pdf.heading(f"Measurements, {r.from_age:g} → {r.to_age:g} y ({r.sex})")
        pdf.para(
            "Values in mm: before = the source head, target = what the method asked for, "
            "after = measured on the aged head, residual = after − target. Norm = mean ± SD "
            f"of the {fig0.get('norms', '')} norms ({r.sex}, {fig0.get('ethnicity', '')}). "
            f"Highlighted: a z-score outside ±{Z_LIMIT:g}, the norms' usual range "
            "(about 95 % of people lie within it). Constraint: "
            + "; ".join(f"{k} = {v}" for k, v in CONSTRAINTS.items())
            + ".",
            size=7.5,
            color=GREY,
        )
        body, flags = measurement_table(r)
        pdf.grid(
            TABLE_HEADERS,
            body,
            TABLE_WIDTHS,
            aligns=TABLE_ALIGNS,
            styles=[marked if f else None for f in flags],
            size=7,
        )
        n_flag = sum(flags)
        pdf.para(
            f"{n_flag} of {sum(1 for x in r.rows if x.constraint == 'norms')} measurements "
            f"with norms have a z-score outside ±{Z_LIMIT:g}.",
            size=8,
        )
        groups = _without_norms(r)
        if groups:
            pdf.subheading("Measurements without norms at both ages, and why")
            for label, names in groups:
                pdf.para(f"{label}: " + ", ".join(names), size=7.5)
                pdf.ln(0.5)


def _picture_pages(
    pdf: ReportPDF, results: Sequence[Any], pics: Mapping[str, Path], notes: Sequence[str]
) -> None:
    """The comparison and growth-displacement pictures per target age, with their legends.

    ``notes`` print where the pictures would be (e.g. no OpenGL).
    """
    from workbench.reporting.pdf import GREY

    if pics or notes:
        pdf.add_page(orientation="P")
        pdf.heading("Pictures")
    for r in results:
        tag = f"{r.to_age:g}y"
        compare, growth = pics.get(f"compare_{tag}"), pics.get(f"growth_{tag}")
        if compare is not None:
            pdf.pictures(
                [(f"source {r.from_age:g} y and aged {r.to_age:g} y, same scale", Path(compare))],
                columns=1,
            )
            pdf.para(
                f"Source head ({r.from_age:g} y) and aged head ({r.to_age:g} y), front and "
                "right side, orthographic, every panel at the same scale and focus (the "
                "labelled bar in the first panel gives it in mm), so the size change shows as "
                "it is.",
                size=7.5,
                color=GREY,
            )
            pdf.ln(1)
        if growth is not None:
            pdf.pictures(
                [(f"growth displacement {r.from_age:g} → {r.to_age:g} y, mm", Path(growth))],
                columns=1,
            )
            pdf.para(
                "Growth displacement (mm): the aged skin coloured by its distance to the "
                "source skin, both heads in their Frankfort frames aligned at the Frankfort "
                "origin (between the porions), no other registration. Blue: the aged skin lies "
                "inside the source skin (smaller there); red: outside (grown); the colour bar "
                "is in mm. Grey behind: the source skin where it is larger.",
                size=7.5,
                color=GREY,
            )
            pdf.ln(1)
    for note in notes:
        pdf.para(f"Note: {note}", size=8, color=GREY)


def _references(
    pdf: ReportPDF, results: Sequence[Any], cite: Mapping[str, str], credits: Sequence[str]
) -> None:
    """References (norms' sources, head-circumference charts, the method) and data credits."""
    pdf.heading("References", min_space=40)
    keys = source_keys(results)
    if keys:
        pdf.subheading("Facial norms")
        for key in keys:
            pdf.para(f"[{key}] {cite.get(key, key)}", size=7.5)
            pdf.ln(0.5)
    charts = chart_references(results)
    if charts:
        pdf.subheading("Head circumference")
        for name in charts:
            pdf.para(f"[{name}] {cite.get(name, name)}", size=7.5)
            pdf.ln(0.5)
    pdf.subheading("Method")
    pdf.para(
        "Kähler K (2003) A Head Model with Anatomical Structure for Facial Modeling and "
        "Animation. Dr.-Ing. dissertation, Universität des Saarlandes, Saarbrücken, §8.5 "
        "(growth and aging) and Table 8.2.",
        size=7.5,
    )
    if credits:
        pdf.heading("Data credits", min_space=20)
        for c in credits:
            pdf.para(c, size=8)
