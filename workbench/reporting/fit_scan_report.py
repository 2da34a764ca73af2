"""The PDF of ``workbench fit-scan`` (issue 13): key figures of the fit and the distance maps.

Units mm and per cent; frame: the fitted person's head frame (x to the
subject's left, x = 0 midsagittal, y up, z toward the face, Frankfort
Horizontal at y = 0), as in :mod:`workbench.services.scan_fit.fit`.

Two steps, so the layout can be tested without a fit:

* :func:`fit_scan_summary` turns a :class:`~workbench.services.scan_fit.settings.ScanFit`
  into a plain, JSON-able dict (provenance, the figure rows beside the
  issue's targets, warnings, per-landmark tables);
* :func:`write_fit_scan_pdf` lays that dict out with the look of the other
  reports (:mod:`workbench.reporting.pdf`) and adds the pictures (PNG paths
  from :mod:`workbench.render.scan_fit_pictures`, drawn by the caller).

Page 1 holds the provenance and the key figures; the warnings close the PDF
in full, in "Appendix: technical notes" (issue 33).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Final

#: issue 13's targets: share of the counted face-region scan vertices within 1 / 2.5 mm
TARGET_WITHIN_1MM: Final = 0.95
TARGET_WITHIN_2_5MM: Final = 0.99
UNITS: Final = "mm (every length in this report); shares in per cent"
FRAME: Final = (
    "the fitted person's head frame: x to the subject's left, x = 0 midsagittal, y up, "
    "z toward the face; Frankfort Horizontal (estimated skull's porions and orbitales) at y = 0"
)
COUNTED: Final = (
    "Counted: scan vertices whose nearest fitted-skin vertex lies in the face region, more "
    "than 4 mm from a hole or scan rim, seen from outside, believed to be the head and not "
    "on a thin sheet over the skin (a cord or strap over the face, hair); for each, the distance to the fitted skin surface."
)
NOTES_INTRO: Final = (
    "Everything the software noted while reading the scan and fitting the reference head, in full."
)
#: captions and legends of the pictures (keys of :func:`render_scan_fit_pictures`)
PICTURES: Final = {
    "distance": (
        "Distance of each scan vertex to the fitted skin (mm), front, left and right",
        "Pale yellow: on the fitted skin; darkest red: 2.5 mm or more. Grey: not counted "
        "(outside the face region, near a hole or scan rim, a cavity wall, not the head, a "
        "thin sheet over the skin). "
        "White through the scan: a hole.",
    ),
    "signed": (
        "Signed distance (mm): which side of the fitted skin the scan lies on",
        "Red: the scan lies outside the fitted skin (the fit is too shallow there); blue: "
        "inside (the fit stands proud). Sign from the fitted skin's outward normal at the "
        "closest point. Grey: not counted.",
    ),
    "histogram": (
        "Distances of the counted scan vertices (log count) with the 1 mm and 2.5 mm lines",
        "",
    ),
}


def _pct(share: Any) -> str:
    return "–" if share is None else f"{100.0 * float(share):.1f} %"


def _mm(value: Any, digits: int = 2) -> str:
    return "–" if value is None else f"{float(value):.{digits}f} mm"


def fit_scan_summary(result: Any, scan_name: str) -> dict[str, Any]:
    """The report's content from a ``ScanFit`` (mm, shares 0..1 turned into per cent text).

    Keys: ``scan``, ``template_id``, ``base_template``, ``inputs`` (role, file,
    sha256), ``frame``, ``units``, ``mirrored_input``, ``rows`` (figure,
    value, target, met: True/False/None), ``warnings``, ``depths`` (code,
    table mm, fitted mm) with ``depth_table`` / ``depth_group``, and
    ``user_landmarks`` (code, mm) when landmarks were placed.
    """
    fig: Mapping[str, Any] = result.figures
    prov: Mapping[str, Any] = result.head.provenance or {}
    rows: list[dict[str, Any]] = []
    _distance_rows(rows, fig)
    _integrity_rows(rows, fig)
    if fig.get("detail"):
        _detail_rows(rows, fig["detail"])
    _landmark_rows(rows, fig)
    _depth_and_bone_rows(rows, fig)
    _orientation_rows(rows, fig, bool(result.mirrored_input))
    depths = fig["tissue_depths"]
    user = fig.get("skin_landmark_to_user_mm")
    per = depths.get("per_landmark") or {}
    base = prov.get("base_template") or {}
    return {
        "scan": scan_name,
        "template_id": result.head.template_id,
        "base_template": f"{base.get('template_id', '–')} ({base.get('content_hash', '–')})"
        if base
        else "–",
        "inputs": [
            {"role": i.get("role", ""), "file": i.get("file", ""), "sha256": i.get("sha256", "")}
            for i in prov.get("built_from") or []
        ],
        "frame": FRAME,
        "units": UNITS,
        "mirrored_input": bool(result.mirrored_input),
        "rows": rows,
        "warnings": list(result.warnings),
        "depth_table": depths["table"],
        "depth_group": depths["group"],
        "depths": [
            {"code": c, "table_mm": float(v["table_mm"]), "fitted_mm": float(v["fitted_mm"])}
            for c, v in per.items()
        ],
        "user_landmarks": [
            {"code": c, "mm": float(g)} for c, g in ((user or {}).get("per_landmark") or {}).items()
        ],
    }


def _row(
    rows: list[dict[str, Any]], figure: str, value: str, target: str = "", met: bool | None = None
) -> None:
    """Append one figure row: its text value, the target (text) and whether it is met."""
    rows.append({"figure": figure, "value": value, "target": target, "met": met})


def _distance_rows(rows: list[dict[str, Any]], fig: Mapping[str, Any]) -> None:
    """Rows of the scan, the counted face region and the scan-to-skin distances (mm, %)."""
    if "scan_vertices" in fig:
        _row(
            rows,
            "Scan",
            f"{fig['scan_vertices']} vertices, {fig.get('scan_triangles', '–')} triangles",
        )
    hidden = fig.get("face_region_hidden_vertices")
    not_head = fig.get("face_region_not_head_vertices")
    sheets = fig.get("face_region_sheet_vertices")
    left_out = [
        f"{n} {what}"
        for n, what in (
            (hidden, "cavity walls"),
            (not_head, "not the head"),
            (sheets, "thin sheets over the skin"),
        )
        if n
    ]
    _row(
        rows,
        "Face-region scan vertices counted",
        str(fig["face_region_vertices"])
        + (f" (also left out: {', '.join(left_out)})" if left_out else ""),
    )
    w1, w25 = fig["face_within_1mm_fraction"], fig["face_within_2_5mm_fraction"]
    _row(
        rows,
        "Within 1 mm of the fitted skin",
        _pct(w1),
        f"≥ {_pct(TARGET_WITHIN_1MM)}",
        w1 >= TARGET_WITHIN_1MM,
    )
    _row(
        rows,
        "Within 2.5 mm of the fitted skin",
        _pct(w25),
        f"≥ {_pct(TARGET_WITHIN_2_5MM)}",
        w25 >= TARGET_WITHIN_2_5MM,
    )
    _row(
        rows,
        "Distance scan → fitted skin, mean / median",
        f"{_mm(fig.get('face_mean_distance_mm'))} / {_mm(fig.get('face_median_distance_mm'))}",
    )
    back = fig.get("face_skin_to_scan_mm")
    if back:
        _row(
            rows,
            "Fitted face skin → scan (where on the scan)",
            f"mean {_mm(back.get('mean'))}, p95 {_mm(back.get('p95'))}, "
            f"{_pct(back.get('within_2_5mm_fraction'))} within 2.5 mm (n = {back.get('n')})",
        )
    if "face_on_scan_fraction" in fig:
        inferred = fig.get("inferred")
        _row(
            rows,
            "Face skin supported by the scan",
            _pct(fig["face_on_scan_fraction"])
            + (
                f"; {_pct(inferred['face_inferred_fraction'])} inferred from the reference "
                "head (the pack's region 'inferred')"
                if inferred
                else ""
            ),
        )


def _integrity_rows(rows: list[dict[str, Any]], fig: Mapping[str, Any]) -> None:
    """Rows of the fitted skin's fold-overs, self-intersections and the fit's self-check."""
    folds = int(fig["fold_overs"])
    _row(rows, "Fold-overs (triangles turned over)", str(folds), "0", folds == 0)
    if "fold_overs_outside_mouth_corner_seam" in fig:
        off = int(fig["fold_overs_outside_mouth_corner_seam"])
        _row(
            rows,
            "… outside the reference's mouth-corner seam",
            f"{off} (the rest are the reference skin's own sliver triangles there)",
            "0",
            off == 0,
        )
    cross = fig.get("self_intersections")
    if cross:
        new = int(cross.get("new_pairs", 0))
        _row(
            rows,
            "Self-intersections added by the fit",
            f"{new} crossing triangle pairs ({cross.get('pairs')} in all; the reference skin "
            f"has {cross.get('reference_pairs')} at the mouth corners)",
            "0",
            new == 0,
        )
    check = fig.get("self_check")
    if check and check.get("outcome") == "check":
        _row(
            rows,
            "Self-check",
            "check before use: " + "; ".join(check.get("reasons", ())),
            "",
            False,
        )


def _detail_rows(rows: list[dict[str, Any]], detail: Mapping[str, Any]) -> None:
    """Rows of the fine-detail skin (``skin_detailed.ply``): distances (mm, %) and defects."""
    d1, d25 = detail["face_within_1mm_fraction"], detail["face_within_2_5mm_fraction"]
    _row(
        rows,
        "Fine detail (skin_detailed.ply): within 1 / 2.5 mm",
        f"{_pct(d1)} / {_pct(d25)}, mean {_mm(detail.get('face_mean_distance_mm'))} "
        f"({detail['fine_vertices']} vertices, {detail['levels']} Loop steps over the "
        f"fitted skin; {_pct(detail.get('face_observed_fraction'))} of its face saw the scan)",
        f"≥ {_pct(TARGET_WITHIN_1MM)} / {_pct(TARGET_WITHIN_2_5MM)}",
        d1 >= TARGET_WITHIN_1MM and d25 >= TARGET_WITHIN_2_5MM,
    )
    beyond = detail.get("face_over_skin_openings_vertices")
    if beyond:
        _row(
            rows,
            "… scan over the skin's eye, mouth, nostril openings",
            f"{beyond} vertices (closed eyes or mouth on the scan); within 2.5 mm "
            f"without them {_pct(detail.get('face_within_2_5mm_fraction_off_openings'))}",
        )
    bad = int(detail["fold_overs"]) + int(detail["new_crossings"])
    _row(
        rows,
        "… fold-overs / crossings it added",
        f"{detail['fold_overs']} / {detail['new_crossings']}",
        "0",
        bad == 0,
    )


def _landmark_rows(rows: list[dict[str, Any]], fig: Mapping[str, Any]) -> None:
    """Rows of the scan left out as cavity walls and of the skin landmarks' distances (mm)."""
    if fig.get("face_region_hidden_vertices"):
        _row(
            rows,
            "Scan left out: cavity walls no scanner sees",
            f"{fig['face_region_hidden_vertices']} vertices (airway, mouth, nostrils)",
        )
    lm = fig.get("skin_landmark_to_scan_mm") or {}
    absent = list(lm.get("absent") or [])
    _row(
        rows,
        "Skin landmarks → scan",
        f"mean {_mm(lm.get('mean'))}, max {_mm(lm.get('max'))} (n = {lm.get('n', 0)}"
        + (f"; over no scan: {', '.join(absent)})" if absent else ")"),
    )
    user = fig.get("skin_landmark_to_user_mm")
    _row(
        rows,
        "Skin landmarks → user-placed",
        f"mean {_mm(user['mean'])}, max {_mm(user['max'])} (n = {len(user.get('per_landmark', {}))})"
        if user
        else "none placed",
    )


def _depth_and_bone_rows(rows: list[dict[str, Any]], fig: Mapping[str, Any]) -> None:
    """Rows of the tissue depths against the table, skin inside the skull and the true bone."""
    depths = fig["tissue_depths"]
    _row(
        rows,
        "Tissue depths vs the table",
        f"mean |fitted − table| {_mm(depths['mean_abs_diff_mm'])}, max "
        f"{_mm(depths.get('max_abs_diff_mm'))} over {depths['pairs']} pairs "
        f"({depths['table']}, {depths['group']})",
    )
    if "face_skin_inside_skull_vertices" in fig:
        inside = int(fig["face_skin_inside_skull_vertices"])
        _row(rows, "Face skin vertices inside the skull", str(inside), "0", inside == 0)
    bone = fig.get("skull_vs_bone")
    _row(
        rows,
        "Estimated skull vs true bone (face region)",
        f"mean |d| {_mm(bone.get('mean_abs_mm'))}, {_pct(bone.get('within_2_5mm_fraction'))} "
        f"within 2.5 mm (n = {bone.get('face_skull_vertices', '–')})"
        if bone
        else "no bone given",
    )
    base = (bone or {}).get("uniform_offset_baseline")
    if bone and base:
        _row(
            rows,
            f"Baseline: face skin {base['depth_mm']:g} mm inward vs true bone",
            f"mean |d| {_mm(base.get('mean_abs_mm'))}, {_pct(base.get('within_2_5mm_fraction'))} "
            f"within 2.5 mm (n = {base.get('face_skin_vertices', '–')})",
            "the estimated skull beats it",
            bone.get("within_2_5mm_fraction", 0.0) > base.get("within_2_5mm_fraction", 1.0),
        )


def _orientation_rows(rows: list[dict[str, Any]], fig: Mapping[str, Any], mirrored: bool) -> None:
    """Rows of the orientation search, the face placement, mirroring and the run time (s)."""
    orient = fig.get("orientation") or {}
    _row(
        rows,
        "Orientation",
        f"{orient.get('method', '–')}, {orient.get('handedness', '–')}; reference scaled "
        f"{orient.get('reference_scale', '–')}; matched {_pct(orient.get('matched_fraction'))}",
    )
    placed = orient.get("face_placement")
    if placed:
        near = placed.get("face_within_5mm_fraction")
        _row(
            rows,
            "Reference face laid on the scan",
            f"{_pct(near)} of its vertices within 5 mm of the scan"
            + (" (moved from the search's pose)" if placed.get("moved") else ""),
            "> 50 %",
            near is not None and float(near) > 0.5,
        )
    _row(rows, "Mirrored input", "yes" if mirrored else "no")
    secs = dict(fig.get("seconds") or {})
    total = secs.pop("total", None)
    _row(
        rows,
        "Seconds",
        ("–" if total is None else f"{float(total):.1f}")
        + (" (" + ", ".join(f"{k} {float(v):.1f}" for k, v in secs.items()) + ")" if secs else ""),
    )


def write_fit_scan_pdf(
    summary: Mapping[str, Any],
    path: str | Path,
    pictures: Mapping[str, Path] | None = None,
    *,
    notes: Sequence[str] = (),
    software: str = "workbench",
    created: str | None = None,
) -> Path:
    """Write the A4 PDF of ``summary`` (from :func:`fit_scan_summary`) to ``path`` atomically.

    ``pictures`` maps "distance", "signed", "histogram" (any subset) to PNG
    files; ``notes`` (e.g. "no OpenGL: no pictures") are printed where the
    pictures would be.
    """
    from workbench.reporting.pdf import ACCENT, DARK, GREY, ReportPDF
    from workbench.reporting.report import utc_now

    created = created or utc_now()
    pdf = ReportPDF(summary["scan"], created, software)
    pdf.set_title(f"Scan fit report, {summary['scan']}")
    pdf.add_page()
    pdf.font(17, "B")
    pdf.set_text_color(*ACCENT)
    pdf.cell(0, 9, pdf.t("Reference head fitted to a scan"), new_x="LMARGIN", new_y="NEXT")
    pdf.font(12)
    pdf.set_text_color(*DARK)
    pdf.cell(0, 7, pdf.t(f"Scan {summary['scan']}"), new_x="LMARGIN", new_y="NEXT")
    pdf.ln(2)
    pairs: list[tuple[str, Any]] = [
        ("Scan file", summary["scan"]),
        ("Created (UTC)", created),
        ("Software", software),
        ("Template", summary["template_id"]),
        ("Fitted from", summary["base_template"]),
        ("Mirrored input", "yes" if summary["mirrored_input"] else "no"),
        ("Units", summary["units"]),
        ("Frame", summary["frame"]),
    ]
    sha_keys = set()
    for item in summary["inputs"]:
        key = f"SHA-256 {item['role']}"
        pairs.append((key, f"{item['sha256']}  {item['file']}"))
        sha_keys.add(key)
    pdf.key_values(pairs, key_width=34, mono_keys=frozenset(sha_keys))

    pdf.heading("Key figures")
    pdf.para(COUNTED, size=8, color=GREY)
    # a missed target prints in bold red (the row), the rest in the usual dark grey
    missed = pdf.face("B", color=(170, 40, 20))
    styles = [missed if r["met"] is False else None for r in summary["rows"]]
    body = [
        (
            r["figure"],
            r["value"],
            r["target"],
            "" if r["met"] is None else ("met" if r["met"] else "not met"),
        )
        for r in summary["rows"]
    ]
    pdf.grid(
        ("figure", "value", "target", ""),
        body,
        (56, 84, 22, 18),
        aligns=("L", "L", "R", "R"),
        styles=styles,
        size=7.8,
    )
    link = pdf.add_link()
    pdf.notes_pointer(len(summary["warnings"]), link, " on the scan and the fit")

    pics = dict(pictures or {})
    if pics or notes:
        pdf.heading("Distance maps", min_space=90)
    for key in ("distance", "signed", "histogram"):
        if key not in pics:
            continue
        caption, legend = PICTURES[key]
        pdf.pictures([(caption, Path(pics[key]))], columns=1)
        if legend:
            pdf.para(legend, size=7.5, color=GREY)
            pdf.ln(1)
    for note in notes:
        pdf.para(f"Note: {note}", size=8, color=GREY)

    if summary["depths"]:
        pdf.heading("Tissue depths at the paired landmarks", min_space=45)
        pdf.para(
            f"Table {summary['depth_table']}, group {summary['depth_group']}: the table's "
            "depth and the fitted skin-to-skull landmark distance (mm).",
            size=8,
            color=GREY,
        )
        rows = [
            (
                d["code"],
                f"{d['table_mm']:.2f}",
                f"{d['fitted_mm']:.2f}",
                f"{d['fitted_mm'] - d['table_mm']:+.2f}",
            )
            for d in summary["depths"]
        ]
        pdf.grid(
            ("landmark", "table (mm)", "fitted (mm)", "fitted − table"),
            rows,
            (30, 24, 24, 26),
            aligns=("L", "R", "R", "R"),
            size=7.5,
        )
    if summary["user_landmarks"]:
        pdf.heading("Skin landmarks: fitted vs user-placed", min_space=45)
        pdf.grid(
            ("landmark", "distance (mm)"),
            [(u["code"], f"{u['mm']:.2f}") for u in summary["user_landmarks"]],
            (30, 26),
            aligns=("L", "R"),
            size=7.5,
        )
    if summary["warnings"]:
        pdf.notes_appendix([("", summary["warnings"])], NOTES_INTRO, link)
    path = Path(path)
    tmp = path.with_name(path.name + ".part")
    pdf.output(str(tmp))
    tmp.replace(path)
    return path
