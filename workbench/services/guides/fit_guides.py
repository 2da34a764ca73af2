"""The nose, mouth and eye guides of one fit: which guides, and which of them are applied.

Used by :func:`workbench.services.reconstruction.service.run_fit` (the one
pipeline of the command line, scripts and the window).  Guides come from the
case (:class:`~workbench.model.reconstruction_setup.GuideList`, set by the
user) or, when the case has none, are computed from the skull (Kähler's
classic guides); published prediction rules may replace the guide of their
feature.  Computed guides that fail their plausibility checks are switched
off with a note, never applied silently.

Units mm; guide values and skull geometry in the head frame (x to the
subject's left, y up, z toward the face, Frankfort Horizontal).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from workbench.core.landmarks import LandmarkSet
from workbench.core.mesh import Mesh
from workbench.model.reconstruction_setup import DEFAULT_TABLE, DowelSettings, GuideList
from workbench.services.guides.classic import (
    Guide,
    apply_guides,
    check_guides,
    classic_guides,
    guides_from_json,
    guides_from_prediction,
)
from workbench.services.guides.rules import DefaultRule, effective_rules, published_predictions
from workbench.services.tissue.dowels import DowelPlan

#: a computed width guide (nose, mouth) that predicts a width this many standard
#: deviations from the adult norm of every population and sex of the facial norms
#: table is taken as a failed skull measurement and switched off (4 SD: about 1 in
#: 16,000 people); the reference head's own width plays no part
MAX_NORM_SD = 4.0
#: the adult age (years) the width norms are read at
NORM_AGE = 30.0
#: width guides (left, right) and the facial-norm measurement of their width
WIDTH_NORMS = {
    ("nose_width_l", "nose_width_r"): "nasal_width",
    ("mouth_width_l", "mouth_width_r"): "labial_fissure_width",
}

SkinTargets = Callable[[dict[str, np.ndarray]], dict[str, np.ndarray]]


def stored_guides(guides: GuideList | None) -> list[Guide] | None:
    """The case's guides as :class:`Guide` objects (checked), or None: compute them."""
    if guides is None:
        return None
    return guides_from_json(guides.to_state(), "case guides")


def plausible_guides(
    guides: list[Guide],
    skin: dict[str, np.ndarray],
    skull_h: Mesh,
    lms_h: LandmarkSet,
    rejected: list[str],
    sex: str | None = None,
) -> dict[str, np.ndarray]:
    """Guide targets, leaving out computed guides that fail their checks.

    A guide set by the user is always applied.  A computed one is switched
    off in ``guides`` (and the reason recorded in ``rejected``) when
    ``check_guides`` finds it outside the skull or anatomically impossible
    (a wing inside the aperture, a mouth corner medial to the canine, lip lines
    out of order ...), or when the width it gives lies more than
    :data:`MAX_NORM_SD` standard deviations from the adult facial norms
    (:func:`width_problem`) — reasons the user can see against the skull in the
    guide views.  How far a guide moves the reference head's own landmark is no
    reason: the reference is not the person.
    """
    widths = {g.id: g for g in guides if g.enabled and g.source != "user" and g.kind == "vline"}
    for i, g in enumerate(guides):
        if not g.enabled or g.source == "user":
            continue
        problems = check_guides([g], skull_h, lms_h)
        why = problems[0] if problems else width_problem(g, widths, sex)
        if why:
            rejected.append(
                f"guide {g.id} switched off ({why}); check the skull there or set the guide by hand"
            )
            guides[i] = replace(g, enabled=False)
    return apply_guides(guides, skin)


def width_problem(guide: Guide, enabled: dict[str, Guide], sex: str | None) -> str:
    """Why a nose- or mouth-width guide gives an impossible width ("" when it does not).

    The width is the distance between the pair's two lines (twice the line's
    distance from the midline when its partner is off), compared with the adult
    norm (:data:`NORM_AGE` years) of the facial norms table for every population
    and, with the sex unknown, both sexes: the guide fails only when the width
    lies more than :data:`MAX_NORM_SD` SD from all of them.
    """
    from workbench.io.growth_norms import load_growth_norms

    for pair, measurement in WIDTH_NORMS.items():
        if guide.id not in pair:
            continue
        left, right = (enabled.get(k) for k in pair)
        width = (
            left.value[0] - right.value[0]
            if left is not None and right is not None
            else 2.0 * abs(guide.value[0])
        )
        norms = load_growth_norms()
        sexes = [sex] if sex in ("female", "male") else ["female", "male"]
        best: tuple[float, float, float, str] | None = None
        for eth in norms.ethnicities():
            for sx in sexes:
                if not norms.has(measurement, sx, eth):
                    continue
                lo, hi = norms.age_range(measurement, sx, eth)
                mean, sd = norms.at(measurement, sx, min(max(NORM_AGE, lo), hi), eth)
                z = (width - mean) / sd
                if best is None or abs(z) < abs(best[0]):
                    best = (z, mean, sd, f"{eth} {sx}, {norms.source_of(measurement, sx, eth)}")
        if best is not None and abs(best[0]) > MAX_NORM_SD:
            z, mean, sd, who = best
            return (
                f"it gives a {measurement.replace('_', ' ')} of {width:.1f} mm, {abs(z):.1f} SD "
                f"{'below' if z < 0 else 'above'} the closest adult norm {mean:.1f} ± {sd:.1f} mm "
                f"({who})"
            )
    return ""


@dataclass
class FitGuides:
    """The guide step of one fit; :meth:`__call__` is ``reconstruct``'s ``guides=``.

    After the fit, :attr:`chosen` holds the guides used (computed ones that
    failed their checks switched off) and :attr:`rejected` the notes on
    guides and rules that were not applied.
    """

    dowels: DowelSettings
    stored: list[Guide] | None = None
    rules: Sequence[str] = ()
    enabled: bool = True
    chosen: list[Guide] = field(default_factory=list)
    rejected: list[str] = field(default_factory=list)

    def __call__(self, skull_h: Mesh, lms_h: LandmarkSet, plan: DowelPlan) -> SkinTargets | None:
        if not self.enabled:
            return None
        tips = {d.code: d.tip for d in plan.active()}
        if self.stored is None:
            table = self.dowels.table if not self.dowels.table.endswith(".csv") else DEFAULT_TABLE
            missing: list[str] = []
            self.chosen.extend(
                classic_guides(
                    lms_h,
                    skull_h,
                    dowel_tips=tips,
                    sex=self.dowels.sex,
                    table_id=table,
                    problems=missing,
                )
            )
            self.rejected.extend(missing)
        else:
            self.chosen.extend(self.stored)
        asked, defaults = effective_rules(self.rules)
        if self.stored is not None:
            defaults = []  # the case's own guides: nothing replaces them unasked
        if asked or defaults:
            self._apply_rules(skull_h, lms_h, tips, asked, defaults)
        return lambda skin: plausible_guides(
            self.chosen, skin, skull_h, lms_h, self.rejected, self.dowels.sex
        )

    def _apply_rules(
        self,
        skull_h: Mesh,
        lms_h: LandmarkSet,
        tips: dict[str, np.ndarray],
        asked: list[str],
        defaults: list[DefaultRule],
    ) -> None:
        why: dict[str, list[str]] = {}
        ids = [*asked, *(d.rule_id for d in defaults)]
        problems: list[str] = []
        preds = published_predictions(
            lms_h, self.dowels.sex, rules=ids, skull=skull_h, dowel_tips=tips, problems=problems
        )
        for line in problems:
            why.setdefault(line.split(":", 1)[0], []).append(line.split(":", 1)[-1].strip())
        for pred in preds:
            if pred.target:
                self.chosen[:] = guides_from_prediction(pred, self.chosen)
        found = {p.rule_id for p in preds}
        for r in asked:
            if r not in found:
                reason = "; ".join(why.get(r, [])) or "no prediction for this skull"
                self.rejected.append(f"published rule {r} not applied: {reason}")
        for d in defaults:
            if d.rule_id not in found:
                # the classic guide of those landmarks stays (it was computed, or it says
                # itself why it could not be)
                reason = "; ".join(why.get(d.rule_id, [])) or "no prediction for this skull"
                self.rejected.append(
                    f"default rule {d.rule_id} not applied ({reason}); "
                    f"the classic guide {d.replaces} stays where it could be measured"
                )

    def problems(self, skull_h: Mesh, lms_h: LandmarkSet) -> list[str]:
        """Checks of the enabled guides on the fitted frame (notes for the report)."""
        enabled = [g for g in self.chosen if g.enabled]
        return [f"guide: {p}" for p in check_guides(enabled, skull_h, lms_h)] if enabled else []
