"""Key figures of a finished job, taken from the values it made (not from what it printed).

Each job function returns its figures in a :class:`~workbench.pipelines.outcome.JobOutcome`,
built here from its own results: ``reconstruct`` from its report (fit,
ensemble, validation against a ``--truth``), ``validate`` from its table (one
row per case and method, the metric of ``VALIDATION.md``), ``fit-scan`` from
the fit's figures (the face within 1 / 2.5 mm, distances in mm), ``age`` from
its summary (per target age: head circumference, residual in mm, largest
z-score change); ``animate`` builds its own (vertices, settle iterations,
largest skin movement in mm, morph targets, bytes written).

Figures are flat ``{name: number or text}`` dicts (units in the names: ``_mm``,
``pct_`` 0-100, ``_fraction`` 0-1), so they go straight into summary.csv.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any

import numpy as np

from workbench.pipelines.reconstruct import FIT_FIGURES

Figures = dict[str, Any]

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


def _number(value: Any) -> Any:
    """A finite int/float as is (floats to 4 decimals; numpy scalars as Python numbers), text
    as is, anything else None."""
    if isinstance(value, np.generic):
        value = value.item()
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


def reconstruct_figures(report: dict[str, Any]) -> Figures:
    """``reconstruct``: the fit's figures, the ensemble spread and a ``--truth`` validation."""
    out = _scalars(report.get("fit"), FIT_FIGURES)
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


def validate_figures(rows: list[dict[str, Any]]) -> Figures:
    """``validate``: the cases, the failed ones and each method's mean figures over the cases
    (``rows``: the study's table, one row per case and method, as in ``results.csv``)."""
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


def fit_scan_figures(report: dict[str, Any]) -> Figures:
    """``fit-scan``: the face's distances to the scan, fold-overs, tissue and bone checks
    (``report``: the fit's figures, as in ``fit_report.json``)."""
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


def age_figures(summary: dict[str, Any]) -> Figures:
    """``age``: the source head's circumference and per target age (``_<age>y`` in the name)
    the aged head's and the chart's target (mm), the largest hard-landmark residual (mm) and
    the largest z-score change (``summary``: what ``workbench age`` prints)."""
    ages = summary.get("ages")
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
