"""The skull-to-face reconstruction report: a plain dict, its schema, JSON and PDF output.

The reconstruction service fills a dict in the layout of
``data_tables/schemas/report.schema.json`` (``"@schema":
"reconstruction-report-v1"``; described in ``reports/README.md``); this
module checks it and writes ``report.json`` and ``report.pdf`` from the same
data, so the two never disagree.

Units and frame: every length is in mm.  Landmark positions and dowel
directions are in the frame the report names in its ``"frame"`` field (the
input skull's frame for a reconstruction: results go back to the user in the
frame of the files they came from).  Pictures are given as paths (PNG),
relative to the folder of the report; this layer never renders (no VTK, no
Qt).

Both writers validate first and write atomically (temporary file in the same
folder, then ``os.replace``), so a case folder never holds half a report.
The PDF layout (sections below) uses the primitives of
:mod:`workbench.reporting.pdf`.

Published reference ranges printed beside validation figures (faces
reconstructed from CT skulls of living subjects, compared with their own
faces):

- Miranda, G. E., Wilkinson, C., Roughley, M., Beaini, T. L. and Melani,
  R. F. H. (2018). Assessment of accuracy and recognition of
  three-dimensional computerized forensic craniofacial reconstruction.
  PLoS ONE 13(5): e0196770 — 63–74 % of points within ±2.5 mm.
- Lee, W.-J., Wilkinson, C. M. and Hwang, H.-S. (2012). An accuracy
  assessment of forensic computerized facial reconstruction employing
  cone-beam computed tomography from live subjects. Journal of Forensic
  Sciences 57(2): 318–327 — 54–77 % within 2.5 mm.
- Wilkinson, C., Rynn, C., Peters, H., Taister, M., Kau, C. H. and Richmond,
  S. (2006). A blind accuracy assessment of computer-modeled forensic facial
  reconstruction using computed tomography data from live subjects. Forensic
  Science, Medicine, and Pathology 2(3): 179–187 — 75 % (female) and 90 %
  (male) of the face within 5 mm.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable, Mapping
from datetime import UTC, datetime
from functools import lru_cache
from os import PathLike
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np

from workbench.core.data_paths import data_tables_dir
from workbench.core.errors import InputError
from workbench.io.atomic import write_with_atomic
from workbench.reporting.first_page import (
    appendix,
    before_use_box,
    face_and_figures,
    key_figures,
)
from workbench.reporting.pdf import (
    ACCENT,
    DARK,
    GREY,
    GROUPS,
    ReportPDF,
    describe_value,
    num,
    picture_groups,
    resolve_picture,
    view_caption,
)

#: picture keys of :func:`workbench.render.reconstruction.render_builds`
BUILD_PICTURES = ("builds_front", "builds_side", "band")
#: the portraits drawn in the case's appearance (keys of the report's pictures)
PORTRAIT_PICTURES = ("portrait_front", "portrait_three_quarter", "portrait_profile")
SCHEMA_ID = "reconstruction-report-v1"
SCHEMA_FILE = "report.schema.json"
PathArg = str | PathLike[str]
PUBLISHED = (
    "Published: 63–74 % within ±2.5 mm (Miranda et al. 2018); 54–77 % within 2.5 mm "
    "(Lee et al. 2012); 75–90 % within 5 mm (Wilkinson et al. 2006)."
)


def schema_path() -> Path:
    """The report schema: the wheel's ``_data`` copy first, else the source tree."""
    path = data_tables_dir() / "schemas" / SCHEMA_FILE
    if not path.is_file():
        raise FileNotFoundError(f"{SCHEMA_FILE} not found in {path.parent}")
    return path


@lru_cache(maxsize=1)
def _validator() -> jsonschema.Draft202012Validator:
    schema = json.loads(schema_path().read_text(encoding="utf-8"))
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


def utc_now() -> str:
    """The current time as ISO 8601 UTC with a ``Z`` (seconds), for ``"created"``."""
    return datetime.now(UTC).replace(microsecond=0).isoformat().replace("+00:00", "Z")


def to_jsonable(value: Any, where: str = "$") -> Any:
    """A copy of ``value`` with numpy scalars/arrays, tuples and paths made JSON-native.

    NaN ("no value", e.g. a region without vertices) becomes ``null``, which
    the schema then accepts or rejects per field; an infinite number raises
    :class:`InputError` naming its JSON path.
    """
    if isinstance(value, Mapping):
        return {str(k): to_jsonable(v, f"{where}.{k}") for k, v in value.items()}
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, list | tuple):
        return [to_jsonable(v, f"{where}[{i}]") for i, v in enumerate(value)]
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        if math.isnan(value):
            return None
        if not math.isfinite(value):
            raise InputError(
                "report",
                f"{where} is {value}; JSON has no infinity",
                "use null for a missing value",
            )
        return float(value)
    if isinstance(value, PathLike):
        return os.fspath(value)
    return value


def validate_report(report: Mapping[str, Any]) -> None:
    """Check ``report`` against ``report.schema.json``.

    Raises
    ------
    InputError
        Naming the JSON path of the first problem (e.g. ``$.landmarks[3].depth_mm``)
        and what is wrong there (a missing key is named).
    """
    if not isinstance(report, Mapping):
        raise InputError("report", f"a report is a dict, got {type(report).__name__}")
    doc = to_jsonable(report)
    error = jsonschema.exceptions.best_match(_validator().iter_errors(doc))
    if error is not None:
        message = error.message if len(error.message) < 300 else error.message[:300] + "..."
        raise InputError(
            "report",
            f"does not match {SCHEMA_ID} at {error.json_path}: {message}",
            "see reports/README.md for the report layout",
        )
    _check_consistency(doc)


def _check_consistency(doc: Mapping[str, Any]) -> None:
    """Rules a JSON schema cannot say: unique landmark codes, guide ids and picture files."""
    for key, field in (("landmarks", "code"), ("guides", "id")):
        seen: set[str] = set()
        for i, item in enumerate(doc.get(key) or ()):
            if item[field] in seen:
                raise InputError(
                    "report", f"$.{key}[{i}].{field}: duplicate {field} {item[field]!r}"
                )
            seen.add(item[field])


def _atomic_write(path: PathArg, write: Callable[[Path], object]) -> Path:
    """Call ``write(tmp)`` on a temporary file beside ``path``, then move it into place."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    return write_with_atomic(path, write)


def write_report_json(report: Mapping[str, Any], path: PathArg) -> Path:
    """Validate and write ``report.json`` (UTF-8, keys in the given order, indent 1)."""
    validate_report(report)
    text = json.dumps(to_jsonable(report), indent=1, ensure_ascii=False, allow_nan=False) + "\n"
    return _atomic_write(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))


def read_report_json(path: PathArg) -> dict[str, Any]:
    """Read and validate a ``report.json``."""
    try:
        doc = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise InputError(path, f"cannot read the report ({exc})") from None
    try:
        validate_report(doc)
    except InputError as exc:
        raise InputError(path, exc.problem, exc.hint) from None
    return doc


def write_report_pdf(
    report: Mapping[str, Any], path: PathArg, *, base_dir: PathArg | None = None
) -> Path:
    """Validate and write the A4 PDF of ``report``.

    ``base_dir`` is where relative picture paths are resolved (default: the
    PDF's folder, which is where ``report.json`` lives).  A picture file that
    is listed but missing is shown as a framed note in the PDF, not an error.
    """
    validate_report(report)
    path = Path(path)
    base = Path(base_dir) if base_dir is not None else path.parent
    pdf = build_pdf(to_jsonable(report), base)
    return _atomic_write(path, lambda tmp: pdf.output(str(tmp)))


# -------------------------------------------------------------------- sections
SOURCE_STYLE = {
    "table": ("", DARK),
    "override": ("B", (150, 60, 0)),
    "interpolated": ("", (40, 90, 40)),
    "excluded": ("I", GREY),
    "none": ("", GREY),
}


def build_pdf(report: dict[str, Any], base: Path) -> ReportPDF:
    """Lay out every section of ``report``; picture paths resolve against ``base``.

    Page 1 is what a reader needs first: who and which case, the face (the three
    builds' front picture, else the face's front view) with the key figures, and a
    short "Before use" box with only what must be acted on.  Every warning follows,
    in full, in the closing "Appendix: technical notes".
    """
    software = f"{report['software']['name']} {report['software']['version']}"
    pdf = ReportPDF(report["case_id"], report["created"], software)
    pdf.add_page()
    listed = dict(report.get("pictures") or {})
    builds = report.get("builds") or None
    # the build pictures go with their sections (with no builds entry: "Other pictures")
    build_pictures = {
        k: resolve_picture(listed.pop(k), base)
        for k in BUILD_PICTURES
        if builds is not None and k in listed
    }
    portraits = [
        (view_caption(k.removeprefix("portrait_")), resolve_picture(listed.pop(k), base))
        for k in PORTRAIT_PICTURES
        if k in listed
    ]
    # with no builds, the face's front view leads page 1 (and is not repeated later)
    front = None if builds is not None or "face_front" not in listed else listed.pop("face_front")
    pictures = picture_groups(listed, base)
    _title(pdf, report)
    link = pdf.add_link()
    if builds is not None:
        _builds(pdf, builds, build_pictures.get("builds_front"))
        pdf.heading("Key figures", min_space=25)
        key_figures(pdf, report, wide=True)
    else:
        face_and_figures(pdf, report, None if front is None else resolve_picture(front, base))
    before_use_box(pdf, report, link)
    _details(pdf, report)
    _inputs(pdf, report["inputs"])
    _table(pdf, report["table"])
    _landmarks(pdf, report["landmarks"])
    if report.get("guides"):
        _guides(pdf, report["guides"])
    if report.get("predictions"):
        pdf.heading("Feature predictions")
        pdf.grid(
            ("rule", "feature", "value (mm)", "citation"),
            [
                (p["rule_id"], p["label"], num(p["value_mm"]), p["citation"])
                for p in report["predictions"]
            ],
            (30, 45, 20, 85),
            aligns=("L", "L", "R", "L"),
        )
    if report.get("fit"):
        _fit(pdf, report["fit"])
    if report.get("registration"):
        _registration(pdf, report["registration"], report.get("self_check"))
    if report.get("appearance"):
        _appearance(pdf, report["appearance"], portraits)
    shown = [title for _, title in GROUPS if title in pictures]
    side = build_pictures.get("builds_side")
    if shown or side is not None:
        pdf.heading("Pictures", min_space=100)
        pdf.para(
            "Orthographic views oriented by the head frame (Frankfort Horizontal): front, "
            "right side and right three-quarter; every picture has the same scale (see the "
            "50 mm bars).",
            size=8,
            color=GREY,
        )
        for title in shown:
            on_first = front is not None and title == "Reconstructed face"
            pdf.pictures(
                pictures.pop(title), title=f"{title} (front view on page 1)" if on_first else title
            )
        if side is not None:
            pdf.pictures(
                [("right side, slender to heavy, same scale", side)],
                columns=1,
                title="The three builds",
            )
    if builds is not None:
        _band(pdf, builds, build_pictures.get("band"))
    if report.get("ensemble"):
        _ensemble(pdf, report["ensemble"], pictures.pop("spread", []))
    if report.get("validation"):
        _validation(
            pdf,
            report["validation"],
            [
                item
                for k in list(pictures)
                if k.startswith("validation")
                for item in pictures.pop(k)
            ],
        )
    if pictures:
        pdf.heading("Other pictures", min_space=100)
        for items in pictures.values():
            pdf.pictures(items, columns=1 if len(items) == 1 else 3)
    if report.get("credits"):
        pdf.heading("Data credits", min_space=25)
        pdf.numbered(report["credits"])
    appendix(pdf, report, link)
    return pdf


def _title(pdf: ReportPDF, report: dict[str, Any]) -> None:
    """Title, case, examiner, depth table and build; the run's details follow on page 2."""
    pdf.font(17, "B")
    pdf.set_text_color(*ACCENT)
    pdf.cell(0, 9, pdf.t("Skull-to-face reconstruction report"), new_x="LMARGIN", new_y="NEXT")
    pdf.font(12)
    pdf.set_text_color(*DARK)
    pdf.cell(0, 7, pdf.t(f"Case {report['case_id']}"), new_x="LMARGIN", new_y="NEXT")
    pdf.ln(2)
    table = report["table"]
    pdf.key_values(
        [
            ("Case id", report["case_id"]),
            ("Created (UTC)", report["created"]),
            ("Examiner", report.get("examiner") or "not recorded"),
            (
                "Depth table",
                f"{table['id']}" + (f" ({table['group']})" if table.get("group") else ""),
            ),
            ("Build", _build_text(report)),
        ]
    )


def _details(pdf: ReportPDF, report: dict[str, Any]) -> None:
    """Software, reference head, units, frame and schema: what the run was made with."""
    pdf.heading("Software, reference head and frame")
    pdf.key_values(
        [
            ("Software", f"{report['software']['name']} {report['software']['version']}"),
            ("Template", report["template"]["id"]),
            ("Template SHA-256", report["template"]["content_hash"]),
            ("Units", "mm (every length in this report)"),
            ("Frame", report["frame"]),
            ("Report schema", report["@schema"]),
        ],
        mono_keys=frozenset({"Template SHA-256"}),
    )


def _build_text(report: dict[str, Any]) -> str:
    """The build as asked, and which of the three faces face.ply is."""
    asked = report["table"].get("build") or "–"
    builds = report.get("builds")
    if not builds:
        return asked
    names = ", ".join(builds.get("builds", {}))
    return f"{asked}: face.ply is the {builds.get('main')} face ({names} beside it)"


def _inputs(pdf: ReportPDF, inputs: list[dict[str, Any]]) -> None:
    pdf.heading("Input files")
    mono = pdf.face(mono=True, size=6.2)
    pdf.grid(
        ("role", "file", "units", "SHA-256"),
        [(f["role"], f["path"], f.get("units") or "–", f["sha256"]) for f in inputs],
        (19, 60, 11, 90),
        col_styles={3: mono},
    )


def _table(pdf: ReportPDF, table: dict[str, Any]) -> None:
    pdf.heading("Tissue-depth table")
    pairs = [("Table", table["id"])]
    if table.get("title"):
        pairs.append(("Title", table["title"]))
    pairs += [
        ("Group", table.get("group") or "–"),
        ("Build", table.get("build") or "–"),
        ("Citation", table["citation"]),
    ]
    pdf.key_values(pairs)
    if table.get("caveats"):
        pdf.ln(1)
        pdf.para("Caveats: " + " ".join(table["caveats"]), size=7.5, color=GREY)


def _landmarks(pdf: ReportPDF, landmarks: list[dict[str, Any]]) -> None:
    """The landmark table; its header names the one frame of the positions (report.json) and
    of the landmark files (:data:`workbench.io.markups.OUTPUT_FRAME_NAME`)."""
    from workbench.io.markups import OUTPUT_FRAME_NAME

    pdf.heading("Skull landmarks and tissue depths", min_space=45)
    counts = {s: sum(lm["source"] == s for lm in landmarks) for s in SOURCE_STYLE}
    pdf.para(
        f"{len(landmarks)} landmarks: "
        + ", ".join(
            f"{n} {'without a depth' if s == 'none' else s}" for s, n in counts.items() if n
        )
        + ". Depths in mm along the dowel (skull landmark to skin); 'used' is the depth the fit "
        "applied. Positions and dowel directions are in report.json, the positions also in "
        "skull_landmarks.mrk.json (and .fcsv when written), all in one frame: "
        f"{OUTPUT_FRAME_NAME}, the skull file's coordinates as 3D Slicer shows them.",
        size=8,
        color=GREY,
    )
    pdf.ln(1)
    pdf.font(8)
    code_w = min(
        max(12.0, *(pdf.get_string_width(pdf.t(lm["code"])) + 3 for lm in landmarks)), 30.0
    )
    skin_w = min(
        max(
            10.0, *(pdf.get_string_width(pdf.t(lm.get("skin_code") or "")) + 3 for lm in landmarks)
        ),
        24.0,
    )
    rows, styles = [], []
    for lm in landmarks:
        rows.append(
            (
                lm["code"],
                lm.get("skin_code") or "–",
                lm["name"],
                lm["status"],
                num(lm["table_depth_mm"]),
                num(lm["sd_mm"]),
                num(lm["depth_mm"]),
                lm["source"],
            )
        )
        style, colour = SOURCE_STYLE[lm["source"]]
        styles.append(pdf.face(style, color=colour))
    pdf.grid(
        ("skull", "skin", "name", "status", "table", "SD", "used", "source"),
        rows,
        (code_w, skin_w, 95 - code_w - skin_w, 19, 15, 13, 15, 23),
        aligns=("L", "L", "L", "L", "R", "R", "R", "L"),
        styles=styles,
    )
    notes = [f"{lm['code']}: {lm['note']}" for lm in landmarks if lm.get("note")]
    if notes:
        pdf.para("Notes: " + "; ".join(notes), size=8)


def _guides(pdf: ReportPDF, guides: list[dict[str, Any]]) -> None:
    pdf.heading("Guides")
    rows = [
        (
            g["label"] or g["id"],
            g["kind"],
            describe_value(g.get("value")),
            " ".join(filter(None, (g.get("rule_id"), g.get("citation")))) or "–",
            g.get("source") or "–",
            "on" if g["enabled"] else "off",
        )
        for g in guides
    ]
    styles = [None if g["enabled"] else pdf.face("I", color=GREY) for g in guides]
    pdf.grid(
        ("guide", "kind", "value (mm)", "rule and citation", "source", "use"),
        rows,
        (40, 16, 40, 56, 16, 12),
        styles=styles,
    )


def _fit(pdf: ReportPDF, fit: dict[str, Any]) -> None:
    pdf.heading("Fit")
    rows = []
    for key, value in fit.items():
        unit = "mm" if key.endswith("_mm") else "s" if key in ("seconds", "time_s") else ""
        label = key.removesuffix("_mm").replace("_", " ")
        rows.append((label, f"{num(value, 2)} {unit}".strip()))
    pdf.grid((), rows, (70, 40), aligns=("L", "R"), size=8.5)


def _registration(pdf: ReportPDF, reg: dict[str, Any], check: dict[str, Any] | None) -> None:
    """How the skull was oriented, judged and articulated (issue 28)."""
    pdf.heading("Skull registration")
    orientation = reg.get("orientation") or {}
    how = str(orientation.get("method", "–"))
    method = {
        "search": "found from the bone alone",
        "hint": "from the directions given",
        "seeds": "from the landmarks placed",
    }.get(how, how)
    rows = [("orientation", method)]
    if check:
        rows.append(("self-check", check.get("outcome", "–")))
        measures = check.get("measures") or {}
        if measures.get("face_observed") is not None:
            rows.append(
                ("facial skeleton on bone", f"{100 * float(measures['face_observed']):.0f} %")
            )
        if measures.get("symmetry_deg") is not None:
            rows.append(("symmetry plane off the midline", f"{num(measures['symmetry_deg'])}°"))
    jaw = reg.get("jaw") or {}
    if jaw:
        if not jaw.get("present"):
            rows.append(("mandible", "not found (the lower face is inferred)"))
        else:
            shift = jaw.get("shift_mm") or [0.0, 0.0, 0.0]
            rows.append(
                (
                    "mandible in the scan",
                    f"opened {num(jaw.get('opening_deg'))}°, joint moved "
                    f"{num(float(np.linalg.norm(shift)))} mm",
                )
            )
            occ = jaw.get("occlusion")
            rows.append(
                (
                    "jaw for the face",
                    f"in occlusion: {occ['method']}" if occ else "as scanned",
                )
            )
    pdf.grid((), rows, (70, 110), aligns=("L", "L"), size=8.5)


COUNT_WORDS = {1: "one", 2: "two", 3: "three", 4: "four", 5: "five"}


def _appearance(
    pdf: ReportPDF, appearance: dict[str, Any], portraits: list[tuple[str, Path]]
) -> None:
    """The colours and hair chosen for the face, said to be artistic, with the portraits."""
    pdf.heading("Appearance: an artistic presentation", min_space=110)
    lines = [str(appearance.get("note") or "")]
    additions = appearance.get("artistic_additions") or {}
    if additions.get("hair_and_brows"):
        styles = ", ".join(
            f"{kind} {style.replace('_', ' ')}"
            for kind, style in additions["hair_and_brows"].items()
        )
        lines.append(f"{styles}: {additions.get('note', '')}")
    pdf.box("Not evidence", [line for line in lines if line])
    if appearance.get("summary"):
        pdf.para(f"Chosen: {appearance['summary']}", size=8, color=GREY)
    if portraits:
        pdf.pictures(portraits, columns=3, title="Portraits in the chosen appearance")


def _bmi(value: Any) -> str:
    ok = isinstance(value, int | float) and not isinstance(value, bool)
    return f"BMI {value:g}" if ok else "BMI –"


def _builds(pdf: ReportPDF, builds: dict[str, Any], front: Path | None) -> None:
    """First page: the three build faces (BMI, which is ``face.ply``) and the band in brief."""
    pdf.heading("Three builds", min_space=70 if front is not None else 25)
    faces = builds.get("builds")
    faces = faces if isinstance(faces, dict) else {}
    listed = ", ".join(
        f"{name} ({_bmi(b.get('bmi') if isinstance(b, dict) else None)})"
        for name, b in faces.items()
    )
    main = builds.get("main")
    text = "The skull cannot tell how heavy the person was, so the face is given for " + (
        f"{COUNT_WORDS.get(len(faces), len(faces))} body builds (BMI in kg/m²): {listed}."
        if faces
        else "several body builds."
    )
    if main:
        text += (
            f" face.ply is the {main} face."
            if main in faces
            else f" face.ply is a face for {main}, between them."
        )
    half = (builds.get("band_half_width_mm") or {}).get("median")
    if half is not None:
        text += (
            " With the build unknown, the true skin should lie within a band around face.ply "
            f"about {num(2 * half)} mm thick (median half-width {num(half)} mm; 95 % band, "
            "see 'Uncertainty band')."
        )
    pdf.para(text, size=9)
    pdf.ln(1)
    if front is not None:
        pdf.picture("front view, slender to heavy, one scale (see the 50 mm bar)", front)


def _band(pdf: ReportPDF, builds: dict[str, Any], picture: Path | None) -> None:
    """The 95 % band around the main face: what it holds, its width, its map."""
    pdf.heading("Uncertainty band", min_space=100 if picture is not None else 30)
    hw = builds.get("band_half_width_mm") or {}
    text = (
        "Where the true skin may lie, with about 95 % probability, when the build is not "
        "known: an inner and an outer surface around face.ply. The band spans the slender "
        "to heavy faces and is widened for what the depth table leaves open even for a "
        "known build, for the fit's own error and, where no bone lies under the skin, for "
        "the reference head's guess. Its half-width is half its thickness, measured straight "
        "out from the skin"
    )
    if hw.get("median") is not None:
        text += f": median {num(hw['median'])} mm, 90th percentile {num(hw.get('p90'))} mm"
    text += "."
    files = [str(f) for f in builds.get("files") or () if "band" in str(f)]
    if files:
        text += f" Files: {', '.join(files)} (mm, per vertex of face.ply)."
    pdf.para(text, size=9)
    pdf.ln(1)
    if picture is not None:
        pdf.picture(
            "half-width of the 95 % band (mm): front, side, three-quarter", picture, min_scale=0.75
        )


def _ensemble(pdf: ReportPDF, ensemble: dict[str, Any], pictures: list[tuple[str, Path]]) -> None:
    pdf.heading("Uncertainty (ensemble of fits)", min_space=90)
    s = ensemble["spread_mm"]
    pdf.para(
        f"{ensemble['n']} fits, each drawing every landmark depth from its table mean ± SD. "
        f"Per-vertex spread of the face: median {num(s['median'])} mm, 90th percentile "
        f"{num(s['p90'])} mm, maximum {num(s['max'])} mm.",
        size=9,
    )
    pdf.ln(1)
    if pictures:
        pdf.pictures(pictures, columns=1)


def _validation(pdf: ReportPDF, v: dict[str, Any], pictures: list[tuple[str, Path]]) -> None:
    pdf.heading("Validation against the known face", min_space=60)
    if v.get("truth"):
        pdf.para(
            f"Truth surface: {v['truth']}"
            + (f"; region: {v['region']}" if v.get("region") else ""),
            size=8.5,
        )
    pdf.para(
        v.get("metric")
        or "Signed distance from each vertex of the true skin to the "
        "reconstruction (positive = reconstruction outside).",
        size=8,
        color=GREY,
    )
    pdf.ln(1)
    keys = [
        "mean_abs_mm",
        "rms_mm",
        "signed_mean_mm",
        "signed_sd_mm",
        "pct_within_2_5mm",
        "pct_within_5mm",
    ]
    heads = [
        "region",
        "mean |d| (mm)",
        "RMS (mm)",
        "signed mean (mm)",
        "signed SD (mm)",
        "≤ 2.5 mm (%)",
        "≤ 5 mm (%)",
    ]
    if "coverage" in v:
        keys.append("coverage")
        heads.append("coverage (%)")

    def cell(fig: dict[str, Any], key: str) -> str:
        value = fig.get(key)
        return num(100.0 * value if key == "coverage" and value is not None else value)

    rows = [("whole", *(cell(v, k) for k in keys))]
    if v.get("baseline"):
        rows.append(("6 mm offset (whole)", *(cell(v["baseline"], k) for k in keys)))
    rows += [
        (name, *(cell(fig, k) for k in keys)) for name, fig in (v.get("regions") or {}).items()
    ]
    styles = [pdf.face("B")] + [None] * (len(rows) - 1)
    width = 150 / len(keys)
    pdf.grid(heads, rows, (30, *[width] * len(keys)), aligns=("L", *"R" * len(keys)), styles=styles)
    pdf.para(PUBLISHED, size=7.5, color=GREY)
    pdf.ln(1)
    if pictures:
        pdf.pictures(pictures, columns=1 if len(pictures) == 1 else 3)
