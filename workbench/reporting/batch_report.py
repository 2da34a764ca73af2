"""The summary of a batch study: ``summary.csv``, ``summary.md``, plots and ``summary.pdf``.

Input is plain data, one *record* per manifest row (built by
``workbench.pipelines.batch.run.summary_record``)::

    {"id", "job", "line", "status" ("ok" | "check" | "failed"), "resumed", "exit_status",
     "seconds", "message", "folder", "figures": {name: number},
     "cases": [results.csv rows of a validate row]}

Figures keep their units in their names (``_mm``, ``pct_`` 0-100,
``_fraction`` 0-1).  Plots are drawn with matplotlib's Agg canvas (no
display): seconds per job; for validate rows the distribution of the
unsigned error |d| of every case (the cumulative share of the truth points
within 1, 2.5 and 5 mm and the 95th percentile, which is what
``results.csv`` holds: validate writes no per-point distances) and the share
within 2.5 mm per face region; for age rows the head circumference at each
target age (growth curves).
"""

from __future__ import annotations

import csv
import math
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from workbench.core.table_cells import csv_row, md_cell

BASE_COLUMNS = ("id", "job", "line", "status", "resumed", "exit_status", "seconds", "message")
REGIONS = ("forehead", "orbits", "nose", "cheeks", "mouth", "chin")
TOLERANCES = ((1.0, "pct_within_1mm"), (2.5, "pct_within_2_5mm"), (5.0, "pct_within_5mm"))
OK_COLOUR, FAILED_COLOUR = "#2f6f9f", "#b8412c"
#: a row whose outputs were written but whose skull registration asks for a check
CHECK_COLOUR = "#d08a12"
PALETTE = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2")


def _float(value: Any) -> float | None:
    try:
        x = float(value)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


def _cell(value: Any) -> Any:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "yes" if value else "no"
    return value


def table(records: Sequence[Mapping[str, Any]]) -> tuple[list[str], list[dict[str, Any]]]:
    """``(columns, rows)``: the base columns, then every figure in order of appearance."""
    keys: list[str] = []
    for r in records:
        keys += [k for k in r.get("figures", {}) if k not in keys]
    rows = []
    for r in records:
        row = {c: _cell(r.get(c)) for c in BASE_COLUMNS}
        row.update({k: _cell(r.get("figures", {}).get(k)) for k in keys})
        rows.append(row)
    return [*BASE_COLUMNS, *keys], rows


def write_csv(records: Sequence[Mapping[str, Any]], path: Path) -> Path:
    columns, rows = table(records)
    tmp = path.with_name(path.name + ".part")
    with tmp.open("w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=columns)
        w.writeheader()
        w.writerows(csv_row(r) for r in rows)  # ids and messages: no spreadsheet formulas
    tmp.replace(path)
    return path


def _fmt(value: Any) -> str:
    if value is None or value == "":
        return "–"
    if isinstance(value, float):
        return f"{value:.3g}" if abs(value) < 100 else f"{value:.1f}"
    return md_cell(value)


def _list_item(r: Mapping[str, Any]) -> str:
    """One Markdown list line for a row to check or a failed row (user text on one line)."""
    return f"- line {r['line']}, {md_cell(r['id'])} ({r['job']}): {md_cell(r['message'])}"


def _by_job(records: Sequence[Mapping[str, Any]]) -> dict[str, list[Mapping[str, Any]]]:
    groups: dict[str, list[Mapping[str, Any]]] = {}
    for r in records:
        groups.setdefault(r["job"], []).append(r)
    return groups


def counts(records: Sequence[Mapping[str, Any]]) -> dict[str, int]:
    ok = sum(1 for r in records if r["status"] == "ok")
    check = sum(1 for r in records if r["status"] == "check")
    resumed = sum(1 for r in records if r.get("resumed"))
    return {
        "rows": len(records),
        "ok": ok,
        "check": check,
        "failed": len(records) - ok - check,
        "resumed": resumed,
    }


def _colour(status: str) -> str:
    return {"ok": OK_COLOUR, "check": CHECK_COLOUR}.get(status, FAILED_COLOUR)


def _rows_line(n: Mapping[str, int]) -> str:
    to_check = f", {n['check']} to check" if n["check"] else ""
    return f"{n['ok']} ok{to_check}, {n['failed']} failed, {n['resumed']} resumed"


def markdown(
    records: Sequence[Mapping[str, Any]], info: Mapping[str, Any], plots: Sequence[Path] = ()
) -> str:
    """``summary.md``: what ran, one table per job kind (status, seconds, figures), failures."""
    n = counts(records)
    lines = [f"# Batch study: {info.get('manifest', '')}", ""]
    lines += [f"- {k}: {v}" for k, v in info.items()]
    lines += [
        f"- rows: {n['rows']} ({_rows_line(n)} from an earlier run)",
        "",
    ]
    for job, group in _by_job(records).items():
        keys: list[str] = []
        for r in group:
            keys += [k for k in r.get("figures", {}) if k not in keys]
        lines += [f"## {job}", ""]
        head = ["id", "status", "seconds", *keys]
        lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for r in group:
            status = r["status"] + (" (resumed)" if r.get("resumed") else "")
            cells = [md_cell(r["id"]), status, _fmt(r.get("seconds"))]
            cells += [_fmt(r.get("figures", {}).get(k)) for k in keys]
            lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
    checks = [r for r in records if r["status"] == "check"]
    if checks:  # before the failures: these wrote a face that may be wrong
        lines += ["## Rows to check (outputs written; the skull registration is in doubt)", ""]
        lines += [_list_item(r) for r in checks]
        lines.append("")
    failed = [r for r in records if r["status"] not in ("ok", "check")]
    if failed:
        lines += ["## Failed rows", ""]
        lines += [_list_item(r) for r in failed]
        lines.append("")
    if plots:
        lines += ["## Plots", ""] + [f"![{p.stem}](plots/{p.name})" for p in plots] + [""]
    return "\n".join(lines)


# ----------------------------------------------------------------------------- plots


def _figure(width: float, height: float):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), dpi=130)
    FigureCanvasAgg(fig)
    return fig


def _save(fig: Any, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.stem + ".part.png")
    fig.savefig(tmp)
    tmp.replace(path)
    return path


def plot_seconds(records: Sequence[Mapping[str, Any]], path: Path) -> Path | None:
    """Horizontal bars: the seconds of every row that ran (failed rows in red)."""
    done = [r for r in records if _float(r.get("seconds")) is not None]
    if not done:
        return None
    fig = _figure(6.4, 1.2 + 0.28 * len(done))
    ax = fig.add_subplot()
    y = list(range(len(done)))[::-1]
    ax.barh(
        y,
        [_float(r["seconds"]) or 0.0 for r in done],
        color=[_colour(r["status"]) for r in done],
    )
    ax.set_yticks(y, [f"{r['id']} ({r['job']})" + (" *" if r.get("resumed") else "") for r in done])
    ax.set_xlabel("seconds per job (red: failed; amber: to check; *: from an earlier run)")
    ax.tick_params(axis="y", labelsize=7)
    fig.tight_layout()
    return _save(fig, path)


def _cases(records: Sequence[Mapping[str, Any]]) -> list[tuple[str, Mapping[str, Any]]]:
    """``(label, results.csv row)`` of every scored case of the validate rows."""
    out = []
    for r in records:
        for case in r.get("cases") or ():
            if case.get("status") == "ok":
                label = f"{r['id']}/{case.get('case')}"
                out.append((label, case))
    return out


def plot_error_distributions(records: Sequence[Mapping[str, Any]], path: Path) -> Path | None:
    """The cumulative distribution of |d| per validate case and method (from results.csv)."""
    cases = _cases(records)
    if not cases:
        return None
    fig = _figure(6.4, 4.0)
    ax = fig.add_subplot()
    colours: dict[str, str] = {}
    for label, case in cases:
        points = [(0.0, 0.0)]
        points += [(t, v) for t, k in TOLERANCES if (v := _float(case.get(k))) is not None]
        if (p95 := _float(case.get("p95_mm"))) is not None:
            points.append((p95, 95.0))
        points.sort()
        name = label
        if name not in colours:
            colours[name] = PALETTE[len(colours) % len(PALETTE)]
        method = case.get("method", "")
        offset = method.startswith("uniform")
        ax.plot(
            [p[0] for p in points],
            [p[1] for p in points],
            marker="o",
            markersize=3,
            linestyle="--" if offset else "-",
            color=colours[name],
            label=f"{label} {method}",
        )
        if (mean := _float(case.get("mean_abs_mm"))) is not None:
            ax.axvline(mean, color=colours[name], linewidth=0.6, linestyle=":" if offset else "-.")
    ax.set_xlabel("unsigned distance |d| to the true skin (mm)")
    ax.set_ylabel("% of the scored truth points within")
    ax.set_ylim(0, 100)
    ax.set_xlim(left=0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=6, loc="lower right")
    title = (
        "Error distribution per case (at 1, 2.5, 5 mm and the 95th percentile; vertical: mean |d|)"
    )
    ax.set_title(title, fontsize=7)
    fig.tight_layout()
    return _save(fig, path)


def plot_regions(records: Sequence[Mapping[str, Any]], path: Path) -> Path | None:
    """Grouped bars: % within 2.5 mm per face region, one bar per case (method reconstruction)."""
    cases = [
        (label, c)
        for label, c in _cases(records)
        if not str(c.get("method", "")).startswith("uniform")
        and any(_float(c.get(f"{g}_pct_within_2_5mm")) is not None for g in REGIONS)
    ]
    if not cases:
        return None
    fig = _figure(6.4, 3.6)
    ax = fig.add_subplot()
    width = 0.8 / len(cases)
    for i, (label, case) in enumerate(cases):
        xs = [j + (i - (len(cases) - 1) / 2) * width for j in range(len(REGIONS))]
        values = [_float(case.get(f"{g}_pct_within_2_5mm")) or 0.0 for g in REGIONS]
        ax.bar(xs, values, width, label=f"{label} {case.get('method', '')}")
    ax.set_xticks(range(len(REGIONS)), REGIONS)
    ax.set_ylabel("% within 2.5 mm")
    ax.set_ylim(0, 100)
    ax.legend(fontsize=6)
    ax.set_title("Per face region", fontsize=8)
    fig.tight_layout()
    return _save(fig, path)


AGE_CURVE = re.compile(r"^head_circumference_mm_(?P<kind>after|target)_(?P<age>[0-9.]+)y$")


def plot_growth(records: Sequence[Mapping[str, Any]], path: Path) -> Path | None:
    """Age rows: the aged head's circumference (mm) at each target age, one curve per row,
    beside the growth chart's target (dashed)."""
    curves = []
    for r in records:
        if r["job"] != "age" or r["status"] != "ok":
            continue
        found: dict[str, list[tuple[float, float]]] = {"after": [], "target": []}
        for key, value in r.get("figures", {}).items():
            if (m := AGE_CURVE.match(key)) and (v := _float(value)) is not None:
                found[m["kind"]].append((float(m["age"]), v))
        if found["after"]:
            curves.append((r["id"], sorted(found["after"]), sorted(found["target"])))
    if not curves:
        return None
    fig = _figure(6.4, 3.6)
    ax = fig.add_subplot()
    for i, (name, after, target) in enumerate(curves):
        colour = PALETTE[i % len(PALETTE)]
        ax.plot(*zip(*after, strict=True), marker="o", color=colour, label=f"{name} aged head")
        if target:
            ax.plot(*zip(*target, strict=True), linestyle="--", color=colour, label=f"{name} chart")
    ax.set_xlabel("target age (years)")
    ax.set_ylabel("head circumference (mm)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=6)
    ax.set_title("Age rows: growth curves", fontsize=8)
    fig.tight_layout()
    return _save(fig, path)


def write_plots(records: Sequence[Mapping[str, Any]], folder: Path) -> list[Path]:
    """Every plot that has data, as PNG files in ``folder``."""
    made = [
        plot_seconds(records, folder / "seconds.png"),
        plot_error_distributions(records, folder / "validate_error_distribution.png"),
        plot_regions(records, folder / "validate_regions.png"),
        plot_growth(records, folder / "age_growth.png"),
    ]
    return [p for p in made if p is not None]


# ----------------------------------------------------------------------------- PDF

CAPTIONS = {
    "seconds": "Seconds per job",
    "validate_error_distribution": "Validate rows: |d| distribution per case",
    "validate_regions": "Validate rows: % within 2.5 mm per face region",
    "age_growth": "Age rows: head circumference by target age",
}


def write_pdf(
    records: Sequence[Mapping[str, Any]],
    info: Mapping[str, Any],
    plots: Sequence[Path],
    path: Path,
    *,
    software: str = "workbench",
    created: str | None = None,
) -> Path:
    """``summary.pdf`` (A4, the report style of :mod:`workbench.reporting.pdf`)."""
    from workbench.reporting.pdf import ACCENT, DARK, GREY, ReportPDF
    from workbench.reporting.report import utc_now

    created = created or utc_now()
    pdf = ReportPDF("batch", created, software)
    pdf.set_title(f"Batch study, {info.get('manifest', '')}")
    pdf.add_page()
    pdf.font(17, "B")
    pdf.set_text_color(*ACCENT)
    pdf.cell(0, 9, pdf.t("Batch study"), new_x="LMARGIN", new_y="NEXT")
    pdf.set_text_color(*DARK)
    pdf.ln(2)
    n = counts(records)
    pairs = [(str(k), str(v)) for k, v in info.items()]
    pairs += [("Created (UTC)", created), ("Software", software)]
    pairs.append(("Rows", f"{n['rows']}: {_rows_line(n)}"))
    pdf.key_values(pairs, key_width=34)
    checks = [r for r in records if r["status"] == "check"]
    if checks:
        pdf.box(
            "Rows to check (outputs written; the skull registration is in doubt)",
            [f"line {r['line']}, {r['id']} ({r['job']}): {r['message']}" for r in checks],
        )
    failed = [r for r in records if r["status"] not in ("ok", "check")]
    if failed:
        pdf.box(
            "Failed rows",
            [f"line {r['line']}, {r['id']} ({r['job']}): {r['message']}" for r in failed],
        )
    pdf.heading("Jobs")
    bad = pdf.face("B", color=(170, 40, 20))
    pdf.grid(
        ("id", "job", "line", "status", "seconds"),
        [
            (
                r["id"],
                r["job"],
                str(r["line"]),
                r["status"] + (" (resumed)" if r.get("resumed") else ""),
                _fmt(r.get("seconds")),
            )
            for r in records
        ],
        (56, 28, 14, 36, 22),
        aligns=("L", "L", "R", "L", "R"),
        styles=[bad if r["status"] != "ok" else None for r in records],
        size=7.8,
    )
    for job, group in _by_job(records).items():
        keys: list[str] = []
        for r in group:
            keys += [k for k in r.get("figures", {}) if k not in keys]
        if not keys:
            continue
        pdf.heading(f"Key figures: {job}", min_space=40)
        note = "One line per figure, one column per row of the manifest (units in the names)."
        pdf.para(note, size=8, color=GREY)
        for start in range(0, len(group), 4):  # at most 4 rows side by side
            part = group[start : start + 4]
            pdf.grid(
                ("figure", *[r["id"] for r in part]),
                [(k, *[_fmt(r.get("figures", {}).get(k)) for r in part]) for k in keys],
                (64, *[(180 - 64) / len(part)] * len(part)),
                aligns=("L", *["R"] * len(part)),
                size=7.2,
            )
            pdf.ln(2)
    if plots:
        pdf.heading("Plots", min_space=90)
        for plot in plots:
            pdf.pictures([(CAPTIONS.get(plot.stem, plot.stem), plot)], columns=1)
    tmp = path.with_name(path.name + ".part")
    pdf.output(str(tmp))
    tmp.replace(path)
    return path


def write_summary(
    records: Sequence[Mapping[str, Any]],
    folder: Path,
    info: Mapping[str, Any],
    *,
    software: str = "workbench",
) -> list[Path]:
    """``summary.csv``, ``plots/*.png``, ``summary.md`` and ``summary.pdf`` into ``folder``."""
    written = [write_csv(records, folder / "summary.csv")]
    plots = write_plots(records, folder / "plots")
    md = folder / "summary.md"
    tmp = md.with_name(md.name + ".part")
    tmp.write_text(markdown(records, info, plots), encoding="utf-8")
    tmp.replace(md)
    written += [md, write_pdf(records, info, plots, folder / "summary.pdf", software=software)]
    return written + plots
