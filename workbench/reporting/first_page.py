"""Page 1 of the reconstruction report and its closing appendix (issue 33).

Page 1 leads with the result: the face and the fit's key figures, then a short
"Before use" box holding only what a reader must act on (the registration's
self-check doubting the result, skin left inside the bone, a large share of
the face inferred, dowel tips missed).  Every warning of the report follows
in full, sorted into a few groups, in "Appendix: technical notes" at the end.
:mod:`workbench.reporting.report` calls these while laying out the PDF; mm
throughout.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from workbench.reporting.pdf import ReportPDF, num

#: (figure in the report's ``fit`` section, its words on page 1, unit); the pipeline's
#: ``FIT_FIGURES`` are all here (landmark counts in one row)
KEY_FIGURES = (
    ("max_tip_error_mm", "largest dowel-tip miss", "mm"),
    ("min_tissue_mm", "thinnest soft tissue", "mm"),
    ("penetrating_vertices", "skin vertices inside bone", ""),
    ("refits", "refits (skin out of bone)", ""),
)
#: a face inferred (no bone under it) over at least this share goes in "Before use"
INFERRED_BEFORE_USE = 0.10
#: a dowel tip missed by more than this (mm) goes in "Before use"
TIP_ERROR_BEFORE_USE = 2.0


def figure_rows(report: dict[str, Any]) -> list[tuple[str, str]]:
    """The key figures of page 1 as (words, value) rows."""
    fit = report.get("fit") or {}
    rows = [
        (words, f"{num(fit.get(key), 2 if unit else 1)} {unit}".strip())
        for key, words, unit in KEY_FIGURES
        if key in fit
    ]
    counts = {k: fit.get(f"{k}_landmarks") for k in ("placed", "suggested", "absent")}
    if any(v is not None for v in counts.values()):
        rows.append(
            (
                "skull landmarks",
                ", ".join(f"{num(v)} {k}" for k, v in counts.items() if v is not None),
            )
        )
    observed = (report.get("inferred") or {}).get("face_observed_fraction")
    if observed is not None:
        rows.append(
            (
                "face over bone",
                f"{100 * observed:.0f} % ({100 * (1 - observed):.0f} % inferred)",
            )
        )
    check = (report.get("self_check") or {}).get("outcome")
    if check:
        rows.append(("self-check", "CHECK (see Before use)" if check == "check" else check))
    spread = (report.get("ensemble") or {}).get("spread_mm")
    if spread:
        rows.append(
            ("ensemble spread", f"median {num(spread['median'])} mm, p90 {num(spread['p90'])} mm")
        )
    v = report.get("validation")
    if v:
        rows.append(
            (
                "against the known face",
                f"mean |d| {num(v.get('mean_abs_mm'))} mm; "
                f"{num(v.get('pct_within_2_5mm'))} % within 2.5 mm",
            )
        )
    return rows


def key_figures(pdf: ReportPDF, report: dict[str, Any], wide: bool) -> None:
    """The key figures: in two pairs of columns across the page (``wide``), else one pair."""
    rows = figure_rows(report)
    if not rows:
        return
    if wide:
        half = (len(rows) + 1) // 2
        paired = [
            (*rows[i], *(rows[half + i] if half + i < len(rows) else ("", ""))) for i in range(half)
        ]
        pdf.grid((), paired, (42, 48, 36, 54), aligns=("L", "R", "L", "R"), size=8.5)
    else:
        width = pdf.w - pdf.r_margin - pdf.l_margin
        pdf.grid((), rows, (width * 0.55, width * 0.45), aligns=("L", "R"), size=8.5)


def face_and_figures(pdf: ReportPDF, report: dict[str, Any], front: Path | None) -> None:
    """Page 1 without build faces: the face's front view, the key figures beside it."""
    pdf.heading("The reconstructed face and key figures", min_space=70 if front else 25)
    if front is None:
        key_figures(pdf, report, wide=True)
        return
    margin, top, left = pdf.l_margin, pdf.get_y(), 72.0
    bottom = pdf.picture_at(margin, top, left, "front view (see the 50 mm bar)", front)
    pdf.set_left_margin(margin + left + 6.0)
    pdf.set_xy(pdf.l_margin, top)
    try:
        key_figures(pdf, report, wide=False)
    finally:
        pdf.set_left_margin(margin)
    pdf.set_xy(margin, max(bottom, pdf.get_y()))


def before_use(report: dict[str, Any]) -> tuple[list[str], bool]:
    """What a reader must act on before using the face, as sentences, and whether the
    registration's self-check doubts it (then its reasons come first)."""
    check = report.get("self_check") or {}
    doubt = check.get("outcome") == "check"
    items = []
    if doubt:
        reasons = "; ".join(str(r) for r in check.get("reasons") or ()) or "no reason given"
        items.append(
            f"The registration's self-check doubts this reconstruction: {reasons}. "
            "Confirm the orientation and the skull landmarks before use."
        )
    fit = report.get("fit") or {}
    others = []
    if fit.get("penetrating_vertices"):
        others.append(
            f"{fit['penetrating_vertices']} skin vertices still lie inside the bone: look at "
            "the face over the skull before use."
        )
    observed = (report.get("inferred") or {}).get("face_observed_fraction")
    if observed is not None and round(1 - observed, 2) >= INFERRED_BEFORE_USE:
        others.append(
            f"{100 * (1 - observed):.0f} % of the face lies over bone missing from the skull "
            "and is taken from the reference head, not from this skull (marked in the "
            "pictures): treat that part as a guess."
        )
    tip = fit.get("max_tip_error_mm")
    if isinstance(tip, int | float) and tip > TIP_ERROR_BEFORE_USE:
        others.append(
            f"The skin misses a dowel tip by up to {num(tip)} mm: the tissue depths are not "
            "all met; see the landmark table."
        )
    return items + others[:3], doubt


def before_use_box(pdf: ReportPDF, report: dict[str, Any], link: int) -> None:
    """The "Before use" box (red when the self-check doubts the registration, issue 28)
    and a line pointing to the appendix with every technical note."""
    items, doubt = before_use(report)
    if items:
        title = (
            "Before use: CHECK THIS RECONSTRUCTION (the registration's self-check)"
            if doubt
            else "Before use"
        )
        pdf.box(title, items, fill=(255, 205, 205) if doubt else (255, 243, 205))
    pdf.notes_pointer(len(report.get("warnings") or ()), link, " on the inputs and the fit")


#: the appendix's groups: (title, words that put a note in it); the rest go under "The fit"
NOTE_GROUPS = (
    ("The skull file", ("skull mesh", "working skull", "bone surface", "units", "mirrored")),
    ("Guides and feature rules", ("guide", " rule ")),
    ("Landmarks and tissue depths", ("dowel", "depth", "landmark", "table ")),
)


def note_groups(warnings: list[str]) -> list[tuple[str, list[str]]]:
    """The report's warnings sorted into the appendix's groups (in their order within each)."""
    groups: dict[str, list[str]] = {title: [] for title, _ in NOTE_GROUPS}
    groups["The fit and the face"] = []
    order = ("The skull file", "Landmarks and tissue depths", "Guides and feature rules")
    for note in warnings:
        low = f" {str(note).lower()} "
        title = next(
            (t for t, words in NOTE_GROUPS if any(w in low for w in words)),
            "The fit and the face",
        )
        groups[title].append(str(note))
    return [(t, groups[t]) for t in (*order, "The fit and the face") if groups[t]]


def appendix(pdf: ReportPDF, report: dict[str, Any], link: int) -> None:
    """The closing "Appendix: technical notes": every warning of ``report``, grouped;
    ``link`` (page 1's pointer) is set to it."""
    warnings = [str(w) for w in report.get("warnings") or ()]
    if not warnings:
        return
    pdf.notes_appendix(
        note_groups(warnings),
        "Everything the software noted while opening the inputs and fitting the face, in "
        "full. What must be acted on before use is also on page 1.",
        link,
    )
