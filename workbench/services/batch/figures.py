"""Key figures of a finished batch row, read from the files its command wrote.

Each sub-command leaves its figures where its single run puts them:
``reconstruct`` in ``report.json`` (fit, ensemble, validation against a
``--truth``), ``validate`` in ``results.csv`` (one row per case and method,
the metric of ``VALIDATION.md`` overall and per face region), ``fit-scan``
in ``fit_report.json`` (the face within 1 / 2.5 mm, distances in mm) and
``animate`` only in its closing line on stdout (vertices, settle iterations,
largest skin movement in mm), ``age`` in the summary it prints (per target
age: head circumference, residual in mm, largest z-score change).  A sub-command this module does not know (a new
one, such as ``age``) gets the numbers of the last JSON object it printed.

Figures are flat ``{name: number or text}`` dicts (units in the names: ``_mm``,
``pct_`` 0-100, ``_fraction`` 0-1), so they go straight into summary.csv.
"""

from __future__ import annotations

import csv
import json
import math
import re
from pathlib import Path
from typing import Any

Figures = dict[str, Any]

RECONSTRUCT_FIT = (
    "max_tip_error_mm",
    "min_tissue_mm",
    "penetrating_vertices",
    "refits",
    "suggested_landmarks",
    "absent_landmarks",
)
VALIDATION_KEYS = ("n", "mean_abs_mm", "rms_mm", "p95_mm", "pct_within_2_5mm", "pct_within_5mm")
FIT_SCAN_KEYS = (
    "face_within_1mm_fraction",
    "face_within_2_5mm_fraction",
    "face_mean_distance_mm",
    "fold_overs",
)
#: what an age row's summary keeps per target age (sub-keys of the printed figures)
AGE_KEYS = {
    "head_circumference_mm": ("before", "after", "target"),
    "hard_residual_mm": ("max",),
    "z_change_max": ("",),
}
ANIMATE_LINE = re.compile(
    r"\((?P<vertices>\d+) vertices(?:; .*?settled in (?P<iterations>\d+) iterations; largest skin "
    r"movement (?P<movement>[0-9.]+) mm)?(?:, (?P<targets>\d+) morph targets settled in "
    r"(?P<target_seconds>[0-9.]+) s)?"
)


def _number(value: Any) -> Any:
    """A finite int/float as is (floats to 4 decimals), text as is, anything else None."""
    if isinstance(value, bool):
        return int(value)
    if isinstance(value, int):
        return value
    if isinstance(value, float):
        return round(value, 4) if math.isfinite(value) else None
    if isinstance(value, str):
        return value
    return None


def _scalars(data: Any, keys: tuple[str, ...] | None = None, prefix: str = "") -> Figures:
    if not isinstance(data, dict):
        return {}
    out = {}
    for k in keys or tuple(data):
        v = _number(data.get(k))
        if v is not None and not isinstance(v, str):
            out[prefix + k] = v
    return out


def _read_json(path: Path) -> dict[str, Any]:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def reconstruct_figures(folder: Path) -> Figures:
    report = _read_json(folder / "report.json")
    out = _scalars(report.get("fit"), RECONSTRUCT_FIT)
    ensemble = report.get("ensemble")
    if isinstance(ensemble, dict):
        spread = ensemble.get("spread_mm")
        out.update(_scalars(spread, None, "ensemble_spread_") if isinstance(spread, dict) else {})
        if isinstance(spread, int | float):
            out["ensemble_spread_mm"] = _number(float(spread))
    out.update(_scalars(report.get("validation"), VALIDATION_KEYS, "truth_"))
    return out


def validate_rows(folder: Path) -> list[dict[str, str]]:
    """The rows of a validate run's ``results.csv`` (case, method, status, figures)."""
    try:
        with (folder / "results.csv").open(encoding="utf-8", newline="") as fh:
            return list(csv.DictReader(fh))
    except OSError:
        return []


def _float(text: Any) -> float | None:
    try:
        value = float(text)
    except (TypeError, ValueError):
        return None
    return value if math.isfinite(value) else None


def validate_figures(folder: Path) -> Figures:
    rows = validate_rows(folder)
    cases = {r.get("case") for r in rows}
    failed = {r.get("case") for r in rows if r.get("status") != "ok"}
    out: Figures = {"cases": len(cases), "failed_cases": len(failed)}
    methods = dict.fromkeys(r.get("method") for r in rows if r.get("status") == "ok")
    for method in methods:
        mine = [r for r in rows if r.get("method") == method and r.get("status") == "ok"]
        for key in ("pct_within_2_5mm", "pct_within_5mm", "mean_abs_mm"):
            values = [v for r in mine if (v := _float(r.get(key))) is not None]
            if values:  # mean over the cases (one case: its figure)
                out[f"{method}_{key}"] = round(sum(values) / len(values), 3)
    return out


def fit_scan_figures(folder: Path) -> Figures:
    report = _read_json(folder / "fit_report.json")
    out = _scalars(report, FIT_SCAN_KEYS)
    tissue = report.get("tissue_depths")
    if isinstance(tissue, dict):
        out.update(_scalars(tissue, ("mean_abs_diff_mm",), "tissue_depth_"))
    bone = report.get("skull_vs_bone")
    out.update(_scalars(bone, None, "skull_vs_bone_"))
    if isinstance(bone, dict):
        base = bone.get("uniform_offset_baseline")
        out.update(_scalars(base, None, "skull_vs_bone_baseline_"))
    return out


def animate_figures(output: Path, stdout: str) -> Figures:
    out: Figures = {}
    lines = [ln for ln in stdout.splitlines() if ln.startswith("wrote ")]
    match = ANIMATE_LINE.search(lines[-1]) if lines else None
    if match:
        names = {
            "vertices": "vertices",
            "iterations": "settle_iterations",
            "movement": "largest_movement_mm",
            "targets": "morph_targets",
            "target_seconds": "targets_seconds",
        }
        for group, name in names.items():
            if match.group(group) is not None:
                out[name] = (
                    float(match.group(group))
                    if "." in match.group(group)
                    else int(match.group(group))
                )
    if output.is_file():
        out["output_bytes"] = output.stat().st_size
    return out


def _last_json(stdout: str) -> dict[str, Any]:
    """The last JSON object a command printed (starting at the beginning of a line)."""
    decoder = json.JSONDecoder()
    last: dict[str, Any] = {}
    for i, ch in enumerate(stdout):
        if ch == "{" and (i == 0 or stdout[i - 1] == "\n"):
            try:
                data, _ = decoder.raw_decode(stdout, i)
            except ValueError:
                continue
            if isinstance(data, dict):
                last = data
    return last


def printed_json(stdout: str) -> Figures:
    """The numbers of the last JSON object a command printed (one level of nesting)."""
    out: Figures = {}
    for k, v in _last_json(stdout).items():
        if isinstance(v, dict):
            out.update(_scalars(v, None, f"{k}_"))
        elif (n := _number(v)) is not None and not isinstance(n, str):
            out[k] = n
    return out


def age_figures(stdout: str) -> Figures:
    """``age``: the source head's circumference and per target age (``_<age>y`` in the name)
    the aged head's and the chart's target (mm), the largest hard-landmark residual (mm) and
    the largest z-score change, from the summary it prints."""
    ages = _last_json(stdout).get("ages")
    out: Figures = {}
    for item in ages if isinstance(ages, list) else ():
        age = _number(item.get("to_age")) if isinstance(item, dict) else None
        if not isinstance(age, int | float):
            continue
        for key, subs in AGE_KEYS.items():
            value = item.get(key)
            for sub in subs:
                number = _number(value.get(sub) if isinstance(value, dict) else value)
                if not isinstance(number, int | float):
                    continue
                if sub == "before":  # the source head, the same for every age
                    out[f"{key}_before"] = number
                else:
                    out[f"{key}{'_' + sub if sub else ''}_{age:g}y"] = number
    return out


def row_figures(job: str, argv: list[str], stdout: str) -> Figures:
    """Key figures of a finished row of ``job`` whose command line was ``argv``."""
    out = Path(argv[argv.index("--out") + 1])
    if job == "reconstruct":
        return reconstruct_figures(out)
    if job == "validate":
        return validate_figures(out)
    if job == "fit-scan":
        return fit_scan_figures(out)
    if job == "animate":
        return animate_figures(out, stdout)
    if job == "age":
        return age_figures(stdout) or printed_json(stdout)
    return printed_json(stdout)
