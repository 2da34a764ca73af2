"""Published nose, mouth and eye prediction rules (and Kähler's classic ones) as data.

Units and frame: millimetres, head frame (x to the subject's left with x = 0
the midsagittal plane, y up, z toward the face, Frankfort Horizontal at y = 0).

The rules live in ``data_tables/guides/guide_rules.csv`` with their primary
citations in ``guides.meta.json``: Rynn, Wilkinson & Peters (2010) and its
recalibrations (Sarilita et al. 2018, Bulut et al. 2019) for the nose, Stephan
(2003) and Stephan & Henneberg (2003) for the mouth, Guyomarc'h et al. (2012)
and Stephan (2002), Stephan, Huang & Davidson (2009) for the eyeball.  Rows whose
attribution is inconsistent in the source are kept but never offered by default.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from workbench.core.data_paths import DEFAULT_DEPTH_TABLE
from workbench.core.errors import InputError
from workbench.core.landmarks import LandmarkSet
from workbench.core.mesh import Mesh
from workbench.services.guides.measure import (
    SIDES,
    SkullMeasures,
    citation,
    constant,
    guides_dir,
    guides_meta,
    measure_skull,
    parse_number,
    read_table_csv,
    sex_code,
)

RULE_COLUMNS = (
    "rule_id",
    "feature",
    "kind",
    "quantity",
    "target",
    "formula",
    "intercept_mm",
    "coef_1",
    "predictor_1",
    "coef_2",
    "predictor_2",
    "sex",
    "population",
    "n",
    "reported_error",
    "uses",
    "offered",
    "status",
    "source",
    "where_read",
    "notes",
)


@dataclass(frozen=True)
class Rule:
    """One row of ``guide_rules.csv`` (see the README there)."""

    rule_id: str
    feature: str
    kind: str
    quantity: str
    target: tuple[str, ...]
    formula: str
    intercept: float
    terms: tuple[tuple[float, str], ...]
    sex: str
    population: str
    reported_error: str
    uses: tuple[str, ...]
    offered: str
    status: str
    citation: str
    where_read: str
    notes: str

    def evaluate(self, values: Mapping[str, float]) -> float:
        """``intercept + Σ coef · predictor`` (mm)."""
        return self.intercept + sum(c * values[p] for c, p in self.terms)

    def suits(self, sex: str | None) -> bool:
        return self.sex == "pooled" or (sex is not None and self.sex == sex)


@lru_cache(maxsize=1)
def load_rules() -> dict[str, Rule]:
    """All rules of ``guide_rules.csv`` by id; raises InputError naming the line on bad rows."""
    path = guides_dir() / "guide_rules.csv"
    where = guides_meta()["where_read"]
    out: dict[str, Rule] = {}
    for line, r in read_table_csv(path, RULE_COLUMNS):
        terms = tuple(
            (parse_number(path, line, f"coef_{k}", r[f"coef_{k}"]), r[f"predictor_{k}"])
            for k in (1, 2)
            if r[f"predictor_{k}"]
        )
        if r["sex"] not in ("pooled", "M", "F") or r["rule_id"] in out:
            raise InputError(path, f"line {line}: bad sex or duplicate rule {r['rule_id']!r}")
        out[r["rule_id"]] = Rule(
            r["rule_id"],
            r["feature"],
            r["kind"],
            r["quantity"],
            tuple(t for t in r["target"].split(";") if t),
            r["formula"],
            parse_number(path, line, "intercept_mm", r["intercept_mm"], 0.0),
            terms,
            r["sex"],
            r["population"],
            r["reported_error"],
            tuple(u for u in r["uses"].split(";") if u),
            r["offered"],
            r["status"],
            citation(r["source"]),
            where.get(r["where_read"], r["where_read"]),
            r["notes"],
        )
    return out


DEFAULT_COLUMNS = ("rule_id", "replaces", "why")


@dataclass(frozen=True)
class DefaultRule:
    """A published rule applied by default in place of a classic guide (``guide_defaults.csv``)."""

    rule_id: str
    replaces: str
    why: str


@lru_cache(maxsize=1)
def load_guide_defaults() -> tuple[DefaultRule, ...]:
    """The rules applied without ``--rule``, each with the validation that chose it."""
    path = guides_dir() / "guide_defaults.csv"
    rules = load_rules()
    out = []
    for line, r in read_table_csv(path, DEFAULT_COLUMNS):
        for col in ("rule_id", "replaces"):
            if r[col] not in rules:
                raise InputError(path, f"line {line}: {col} {r[col]!r} is not in guide_rules.csv")
        if rules[r["replaces"]].kind != "classic" or rules[r["rule_id"]].kind == "classic":
            raise InputError(path, f"line {line}: a published rule must replace a classic one")
        out.append(DefaultRule(r["rule_id"], r["replaces"], r["why"]))
    return tuple(out)


def effective_rules(asked: Iterable[str]) -> tuple[list[str], list[DefaultRule]]:
    """The rules a fit applies: the published ones asked for, and the defaults of
    :func:`load_guide_defaults` for every feature the user did not choose a rule for.

    Asking for a classic rule (e.g. ``kaehler_mouth_width``) keeps Kähler's guide for
    its landmarks instead of the default rule.  Returns (published rules asked for,
    defaults applied).
    """
    rules = load_rules()
    asked = list(asked)
    chosen = {t for r in asked if r in rules for t in rules[r].target}
    defaults = [
        d
        for d in load_guide_defaults()
        if not chosen & set(rules[d.rule_id].target) and d.rule_id not in asked
    ]
    return [r for r in asked if r in rules and rules[r].kind != "classic"], defaults


@dataclass(frozen=True)
class Prediction:
    """One published rule applied to a skull.

    Attributes
    ----------
    rule_id, label, quantity : str
    value_mm : float
        The predicted quantity (mm); for positions the quantity named in ``quantity``.
    target : dict
        ``{skin code or "eye_centre_l"/"eye_centre_r": (3,) position}`` in the head
        frame; NaN coordinates are not constrained by the rule (e.g. a mouth-width
        rule fixes only x of the cheilia).  Empty when the rule gives a value only.
    inputs : dict
        Skull measurements and intermediate values used (mm).
    citation, notes : str
    """

    rule_id: str
    label: str
    quantity: str
    value_mm: float
    target: dict[str, np.ndarray] = field(default_factory=dict)
    inputs: dict[str, float] = field(default_factory=dict)
    citation: str = ""
    notes: str = ""


class _Missing(Exception):
    pass


def _need(m: SkullMeasures, names: Iterable[str]) -> None:
    absent = [f"{n} ({m.missing.get(n, 'not measured')})" for n in names if n not in m]
    if absent:
        raise _Missing("; ".join(absent))


def _point(x: float = np.nan, y: float = np.nan, z: float = np.nan) -> np.ndarray:
    return np.array([x, y, z], dtype=float)


def _rynn_point(rule: Rule, m: SkullMeasures, table: Mapping[str, Rule]) -> Prediction:
    pa_rule, pv_rule = (table[u] for u in rule.uses)
    _need(m, [p for r in (pa_rule, pv_rule) for _, p in r.terms] + ["n_y", "n_z", "pr_y", "pr_z"])
    vals = m.numbers()
    pa, pv = pa_rule.evaluate(vals), pv_rule.evaluate(vals)
    n = np.array([m["n_y"], m["n_z"]])
    e = np.array([m["pr_y"], m["pr_z"]]) - n
    e /= np.linalg.norm(e)  # down along the nasion–prosthion line
    perp = np.array([e[1], -e[0]])
    perp = perp if perp[1] > 0 else -perp  # forward, perpendicular to it
    y, z = n + pa * perp + pv * e
    inputs = {p: vals[p] for r in (pa_rule, pv_rule) for _, p in r.terms} | {"PA": pa, "PV": pv}
    return Prediction(rule.rule_id, "", rule.quantity, pa, {"prn": _point(0.0, y, z)}, inputs)


def _eye_centres(rule: Rule, m: SkullMeasures, table: Mapping[str, Rule]) -> Prediction:
    half = 0.5 * constant("eye_axial_length")
    target: dict[str, np.ndarray] = {}
    inputs: dict[str, float] = {}
    proj: list[float] = []
    for side, sign in SIDES:
        if f"OBH_{side}" not in m:
            continue
        v = {k[:-2]: val for k, val in m.numbers().items() if k.endswith("_" + side)}
        if rule.rule_id == "eye_guyomarch2012_globe":
            si, ml, ap = (table[u].evaluate(v) for u in rule.uses[:3])
            apex = _point(v["d_x"] + sign * ml, v["sk_y"] - si, v["dlom_z"] + ap)
            inputs |= {f"SI_{side}": si, f"ML_{side}": ml, f"AP_{side}": ap}
        elif rule.rule_id == "eye_stephan2009_globe":
            apex = _point(
                v["orbit_cx"] + sign * constant("stephan2009_lateral_offset"),
                v["orbit_cy"] + constant("stephan2009_superior_offset"),
                v["dlom_z"] + constant("stephan2009_globe_projection"),
            )
        elif rule.rule_id == "eye_stephan2002_projection":
            apex = _point(z=v["tangent_z"] + constant("stephan2002_tangent_offset"))
        else:
            raise InputError(rule.rule_id, "no construction is implemented for this eye rule")
        inputs |= {f"{k}_{side}": v[k] for k in ("OBH", "OBB", "sk_y", "d_x", "dlom_z")}
        target[f"eye_centre_{side}"] = apex - _point(0.0, 0.0, half)
        proj.append(apex[2] - v["dlom_z"])
    if not target:
        raise _Missing(m.missing.get("OBH_l", "orbit landmarks"))
    return Prediction(
        rule.rule_id,
        "",
        "corneal apex in front of the lateral orbital margin",
        float(np.mean(proj)),
        target,
        inputs,
    )


def _predict(rule: Rule, m: SkullMeasures, table: Mapping[str, Rule]) -> Prediction:
    vals = m.numbers()
    if rule.feature == "eye" and rule.kind == "construction":
        return _eye_centres(rule, m, table)
    if rule.feature == "nose" and rule.kind == "construction" and len(rule.uses) == 2:
        return _rynn_point(rule, m, table)
    if rule.feature == "eye":  # a component proportion, reported for the left side (else right)
        side = "l" if "OBH_l" in m else "r"
        _need(m, [f"{p}_{side}" for _, p in rule.terms])
        value = rule.evaluate({p: vals[f"{p}_{side}"] for _, p in rule.terms})
        return Prediction(
            rule.rule_id,
            "",
            rule.quantity,
            value,
            {},
            {f"{p}_{side}": vals[f"{p}_{side}"] for _, p in rule.terms},
        )
    preds = [p for _, p in rule.terms]
    if {"canine_pupil_sum", "interpupillary_width"} & set(preds):
        eyes = _eye_centres(table["eye_guyomarch2012_globe"], m, table).target
        if len(eyes) < 2 or "canine_x_l" not in m or "canine_x_r" not in m:
            raise _Missing("both pupils (orbit landmarks) and both canines")
        pl, pr_ = eyes["eye_centre_l"][0], eyes["eye_centre_r"][0]
        vals |= {
            "pupil_x_l": pl,
            "pupil_x_r": pr_,
            "interpupillary_width": pl - pr_,
            "canine_pupil_sum": (pl - vals["canine_x_l"]) + (vals["canine_x_r"] - pr_),
        }
    else:
        _need(m, preds)
    value = rule.evaluate(vals)
    inputs = {p: vals[p] for p in preds} | {
        k: vals[k] for k in ("pupil_x_l", "pupil_x_r") if k in vals
    }
    target: dict[str, np.ndarray] = {}
    quantity = rule.quantity
    if rule.feature == "mouth":
        key = "cp_junction_x" if "cp_junction_width" in preds else "canine_x"
        _need(m, [f"{key}_l", f"{key}_r"])
        mid = 0.5 * (vals[f"{key}_l"] + vals[f"{key}_r"])
        target = {"ch_l": _point(mid + 0.5 * value), "ch_r": _point(mid - 0.5 * value)}
    elif "aperture_width" in preds:  # alar width, centred on the aperture
        mid = 0.5 * (vals["aperture_x_l"] + vals["aperture_x_r"])
        target = {"al_l": _point(mid + 0.5 * value), "al_r": _point(mid - 0.5 * value)}
    elif rule.quantity == "pFHP":
        _need(m, ["ss_z"])
        target = {"prn": _point(0.0, np.nan, vals["ss_z"] + value)}
    elif "spine_projection" in preds:  # threefold-ANS type: the formula gives prn z
        _need(m, ["ans_y"])
        target = {"prn": _point(0.0, vals["ans_y"], value)}
        value = value - vals["mp_dowel_z"]
        quantity = "nose projection in front of the mid-philtrum dowel tip"
    return Prediction(rule.rule_id, "", quantity, value, target, inputs)


def published_predictions(
    skull_landmarks: LandmarkSet,
    sex: str | None,
    *,
    rules: Iterable[str] | None = None,
    skull: Mesh | None = None,
    dowel_tips: Mapping[str, np.ndarray] | None = None,
    table_id: str = DEFAULT_DEPTH_TABLE,
    problems: list[str] | None = None,
) -> list[Prediction]:
    """Apply published prediction rules to a skull.

    Parameters
    ----------
    skull_landmarks : LandmarkSet
        Skull landmarks in the head frame (mm).
    sex : "female" | "male" | None
        Selects sex-specific rules; with None only pooled rules are chosen by default.
    rules : ids, optional
        Rule ids of ``data_tables/guides/guide_rules.csv``.  Default: every rule
        offered ``default`` whose sex fits.  Asked-for rules are computed even when
        not offered by default (attribution-inconsistent ones say so in ``notes``).
    skull : Mesh, optional
        The skull (with teeth) for the canine measurements (see :func:`measure_skull`).
    problems : list, optional
        Receives one line per rule that could not be computed and why.

    Raises
    ------
    InputError
        Unknown rule ids or sex.
    """
    sx = sex_code(sex)
    table = load_rules()
    if rules is None:
        chosen = [r for r in table.values() if r.offered == "default" and r.suits(sx)]
    else:
        ids = list(rules)
        bad = [i for i in ids if i not in table or table[i].kind == "classic"]
        if bad:
            known = sorted(k for k, r in table.items() if r.kind != "classic")
            raise InputError(
                "rules",
                f"unknown prediction rule(s): {', '.join(bad)}",
                f"known rules: {', '.join(known)}",
            )
        chosen = [table[i] for i in ids]
    m = measure_skull(skull_landmarks, skull, dowel_tips=dowel_tips, sex=sx, table_id=table_id)
    out = []
    for rule in chosen:
        try:
            pred = _predict(rule, m, table)
        except _Missing as exc:
            if problems is not None:
                problems.append(f"{rule.rule_id}: not computed, missing {exc}")
            continue
        notes = [rule.notes] if rule.notes else []
        if rule.status == "attribution_inconsistent":
            notes.insert(0, "NOT OFFERED: the source attributes this equation inconsistently")
        elif rule.status == "secondary":
            notes.append(
                "coefficients from a secondary transcription, not checked against the paper"
            )
        if rule.sex != "pooled" and rule.sex != sx:
            who = "women" if rule.sex == "F" else "men"
            notes.append(f"rule is for {who}; subject sex: {sex or 'unknown'}")
        if rule.reported_error:
            notes.append(f"reported error: {rule.reported_error}")
        cite = rule.citation + (f" (read in: {rule.where_read})" if rule.where_read else "")
        label = f"{rule.quantity} ({rule.rule_id}; {rule.population or 'pooled'}, {rule.sex})"
        out.append(
            Prediction(
                pred.rule_id,
                label,
                pred.quantity,
                float(pred.value_mm),
                pred.target,
                pred.inputs,
                cite,
                "; ".join(notes),
            )
        )
    return out
