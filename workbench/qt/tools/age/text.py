"""What the age dock writes: a study in one line, the figures of a result, errors
renamed after the dock's fields (plain strings and HTML, no drawing)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from workbench.core.errors import InputError

if TYPE_CHECKING:
    from workbench.model.age_study import AgeStudy
    from workbench.services.age.change import AgeResult


#: the service's option names (its command line's) as the dock's fields
FIELDS = {
    "--from": "Age now",
    "--to": "Target age",
    "--sex": "Sex",
    "--ethnicity": "Norms of",
    "--norms": "Norms",
    "--arc-increase": "Arc increase",
}


def in_dock(exc: BaseException) -> BaseException:
    """An :class:`InputError` naming a command-line option renamed after the dock's field."""
    if isinstance(exc, InputError) and exc.source in FIELDS:
        hint = exc.hint
        if hint and "--norms" in hint:  # the dock has no norms import: keep the first advice
            hint = hint.split(", or ")[0]
        return InputError(FIELDS[exc.source], exc.problem, hint)
    return exc


def study_text(study: AgeStudy) -> str:
    """One line describing a study: head, sex, ages (years), population."""
    head = (
        "reconstructed head"
        if study.source == "reconstruction"
        else study.source.replace("reference:", "reference ")
    )
    ages = ", ".join(f"{a:g}" for a in study.target_ages)
    text = f"{head}, {study.sex}, {study.from_age:g} y → {ages} y"
    if study.ethnicity:
        text += f", norms of {study.ethnicity}"
    if study.arc_increase:
        text += f", arc increase {study.arc_increase * 100:g} %"
    return text


def figures_html(result: AgeResult) -> str:
    """The result's main figures (mm) as a small HTML table."""
    f = result.figures
    hc = f.get("head_circumference_mm", {}) or {}
    res = f.get("hard_residual_mm", {}) or {}
    normed = [r for r in result.rows if r.constraint == "norms"]
    high = sum(1 for r in normed if abs(r.z_after) > 2 or abs(r.z_before) > 2)
    rows = [
        (
            "Head circumference",
            f"{hc.get('before')} → {hc.get('after')} mm (target {hc.get('target')})",
        ),
        (
            "  z-score",
            f"{_z_html(hc.get('z_before'))} → {_z_html(hc.get('z_after'))} ({hc.get('chart', '')})",
        ),
        ("Global scale", f"{f.get('global_scale')}"),
        (
            "Hard constraints",
            f"{f.get('hard_constraints')}: residual median {res.get('median')} mm, "
            f"max {res.get('max')} mm",
        ),
        ("Largest z change", f"{f.get('z_change_max')}"),
        ("|z| > 2", f"{high} of {len(normed)} measurements with norms"),
        ("Fold-overs", f"{f.get('fold_overs')}"),
    ]
    body = "".join(f"<tr><td>{k}</td><td>&nbsp;<b>{v}</b></td></tr>" for k, v in rows)
    notes = "".join(f"<br><i>note: {w}</i>" for w in result.warnings)
    unconstrained = f.get("unconstrained") or []
    if unconstrained:
        notes += f"<br><i>unconstrained (landmark missing): {', '.join(unconstrained)}</i>"
    return f"<table>{body}</table>{notes}"


def _z_html(z: Any) -> str:
    """A z-score, marked (as in the table) when it is beyond ±2."""
    from workbench.qt.panels.age_panel import HIGHLIGHT, out_of_range

    if not isinstance(z, (int, float)):
        return "–"
    if out_of_range(float(z)):
        return f"<span style='background-color:{HIGHLIGHT.name()}'>{z}</span>"
    return f"{z}"
