"""The tables of ``workbench validate``: CSV, Markdown and PDF (with signed-distance pictures).

Units mm and per cent.  One row per (case, method): the reconstruction
(built-in head, or the reference library leave-one-out, or the identity
test) and the uniform 6 mm offset scored on the same truth points; the
metric is :mod:`workbench.core.face_metric` (``VALIDATION.md``).
"""

from __future__ import annotations

import csv
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from workbench.core.face_metric import TOLERANCES_MM, _pct_key
from workbench.core.table_cells import csv_row, md_cell

FIGURES = (
    "n",
    "mean_abs_mm",
    "rms_mm",
    "signed_mean_mm",
    "signed_sd_mm",
    *(_pct_key(t) for t in TOLERANCES_MM),
    "p95_mm",
)
REGION_FIGURES = ("n", "mean_abs_mm", "signed_mean_mm", _pct_key(2.5), _pct_key(5.0))
PUBLISHED = (
    "Published (% within 2.5 mm): Lee, Wilkinson & Hwang 2012 54-77 %; Miranda et al. "
    "2018 63-74 %; within 5 mm: Wilkinson et al. 2006 75-90 %."
)


def rows(results: Sequence[tuple[Any, str]], region_names: Sequence[str]) -> list[dict[str, Any]]:
    """Flat table rows: case, method, status and every figure (regions as ``region_figure``)."""
    out = []
    for res, label in results:
        if res.status != "ok":
            out.append(
                {"case": res.case_id, "method": label, "status": res.status, "error": res.error}
            )
            continue
        for s in res.scores:
            row: dict[str, Any] = {
                "case": res.case_id,
                "method": s.name,
                "status": "ok",
                "error": "",
                "seconds": round(res.seconds.get("total", 0.0), 1),
            }
            row.update({k: s.figures.get(k) for k in FIGURES})
            for name in region_names:
                fig = s.regions.get(name, {})
                row.update({f"{name}_{k}": fig.get(k) for k in REGION_FIGURES})
            out.append(row)
    return out


def write_csv(table: list[dict[str, Any]], path: Path) -> Path:
    keys: list[str] = []
    for r in table:
        keys += [k for k in r if k not in keys]
    tmp = path.with_name(path.name + ".part")
    with tmp.open("w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=keys)
        w.writeheader()
        for r in table:  # user text (case ids, errors) guarded against spreadsheet formulas
            w.writerow(csv_row({k: ("" if r.get(k) is None else r.get(k)) for k in keys}))
    tmp.replace(path)
    return path


def _fmt(v: Any, digits: int = 1) -> str:
    if v is None or v == "":
        return "–"
    if isinstance(v, float):
        return f"{v:.{digits}f}"
    return str(v)


def feature_table(features: Mapping[str, Mapping[str, float]]) -> list[str]:
    """Markdown lines: per method (the face, the face without guides, each guide rule
    alone) the feature errors in mm (predicted − true for widths and heights;
    distances for points), with the target beside the feature's name."""
    from workbench.services.validation.features import FEATURES, TARGETS_MM

    names = [n for n in FEATURES if any(n in e for e in features.values())]
    head = [f"{n} (≤ {TARGETS_MM[n]:g})" if n in TARGETS_MM else n for n in names]
    out = [
        "Features against the true skin's landmarks (mm):",
        "",
        "| method | " + " | ".join(head) + " |",
        "|---|" + "---|" * len(names),
    ]
    for method, errs in features.items():
        cells = [f"{errs[n]:+.1f}" if n in errs else "–" for n in names]
        out.append(f"| {md_cell(method)} | " + " | ".join(cells) + " |")
    return out


def band_table(band: Mapping[str, Any], region_names: Sequence[str]) -> list[str]:
    """Coverage of the uncertainty band (% of the scored points inside, median half-width mm),
    for the unknown build and for each build given, overall and per region."""
    lines = [
        f"Uncertainty band (95 %): % of the scored true skin inside it (median half-width, mm); "
        f"the main face is the {md_cell(band.get('main'))} one",
        "",
        "| build | all | " + " | ".join(region_names) + " |",
        "|---|---|" + "---|" * len(region_names),
    ]
    for name, fig in band.items():
        if not isinstance(fig, Mapping):
            continue
        cells = [_band_cell(fig)] + [
            _band_cell(fig.get("regions", {}).get(r, {})) for r in region_names
        ]
        lines.append(f"| {md_cell(name)} | " + " | ".join(cells) + " |")
    return lines


def _band_cell(fig: Mapping[str, Any]) -> str:
    if not fig.get("n"):
        return "–"
    return f"{_fmt(100 * fig['coverage'])} ({_fmt(fig['half_width_median_mm'])})"


def band_rows(results: Sequence[tuple[Any, str]]) -> list[dict[str, Any]]:
    """One row per case, band and region (``bands.csv``): coverage and median half-width."""
    out = []
    for res, _label in results:
        band = res.notes.get("band") or {}
        for name, fig in band.items():
            if not isinstance(fig, Mapping):
                continue
            for region, f in [("all", fig), *fig.get("regions", {}).items()]:
                out.append(
                    {
                        "case": res.case_id,
                        "band": name,
                        "region": region,
                        "n": f.get("n"),
                        "coverage": f.get("coverage"),
                        "half_width_median_mm": f.get("half_width_median_mm"),
                    }
                )
    return out


def feature_rows(results: Sequence[tuple[Any, str]]) -> list[dict[str, Any]]:
    """One row per case, method and feature (``features.csv``)."""
    from workbench.services.validation.features import TARGETS_MM

    out = []
    for res, _label in results:
        for method, errs in (res.notes.get("features") or {}).items():
            for name, err in errs.items():
                out.append(
                    {
                        "case": res.case_id,
                        "method": method,
                        "feature": name,
                        "error_mm": round(float(err), 2),
                        "target_mm": TARGETS_MM.get(name, ""),
                    }
                )
    return out


def markdown(
    results: Sequence[tuple[Any, str]], region_names: Sequence[str], credits: Sequence[str] = ()
) -> str:
    """The summary as Markdown: one table over all cases, then regions per case."""
    lines = [
        "# Validation: reconstruction vs uniform 6 mm offset",
        "",
        "Metric: `VALIDATION.md` (outermost, anterior-facing true-skin vertices in front of "
        "the bone centre and within 35 mm of the bone; distance to the reconstructed "
        "surface; positive = reconstruction outside the true skin). mm and %.",
        "",
        PUBLISHED,
        "",
        "| case | method | n | mean \\|d\\| | signed mean ± SD | % ≤ 1 | % ≤ 2.5 | % ≤ 5 | "
        "p95 | s |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for res, label in results:
        if res.status != "ok":
            lines.append(
                f"| {md_cell(res.case_id)} | {label} | failed: {md_cell(res.error)} | | | | | | | |"
            )
            continue
        for s in res.scores:
            f = s.figures
            lines.append(
                f"| {md_cell(res.case_id)} | {s.name} | {f['n']} | {_fmt(f['mean_abs_mm'], 2)} | "
                f"{_fmt(f['signed_mean_mm'], 2)} ± {_fmt(f['signed_sd_mm'], 2)} | "
                f"{_fmt(f[_pct_key(1.0)])} | **{_fmt(f[_pct_key(2.5)])}** | "
                f"{_fmt(f[_pct_key(5.0)])} | {_fmt(f['p95_mm'])} | "
                f"{_fmt(res.seconds.get('total'), 0)} |"
            )
    lines.append("")
    for res, label in results:
        if res.status != "ok":
            continue
        lines += [
            f"## {md_cell(res.case_id)} — {label}: % within 2.5 mm (mean |d| mm) per face region",
            "",
            "| method | " + " | ".join(region_names) + " |",
            "|---|" + "---|" * len(region_names),
        ]
        for s in res.scores:
            cells = []
            for name in region_names:
                fig = s.regions.get(name, {})
                cells.append(
                    f"{_fmt(fig.get(_pct_key(2.5)))} ({_fmt(fig.get('mean_abs_mm'))})"
                    if fig.get("n")
                    else "–"
                )
            lines.append(f"| {s.name} | " + " | ".join(cells) + " |")
        feats = res.notes.get("features")
        if feats:
            lines += ["", *feature_table(feats)]
        band = res.notes.get("band")
        if band:
            lines += ["", *band_table(band, region_names)]
        notes = {
            k: v for k, v in res.notes.items() if v is not None and k not in ("features", "band")
        }
        if notes:
            lines += ["", "notes: " + "; ".join(f"{k}: {md_cell(v)}" for k, v in notes.items())]
        lines.append("")
    if credits:
        lines += ["## Data credits", ""] + [f"- {c}" for c in credits] + [""]
    return "\n".join(lines)


def write_pdf(
    results: Sequence[tuple[Any, str]],
    region_names: Sequence[str],
    path: Path,
    pictures: Mapping[tuple[str, str], list[tuple[str, Path]]] | None = None,
    credits: Sequence[str] = (),
    software: str = "workbench",
) -> Path:
    """The PDF: the summary table, per-case regions and pictures, data credits."""
    from workbench.reporting.pdf import ReportPDF
    from workbench.reporting.report import utc_now

    pdf = ReportPDF("validation", utc_now(), software)
    pdf.add_page()
    pdf.heading("Validation on real skull/skin pairs")
    pdf.para(
        "Metric of VALIDATION.md: the true skin's outermost, anterior-facing vertices in "
        "front of the bone centre and within 35 mm of the bone; for each, the distance to "
        "the reconstructed surface (positive: the reconstruction lies outside). The uniform "
        "6 mm offset of the same bone is scored on the same points. mm and %."
    )
    pdf.para(PUBLISHED, size=8)
    head = ["case", "method", "n", "mean |d|", "signed ± SD", "% ≤ 2.5", "% ≤ 5", "p95"]
    body = []
    for res, label in results:
        if res.status != "ok":
            body.append([res.case_id, label, "failed", res.error[:60], "", "", "", ""])
            continue
        for s in res.scores:
            f = s.figures
            body.append(
                [
                    res.case_id,
                    s.name,
                    f["n"],
                    _fmt(f["mean_abs_mm"], 2),
                    f"{_fmt(f['signed_mean_mm'], 2)} ± {_fmt(f['signed_sd_mm'], 2)}",
                    _fmt(f[_pct_key(2.5)]),
                    _fmt(f[_pct_key(5.0)]),
                    _fmt(f["p95_mm"]),
                ]
            )
    pdf.grid(
        head,
        body,
        (24, 44, 14, 18, 30, 16, 16, 16),
        aligns=("L", "L", "R", "R", "R", "R", "R", "R"),
    )
    for res, label in results:
        if res.status != "ok":
            continue
        pdf.heading(f"{res.case_id} — {label}")
        rh = ["method"] + list(region_names)
        rb = []
        for s in res.scores:
            rb.append(
                [s.name]
                + [
                    f"{_fmt(s.regions.get(n, {}).get(_pct_key(2.5)))} %"
                    if s.regions.get(n, {}).get("n")
                    else "–"
                    for n in region_names
                ]
            )
        pdf.grid(
            rh, rb, (44,) + (22,) * len(region_names), aligns=("L",) + ("R",) * len(region_names)
        )
        pics = (pictures or {}).get((res.case_id, label))
        if pics:
            pdf.pictures(pics, columns=2, title="signed distance on the true skin (mm)")
    if credits:
        pdf.heading("Data credits")
        for c in credits:
            pdf.para(c, size=8)
    tmp = path.with_name(path.name + ".part")
    pdf.output(str(tmp))
    tmp.replace(path)
    return path
