"""The nose, mouth and eye guides of one fit: which guides, and which of them are applied.

Used by :func:`workbench.services.reconstruction_service.run_fit` (the one
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
from workbench.services.dowels import DowelPlan
from workbench.services.guide_rules import published_predictions
from workbench.services.guides import (
    Guide,
    apply_guides,
    check_guides,
    classic_guides,
    guides_from_prediction,
    guides_from_json,
)

#: a computed guide that would move its skin landmark farther than this from
#: the tissue-depth fit is taken as a failed skull measurement and switched off
MAX_GUIDE_SHIFT_MM = 8.0

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
) -> dict[str, np.ndarray]:
    """Guide targets, leaving out computed guides that fail their checks.

    A guide set by the user is always applied.  A computed one is switched
    off in ``guides`` (and the reason recorded in ``rejected``) when
    ``check_guides`` finds it outside the skull or anatomically impossible,
    or when it would move its landmark more than :data:`MAX_GUIDE_SHIFT_MM`
    from the tissue-depth fit — never a silently distorted face.
    """
    for i, g in enumerate(guides):
        if not g.enabled or g.source == "user":
            continue
        problems = check_guides([g], skull_h, lms_h)
        shift = max(
            (float(np.linalg.norm(p - skin[c])) for c, p in apply_guides([g], skin).items()),
            default=0.0,
        )
        if problems or shift > MAX_GUIDE_SHIFT_MM:
            why = (
                problems[0]
                if problems
                else f"it would move {', '.join(g.affects)} by {shift:.1f} mm"
            )
            rejected.append(
                f"guide {g.id} switched off ({why}); check the skull there or set the guide by hand"
            )
            guides[i] = replace(g, enabled=False)
    return apply_guides(guides, skin)


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
            self.chosen.extend(
                classic_guides(lms_h, skull_h, dowel_tips=tips, sex=self.dowels.sex, table_id=table)
            )
        else:
            self.chosen.extend(self.stored)
        if self.rules:
            self._apply_rules(skull_h, lms_h, tips)
        return lambda skin: plausible_guides(self.chosen, skin, skull_h, lms_h, self.rejected)

    def _apply_rules(self, skull_h: Mesh, lms_h: LandmarkSet, tips: dict[str, np.ndarray]) -> None:
        why: list[str] = []
        preds = published_predictions(
            lms_h, self.dowels.sex, rules=self.rules, skull=skull_h, dowel_tips=tips, problems=why
        )
        for pred in preds:
            if pred.target:
                self.chosen[:] = guides_from_prediction(pred, self.chosen)
        found = {p.rule_id for p in preds}
        self.rejected.extend(
            f"published rule {r} not applied: {'; '.join(why) or 'no prediction for this skull'}"
            for r in self.rules
            if r not in found
        )

    def problems(self, skull_h: Mesh, lms_h: LandmarkSet) -> list[str]:
        """Checks of the enabled guides on the fitted frame (notes for the report)."""
        enabled = [g for g in self.chosen if g.enabled]
        return [f"guide: {p}" for p in check_guides(enabled, skull_h, lms_h)] if enabled else []
