"""Nose, mouth and eye guides for skull-to-face reconstruction (Kähler 2003, §8.6.5, Fig. 8.20).

Units and frame: millimetres, head frame (x to the subject's left with x = 0
the midsagittal plane, y up, z toward the face, Frankfort Horizontal at y = 0).

A guide is data a user can move: a vertical line of the frontal view (fixes x
of the skin landmarks it affects), a horizontal line of the frontal view
(fixes y) or a point of the lateral view (fixes y and z).  After the first fit
(skin landmarks on the dowel tips) the guides move a few skin landmarks, and
the updated set drives a second warp of the pre-fitted head (Kähler Fig. 8.19).

Kähler's five rules (:func:`classic_guides`):

1. nose width: alare at the widest point of the nasal aperture + 5 mm per side;
2. nose tip (Krogman, via Taylor 2001 p. 443): pronasale 3 × the nasal-spine
   length in front of the mid-philtrum dowel tip;
3. mouth width: cheilia above the canine–first-premolar junctions;
4. lip margins: labrale superius / inferius at the cemento-enamel junctions of
   the upper / lower central incisors;
5. lip parting line slightly above the upper incisal edges (by the incisor
   display at rest, Vig & Brundo 1978).

:func:`guides_from_prediction` swaps in a published rule from
:mod:`workbench.services.guides.rules` for the same feature.
"""

from __future__ import annotations

import itertools
import json
import math
from collections.abc import Iterable, Mapping
from dataclasses import asdict, dataclass, replace
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np

from workbench.core.data_paths import DEFAULT_DEPTH_TABLE
from workbench.core.errors import InputError
from workbench.core.landmarks import LandmarkSet
from workbench.core.mesh import Mesh
from workbench.io.catalogue import load_catalogue
from workbench.services.guides.measure import SkullMeasures, measure_skull
from workbench.services.guides.rules import Prediction, load_rules

KINDS = {"vline": ("frontal", 1), "hline": ("frontal", 1), "point": ("lateral", 2)}
#: Coordinates (0 = x, 1 = y, 2 = z) each kind of guide fixes.
AXES = {"vline": (0,), "hline": (1,), "point": (1, 2)}
#: Skin landmarks of the nose's tip lobule that follow a nose-tip guide's move of
#: pronasale (an implementation choice: the guide rules place prn only).
TIP_LOBULE = ("c",)
#: Codes a guide may move besides the catalogue's skin landmarks.
EXTRA_TARGETS = ("eye_centre_l", "eye_centre_r")


@dataclass(frozen=True)
class Guide:
    """A movable guide line or point.

    Attributes
    ----------
    id : str
        E.g. ``"nose_width_l"``, ``"nose_tip"``, ``"lip_parting"``.
    kind : "vline" | "hline" | "point"
        vline fixes x (frontal view), hline fixes y (frontal view), point fixes (y, z) (lateral view).
    view : "frontal" | "lateral"
    value : tuple of float
        ``(x,)``, ``(y,)`` or ``(y, z)`` in mm.
    affects : tuple of str
        Skin landmark codes it moves (or ``eye_centre_l``/``eye_centre_r``).
    rule_id, citation : str
        The rule that placed it (``data_tables/guides/guide_rules.csv``).
    source : "computed" | "user"
    enabled : bool
    derivation : str
        How the value was obtained from the skull.
    """

    id: str
    label: str
    kind: str
    view: str
    value: tuple[float, ...]
    affects: tuple[str, ...]
    rule_id: str
    citation: str
    source: str = "computed"
    enabled: bool = True
    derivation: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "affects", tuple(self.affects))
        object.__setattr__(self, "value", _check_value(self.id, self.kind, self.view, self.value))
        if self.source not in ("computed", "user"):
            raise InputError(
                f"guide {self.id!r}", f"source must be 'computed' or 'user', not {self.source!r}"
            )
        if not self.affects or not all(isinstance(c, str) and c for c in self.affects):
            raise InputError(f"guide {self.id!r}", "affects must list at least one landmark code")

    def moved(self, value: Iterable[float] | float) -> Guide:
        """A copy at ``value``, marked as set by the user."""
        value = (value,) if isinstance(value, (int, float)) else tuple(value)
        return replace(self, value=value, source="user")


def _check_value(gid: str, kind: str, view: str, value: Any) -> tuple[float, ...]:
    where = f"guide {gid!r}"
    if kind not in KINDS:
        raise InputError(where, f"unknown kind {kind!r}", "use vline, hline or point")
    if view != KINDS[kind][0]:
        raise InputError(where, f"a {kind} belongs to the {KINDS[kind][0]} view, not {view!r}")
    try:
        seq = value if isinstance(value, (list, tuple, np.ndarray)) else [value]
        vals = tuple(float(v) for v in seq)
    except (TypeError, ValueError):
        raise InputError(where, f"value {value!r} is not numeric") from None
    if len(vals) != KINDS[kind][1]:
        raise InputError(where, f"a {kind} needs {KINDS[kind][1]} value(s), got {len(vals)}")
    if not all(math.isfinite(v) for v in vals):
        raise InputError(where, f"value {vals} is not finite")
    return vals


def _rule(rule_id: str) -> tuple[str, str]:
    r = load_rules()[rule_id]
    return rule_id, r.citation


def classic_guides(
    skull_landmarks: LandmarkSet,
    skull: Mesh | None = None,
    *,
    dowel_tips: Mapping[str, np.ndarray] | None = None,
    sex: str | None = None,
    spine_base: np.ndarray | None = None,
    table_id: str = DEFAULT_DEPTH_TABLE,
    problems: list[str] | None = None,
) -> list[Guide]:
    """Kähler's five guide rules, computed from a skull.

    Parameters
    ----------
    skull_landmarks : LandmarkSet
        Skull landmarks, head frame, mm.
    skull : Mesh, optional
        The skull (cranium, mandible and teeth as one mesh) in the same frame: gives
        the widest aperture, the base of the nasal spine, the incisal edge and the
        canine–premolar junctions; without it landmarks and cited typical values stand in.
    dowel_tips : {skull code: (3,)}, optional
        Tissue-depth dowel tips; ``"mp"`` (mid-philtrum) starts the nose-tip construction.
        Without it the tip is skull mp + the table's mean depth parallel to FH.
    sex : "female" | "male" | None
        Selects the incisor display at rest (lip parting line).
    spine_base : (3,), optional
        A user-marked base (begin) of the anterior nasal spine; see below.
    problems : list, optional
        Receives one line per guide that could not be derived and why.

    Notes
    -----
    Nose tip.  Kähler: "starting from the z value of the tissue-depth marker
    directly below the nose (mid-philtrum), the line [of the nasal spine] is
    extended by 3 × the nasal-spine length and prn is placed there".  Which
    direction the line has is not said.  With a user-marked ``spine_base`` we
    follow the text literally: on the line base→ans, find the point whose z is the
    mid-philtrum dowel tip's, and go 3 × |ans − base| further along it.  Without
    it the base cannot be located reliably on a surface, and a base taken on the
    aperture margin tilts the line by tens of degrees; so the spine is taken
    parallel to FH (the palate and spine lie close to it): prn = (y of ans,
    z of the mid-philtrum dowel tip + 3 × the spine's forward projection beyond
    the maxilla beneath it), which is the usual statement of Krogman's rule
    (projection = 3 × spine length + mid-philtrum depth).  The tip's height is the
    weakest part of the rule (Stephan et al. 2003 found it performs poorly); the
    guide is a lateral-view point the user is expected to check.
    """
    m = measure_skull(skull_landmarks, skull, dowel_tips=dowel_tips, sex=sex, table_id=table_id)
    out: list[Guide] = []

    def skip(what: str, names: Iterable[str]) -> bool:
        absent = [f"{n}: {m.missing.get(n, 'not measured')}" for n in names if n not in m]
        if absent and problems is not None:
            problems.append(f"{what} guide not derived ({'; '.join(absent)})")
        return bool(absent)

    rules = load_rules()

    def lateral(rule_id: str, name: str, side: str, sign: float) -> float:
        """A per-side rule on |x|, mirrored back to the side."""
        return sign * rules[rule_id].evaluate(
            {rules[rule_id].terms[0][1]: abs(m[f"{name}_{side}"])}
        )

    width = rules["kaehler_nose_width"]
    for side, sign, word in (("l", 1.0, "left"), ("r", -1.0, "right")):
        if not skip(f"nose width ({word})", [f"aperture_x_{side}"]):
            out.append(
                Guide(
                    f"nose_width_{side}",
                    f"Nose width ({word} ala)",
                    "vline",
                    "frontal",
                    (lateral(width.rule_id, "aperture_x", side, sign),),
                    (f"al_{side}",),
                    *_rule(width.rule_id),
                    derivation=f"{_how(m, f'aperture_x_{side}')} + {width.intercept} mm",
                )
            )

    if not skip("nose tip", ["spine_projection", "mp_dowel_z", "ans_y", "ans_z"]):
        out.append(_nose_tip(m, rules["krogman_nose_tip"], spine_base))

    for side, sign, word in (("l", 1.0, "left"), ("r", -1.0, "right")):
        if not skip(f"mouth width ({word})", [f"cp_junction_x_{side}"]):
            out.append(
                Guide(
                    f"mouth_width_{side}",
                    f"Mouth width ({word} corner)",
                    "vline",
                    "frontal",
                    (lateral("kaehler_mouth_width", "cp_junction_x", side, sign),),
                    (f"ch_{side}",),
                    *_rule("kaehler_mouth_width"),
                    derivation=_how(m, f"cp_junction_x_{side}"),
                )
            )
    for gid, label, name, code, rule in (
        ("lip_upper_margin", "Upper lip margin", "upper_cej_y", "ls", "kaehler_lip_upper"),
        ("lip_lower_margin", "Lower lip margin", "lower_cej_y", "li", "kaehler_lip_lower"),
    ):
        if not skip(label.lower(), [name]):
            out.append(
                Guide(
                    gid,
                    label,
                    "hline",
                    "frontal",
                    (rules[rule].evaluate(m.numbers()),),
                    (code,),
                    *_rule(rule),
                    derivation=_how(m, name),
                )
            )
    if not skip("lip parting line", ["incisal_edge_y"]):
        out.append(
            Guide(
                "lip_parting",
                "Lip parting line",
                "hline",
                "frontal",
                (rules["kaehler_lip_parting"].evaluate(m.numbers()),),
                ("sto", "ch_l", "ch_r"),
                *_rule("kaehler_lip_parting"),
                derivation=f"{_how(m, 'incisal_edge_y')} + {_how(m, 'incisor_display')}",
            )
        )
    return out


def _how(m: SkullMeasures, *names: str) -> str:
    """How the measurements ``names`` were taken, for a guide's derivation (mm)."""
    return "; ".join(f"{n} = {m[n]:.1f} mm from {m.values[n].how}" for n in names)


def _nose_tip(m: SkullMeasures, krogman: Any, spine_base: np.ndarray | None) -> Guide:
    """The nose-tip guide (lateral view: y, z of pronasale, mm) by Krogman's rule; see
    :func:`classic_guides` for the spine line with and without a given ``spine_base``."""
    factor = {p: c for c, p in krogman.terms}["spine_projection"]
    ans = np.array([m["ans_y"], m["ans_z"]])
    if spine_base is not None:
        base = np.asarray(spine_base, float).reshape(3)[1:]
        u = ans - base
        length = float(np.linalg.norm(u))
        if not np.isfinite(length) or length < 1.0 or u[1] < 0.2 * length:
            raise InputError(
                "spine_base",
                "the spine base must lie at least 1 mm behind ans, with the spine pointing forward",
            )
        u /= length
        tip = ans + (m["mp_dowel_z"] - ans[1]) / u[1] * u + factor * length * u
        text = f"spine line from the given base, length {length:.1f} mm"
    else:
        tip = np.array([ans[0], krogman.evaluate(m.numbers())])
        text = _how(m, "spine_projection") + "; spine line parallel to FH through ans"
    return Guide(
        "nose_tip",
        "Nose tip (pronasale)",
        "point",
        "lateral",
        tuple(tip),
        ("prn",),
        *_rule("krogman_nose_tip"),
        derivation=f"{text}; {_how(m, 'mp_dowel_z')}; factor {factor}",
    )


def guides_from_prediction(pred: Prediction, guides: list[Guide]) -> list[Guide]:
    """Replace the guides of the feature ``pred`` predicts by guides at its target.

    For every target code: a finite x replaces the vline affecting it, finite
    (y, z) the lateral point (z alone keeps the point's current y), y alone the
    hline.  Guides that do not exist yet are added (e.g. ``eye_centre_l_x`` /
    ``eye_centre_l_yz`` for an eyeball rule).  Other guides are returned unchanged.
    """
    out = list(guides)
    if not pred.target:
        raise InputError(pred.rule_id, "this rule predicts a value only, not a position")
    for code, pos in pred.target.items():
        x, y, z = (float(v) for v in np.asarray(pos, float).reshape(3))
        wanted: list[tuple[str, tuple[float, ...]]] = []
        if math.isfinite(x) and code not in ("prn", "sto", "ls", "li"):  # midline codes keep x = 0
            wanted.append(("vline", (x,)))
        if math.isfinite(z):
            wanted.append(("point", (y, z)))
        elif math.isfinite(y):
            wanted.append(("hline", (y,)))
        for kind, value in wanted:
            idx = [i for i, g in enumerate(out) if g.kind == kind and code in g.affects]
            if kind == "point" and not math.isfinite(value[0]):
                if not idx:
                    raise InputError(
                        pred.rule_id,
                        f"the rule fixes only z of {code} and there is "
                        "no lateral guide to take y from",
                    )
                value = (out[idx[0]].value[0], value[1])
            new: dict[str, Any] = {
                "rule_id": pred.rule_id,
                "citation": pred.citation,
                "source": "computed",
                "value": value,
                "derivation": f"{pred.label}: {pred.quantity} = {pred.value_mm:.1f} mm",
            }
            if idx:
                for i in idx:
                    out[i] = replace(out[i], **new)
            else:
                suffix = {"vline": "x", "hline": "y", "point": "yz"}[kind]
                out.append(
                    Guide(
                        id=f"{code}_{suffix}",
                        label=f"{code} ({pred.quantity})",
                        kind=kind,
                        view=KINDS[kind][0],
                        affects=(code,),
                        **new,
                    )
                )
    return out


def apply_guides(
    guides: Iterable[Guide], skin_targets: Mapping[str, np.ndarray]
) -> dict[str, np.ndarray]:
    """New target positions for the skin codes the enabled guides affect.

    A vline replaces x, an hline y, a lateral point (y, z); every other
    coordinate is kept.  Codes no enabled guide affects are not returned, but
    for the tip lobule (:data:`TIP_LOBULE`), which follows pronasale's move.

    Raises
    ------
    InputError
        A guide affects a code missing from ``skin_targets``, or two enabled guides
        set the same coordinate of the same code.
    """
    out: dict[str, np.ndarray] = {}
    owner: dict[tuple[str, int], str] = {}
    for g in guides:
        if not g.enabled:
            continue
        for code in g.affects:
            if code not in skin_targets:
                raise InputError(f"guide {g.id!r}", f"moves {code!r}, which has no target position")
            p = out.setdefault(code, np.array(skin_targets[code], dtype=float).reshape(3))
            for axis, v in zip(AXES[g.kind], g.value, strict=True):
                if (code, axis) in owner:
                    raise InputError(
                        f"guide {g.id!r}",
                        f"{code} {'xyz'[axis]} is already set by guide {owner[code, axis]!r}",
                        "disable one of them",
                    )
                owner[code, axis] = g.id
                p[axis] = v
    tip = out.get("prn")
    for code in TIP_LOBULE:
        if tip is not None and code in skin_targets and code not in out:
            # the tip lobule moves as one: the columella point goes with pronasale
            # (alone, a moved prn pulls the skin out into a beak)
            out[code] = np.asarray(skin_targets[code], float) + (tip - skin_targets["prn"])
    return out


def check_guides(
    guides: Iterable[Guide | Mapping[str, Any]], skull: Mesh | None, skull_landmarks: LandmarkSet
) -> list[str]:
    """Human-readable problems with the enabled guides (empty list = none found).

    Flags guides outside the skull's extent (mesh bounds, else the landmarks' with
    a 10 mm margin; the nose tip may stand up to 45 mm in front) and implausible
    placements: a nose wing inside the aperture or across the midline, a mouth corner
    medial to the canine eminence, lip lines above the anterior nasal spine or out
    of order, a nose tip behind the nasal spine.

    Raises
    ------
    InputError
        For entries that are not valid guides (NaN values, wrong kind or arity).
    """
    items = [g if isinstance(g, Guide) else guide_from_dict(g, "guides") for g in guides]
    lm = skull_landmarks.as_dict()
    if skull is not None and skull.n_vertices:
        lo, hi = skull.vertices.min(axis=0), skull.vertices.max(axis=0)
    elif lm:
        pts = np.array(list(lm.values()))
        lo, hi = pts.min(axis=0) - 10.0, pts.max(axis=0) + 10.0
    else:
        lo, hi = np.full(3, -np.inf), np.full(3, np.inf)
    problems = []
    ys: dict[str, float] = {}
    for g in (g for g in items if g.enabled):
        name = f"guide {g.id!r} ({g.label})"
        for axis, v in zip(AXES[g.kind], g.value, strict=True):
            top = hi[axis] + (45.0 if axis == 2 else 0.0)
            if not lo[axis] <= v <= top:
                problems.append(
                    f"{name}: {'xyz'[axis]} = {v:.1f} mm lies outside the skull "
                    f"({lo[axis]:.1f} … {top:.1f} mm)"
                )
        for code in g.affects:
            if g.kind == "hline":
                ys[code] = g.value[0]
            side = 1.0 if code.endswith("_l") else -1.0 if code.endswith("_r") else 0.0
            if g.kind == "vline" and side and side * g.value[0] <= 0:
                problems.append(f"{name}: {code} would cross the midline (x = {g.value[0]:.1f} mm)")
            elif g.kind == "vline" and code in ("al_l", "al_r"):
                apl = lm.get("apl" + code[2:])
                if apl is not None and side * (g.value[0] - apl[0]) < 0:
                    problems.append(
                        f"{name}: the nose wing lies inside the nasal aperture "
                        f"(|x| {abs(g.value[0]):.1f} < {abs(apl[0]):.1f} mm "
                        f"of apl{code[2:]})"
                    )
            elif g.kind == "vline" and code in ("ch_l", "ch_r"):
                sc = lm.get("sC" + code[2:])
                if sc is not None and side * (g.value[0] - sc[0]) < 0:
                    problems.append(
                        f"{name}: the mouth corner lies medial to the canine (sC{code[2:]})"
                    )
            elif g.kind == "point" and code == "prn" and "ans" in lm and g.value[1] <= lm["ans"][2]:
                problems.append(f"{name}: the nose tip lies behind the anterior nasal spine")
    if "ans" in lm:
        for code in ("sto", "ls", "li"):
            if code in ys and ys[code] > lm["ans"][1]:
                problems.append(
                    f"{code} line (y = {ys[code]:.1f} mm) lies above the anterior nasal spine"
                )
    order = [c for c in ("ls", "sto", "li") if c in ys]
    if any(ys[a] <= ys[b] for a, b in itertools.pairwise(order)):
        problems.append(
            "lip lines out of order: expected upper margin > parting line > lower margin "
            f"({', '.join(f'{c} {ys[c]:.1f}' for c in order)})"
        )
    return problems


# ------------------------------------------------------------------ JSON
FIELDS = (
    "id",
    "label",
    "kind",
    "view",
    "value",
    "affects",
    "rule_id",
    "citation",
    "source",
    "enabled",
    "derivation",
)


def guides_to_json(guides: Iterable[Guide]) -> list[dict[str, Any]]:
    """Plain dicts (JSON-ready) for case files and ``--guides FILE``."""
    return [asdict(g) | {"value": list(g.value), "affects": list(g.affects)} for g in guides]


def guide_from_dict(d: Any, source: str, index: int = 0) -> Guide:
    where = f"{source}: guide #{index + 1}"
    if not isinstance(d, Mapping):
        raise InputError(where, f"expected an object, got {type(d).__name__}")
    missing = [k for k in ("id", "kind", "view", "value", "affects") if k not in d]
    unknown = [k for k in d if k not in FIELDS]
    if missing or unknown:
        raise InputError(
            where,
            f"missing keys: {missing}" if missing else f"unknown keys: {unknown}",
            f"keys are {', '.join(FIELDS)}",
        )
    affects = d["affects"]
    if isinstance(affects, str) or not isinstance(affects, (list, tuple)):
        raise InputError(where, "affects must be a list of landmark codes")
    known = set(load_catalogue().codes("skin")) | set(EXTRA_TARGETS)
    bad = [c for c in affects if c not in known]
    if bad:
        raise InputError(where, f"unknown skin landmark code(s): {', '.join(map(str, bad))}")
    if not isinstance(d.get("enabled", True), bool):
        raise InputError(where, "enabled must be true or false")
    try:
        return Guide(
            str(d["id"]),
            str(d.get("label", d["id"])),
            d["kind"],
            d["view"],
            d["value"],
            tuple(affects),
            str(d.get("rule_id", "")),
            str(d.get("citation", "")),
            d.get("source", "user"),
            d.get("enabled", True),
            str(d.get("derivation", "")),
        )
    except InputError as exc:
        raise InputError(where, exc.problem, exc.hint) from None


def guides_from_json(data: Any, source: str | PathLike[str] | None = None) -> list[Guide]:
    """Guides from parsed JSON (a list of dicts, or ``{"guides": [...]}``) or from a file path.

    Raises InputError naming the file (or ``source``) and the guide at fault.
    """
    if isinstance(data, (str, PathLike)):
        path = Path(data)
        source = source or str(path)
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except OSError as exc:
            raise InputError(path, f"cannot read the guides file ({exc.strerror or exc})") from None
        except ValueError as exc:
            raise InputError(path, f"not valid JSON ({exc})") from None
    source = str(source or "guides")
    if isinstance(data, Mapping) and "guides" in data:
        data = data["guides"]
    if not isinstance(data, list):
        raise InputError(source, "expected a list of guides")
    out = [guide_from_dict(d, source, i) for i, d in enumerate(data)]
    dup = sorted({g.id for g in out if sum(h.id == g.id for h in out) > 1})
    if dup:
        raise InputError(source, f"duplicate guide ids: {', '.join(dup)}")
    return out
