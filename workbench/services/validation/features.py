"""Nose, mouth and eye features of a reconstruction against the true skin's landmarks.

Units mm.  Everything is compared in the reconstruction's head frame (x to the
subject's left with x = 0 the midsagittal plane, y up, z toward the face,
Frankfort Horizontal at y = 0): true landmarks given in the case's input frame
are carried into it by the registration's ``input_to_head``.

``workbench validate`` calls :func:`feature_errors` for the delivered face (the
default guides), for the same reconstruction without guides, and for every
guide rule on its own (:func:`rule_landmarks`: the landmark coordinates each
classic guide or published rule fixes, before any fit), so each rule's error is
shown beside the others and beside no guide.

Features (signed where a direction means something: predicted − true):

========================  =====================================================
``prn_mm``                pronasale, 3D distance
``prn_projection_mm``     pronasale, forward (z) difference
``alar_width_mm``         al_l − al_r across (x), predicted − true
``mouth_width_mm``        ch_l − ch_r across (x), predicted − true
``ls_height_mm``          labrale superius, vertical (y) difference
``sto_height_mm``         stomion, vertical difference
``li_height_mm``          labrale inferius, vertical difference
``en_mm``, ``ex_mm``      endo- and exocanthion, 3D distance (mean of the sides)
========================  =====================================================

A feature is left out when the truth does not have it in view (the truth file
marks it absent) or the prediction does not fix it.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from workbench.core.errors import InputError
from workbench.core.landmarks import LandmarkSet
from workbench.core.mesh import Mesh

#: feature -> (codes, kind); kind: "point" 3D distance, "axis:<k>" signed coordinate
#: difference, "width" the x difference of a left/right pair
FEATURES: dict[str, tuple[tuple[str, ...], str]] = {
    "prn_mm": (("prn",), "point"),
    "prn_projection_mm": (("prn",), "axis:2"),
    "alar_width_mm": (("al_l", "al_r"), "width"),
    "mouth_width_mm": (("ch_l", "ch_r"), "width"),
    "ls_height_mm": (("ls",), "axis:1"),
    "sto_height_mm": (("sto",), "axis:1"),
    "li_height_mm": (("li",), "axis:1"),
    "en_mm": (("en_l", "en_r"), "point"),
    "ex_mm": (("ex_l", "ex_r"), "point"),
}
#: published or pragmatic targets (issue: pronasale 4 mm, alar width 3 mm, mouth width
#: 5 mm, canthi 3 mm); the validation table says whether each is reached
TARGETS_MM = {
    "prn_mm": 4.0,
    "alar_width_mm": 3.0,
    "mouth_width_mm": 5.0,
    "en_mm": 3.0,
    "ex_mm": 3.0,
}


@dataclass(frozen=True)
class TruthLandmarks:
    """True soft-tissue landmarks of a case: positions (input frame, mm) and the codes
    the file marks absent (not in view), with the reason when it gives one."""

    landmarks: LandmarkSet
    absent: dict[str, str]
    path: Path

    @property
    def positions(self) -> dict[str, np.ndarray]:
        return self.landmarks.as_dict()


def read_truth_landmarks(path: str | Path) -> TruthLandmarks:
    """A truth landmark file (any format :func:`workbench.io.markups.read_landmarks`
    reads, surface ``skin``).  InputError naming the file when it has none of the
    features' landmarks."""
    from workbench.io.markups import read_landmarks

    p = Path(path)
    read = read_landmarks(p, "skin", allow_undefined=True)
    positions = read.landmarks.as_dict()
    absent = {
        lm.code: lm.description or "not in view" for lm in read.landmarks if not lm.is_defined
    }
    wanted = {c for codes, _ in FEATURES.values() for c in codes}
    if not wanted & set(positions):
        raise InputError(
            p,
            "no nose, mouth or eye landmark with a position",
            f"expected some of {', '.join(sorted(wanted))}",
        )
    return TruthLandmarks(read.landmarks.defined(), absent, p)


def _swapped(code: str) -> str:
    return code[:-2] + {"_l": "_r", "_r": "_l"}[code[-2:]] if code[-2:] in ("_l", "_r") else code


def feature_errors(
    predicted: Mapping[str, np.ndarray], truth: Mapping[str, np.ndarray]
) -> dict[str, float]:
    """Errors (mm) of the features both sides have; NaN coordinates in ``predicted``
    are coordinates a rule does not fix (a vertical guide line fixes x only).

    Left and right are compared without trusting the labels' handedness: a skull is
    nearly symmetric, so an automatic registration may read a file's left as the
    head's right (it says so as ``handedness: assumed``); widths are taken as
    magnitudes and a left/right pair is matched the way that fits best.
    """
    pairs = [(f"{c}_l", f"{c}_r") for c in ("ex", "ch", "al", "en")]
    pair = next((p for p in pairs if p[0] in truth and p[1] in truth), None)
    if pair is not None and truth[pair[0]][0] < truth[pair[1]][0]:  # the other way round
        truth = {_swapped(c): v for c, v in truth.items()}
    out: dict[str, float] = {}
    for name, (codes, kind) in FEATURES.items():
        if not all(c in truth for c in codes) or not all(c in predicted for c in codes):
            continue
        p = [np.asarray(predicted[c], float) for c in codes]
        t = [np.asarray(truth[c], float) for c in codes]
        if kind == "point":
            if any(not np.isfinite(v).all() for v in p):
                continue
            out[name] = float(np.mean([np.linalg.norm(a - b) for a, b in zip(p, t, strict=True)]))
        elif kind == "width":
            if not (np.isfinite(p[0][0]) and np.isfinite(p[1][0])):
                continue
            out[name] = float(abs(p[0][0] - p[1][0]) - abs(t[0][0] - t[1][0]))
        else:
            k = int(kind.split(":")[1])
            if not np.isfinite(p[0][k]):
                continue
            out[name] = float(p[0][k] - t[0][k])
    return out


def rule_landmarks(
    skull_h: Mesh,
    lms_h: LandmarkSet,
    sex: str | None,
    dowel_tips: Mapping[str, np.ndarray],
) -> tuple[dict[str, dict[str, np.ndarray]], dict[str, str]]:
    """What every classic guide and every published rule of the nose and mouth (and the
    eyeball rules' canthi-free centres left aside) predicts for this skull.

    Returns ({rule id: {skin code: (3,) with NaN for coordinates the rule does not
    fix}}, {rule id: why it could not be computed}).
    """
    from workbench.services.guides.classic import AXES, classic_guides
    from workbench.services.guides.measure import sex_code
    from workbench.services.guides.rules import (
        load_guide_defaults,
        load_rules,
        published_predictions,
    )

    out: dict[str, dict[str, np.ndarray]] = {}
    why: dict[str, str] = {}
    problems: list[str] = []
    for g in classic_guides(lms_h, skull_h, dowel_tips=dowel_tips, sex=sex, problems=problems):
        pts = out.setdefault(g.rule_id, {})
        for code in g.affects:
            p = pts.setdefault(code, np.full(3, np.nan))
            for axis, v in zip(AXES[g.kind], g.value, strict=True):
                p[axis] = v
    for line in problems:
        why.setdefault("classic", line)
    table = load_rules()
    defaults = {d.rule_id for d in load_guide_defaults()}  # applied whatever the sex
    ids = [
        r.rule_id
        for r in table.values()
        if r.feature in ("nose", "mouth")
        and r.kind != "classic"
        and r.target
        and r.offered in ("default", "optional")
        and (r.suits(sex_code(sex)) or r.rule_id in defaults)
    ]
    problems = []
    for pred in published_predictions(
        lms_h, sex, rules=ids, skull=skull_h, dowel_tips=dowel_tips, problems=problems
    ):
        if pred.target:
            out[pred.rule_id] = {c: np.asarray(v, float) for c, v in pred.target.items()}
    for line in problems:
        rid, _, text = line.partition(":")
        why[rid] = text.strip()
    return out, why
