"""The eyeballs of a fitted head: where each globe goes, and which lid skin goes with it.

Head frame (x to the subject's left, y up, z toward the face), mm.  Used by
:func:`workbench.services.reconstruction.reconstruct.fit_head`.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from workbench.core.landmarks import LandmarkSet
from workbench.model.template import TemplateHead

#: an eye placement rule moving a globe farther than this is taken as a bad landmark (mm)
EYE_MAX_SHIFT_MM = 15.0


def eye_sides(head: TemplateHead) -> list[tuple[int, str]]:
    """(index into ``eye_centres``, side) — left is +x in the head frame."""
    return [(i, "l" if head.eye_centres[i, 0] > 0 else "r") for i in range(len(head.eye_centres))]


def lid_vertices(head: TemplateHead, i: int, side: str) -> np.ndarray:
    """Skin vertices of the lids over eye ``i``: the lid regions and the palpebral opening."""
    groups = [
        head.regions[r]
        for r in (f"eyelid_upper_{side}", f"eyelid_lower_{side}")
        if r in head.regions
    ]
    if f"eye_{side}" in head.openings:
        groups.append(head.openings[f"eye_{side}"])
    if groups:
        return np.unique(np.concatenate([np.asarray(g, dtype=np.int64) for g in groups]))
    # a reference without regions: the skin just in front of the globe
    d = head.skin.vertices - head.eye_centres[i]
    near = (np.linalg.norm(d, axis=1) < head.eye_radius + 6.0) & (d[:, 2] > 0)
    return np.flatnonzero(near)


def eye_moves(
    head: TemplateHead,
    landmarks_h: LandmarkSet | None,
    placement: str,
    guided: Mapping[str, np.ndarray],
) -> tuple[dict[int, np.ndarray], dict, list[str]]:
    """How far each eyeball (and the lids over it) moves: ``{eye index: (3,) mm}``.

    A guide for ``eye_centre_<side>`` (a published eye rule, or set by the
    user) puts the centre there.  Otherwise, with ``placement ==
    "stephan2009"``, the globe moves along z (head frame) until its corneal
    apex lies 16 mm (``stephan2009_globe_projection``) in front of the registered
    ectoconchion of its side — Stephan, Huang & Davidson 2009 (corneal apex
    about 16 mm in front of the lateral orbital margin; ectoconchion stands
    for the margin as in :mod:`workbench.services.guides.measure`).  Returns
    the moves, flat figures (``eye_placement``, ``eye_<side>_by``,
    ``eye_<side>_shift_mm``, ``eye_<side>_apex_in_front_of_ec_mm``) and
    notes (an eye left where it was, and why).
    """
    from workbench.services.guides.measure import constant

    moves: dict[int, np.ndarray] = {}
    figures: dict = {"eye_placement": placement}
    notes: list[str] = []
    eyes = head.meshes.get("eyes")
    if eyes is None or not len(head.eye_centres):
        return moves, figures, notes
    owner = np.linalg.norm(eyes.vertices[:, None] - head.eye_centres[None], axis=2).argmin(axis=1)
    lms = {lm.code: lm for lm in landmarks_h} if landmarks_h is not None else {}
    for i, side in eye_sides(head):
        code = f"eye_centre_{side}"
        if code in guided:
            moves[i] = np.asarray(guided[code], float).reshape(3) - head.eye_centres[i]
            figures[f"eye_{side}_by"] = "guide"
            figures[f"eye_{side}_shift_mm"] = round(float(np.linalg.norm(moves[i])), 2)
            continue
        if placement != "stephan2009":
            continue
        ec = lms.get(f"ec_{side}")
        if ec is None or not ec.is_defined:
            notes.append(
                f"eye ({side}): no ectoconchion ec_{side} on the skull; the eyeball "
                "stays where the reference has it"
            )
            continue
        apex = float(eyes.vertices[owner == i, 2].max())
        dz = float(ec.position[2]) + constant("stephan2009_globe_projection") - apex
        if abs(dz) > EYE_MAX_SHIFT_MM:
            notes.append(
                f"eye ({side}): the published projection would move the eyeball "
                f"{dz:+.1f} mm (more than {EYE_MAX_SHIFT_MM:g} mm); check ec_{side} — "
                "the eyeball stays where the reference has it"
            )
            continue
        moves[i] = np.array([0.0, 0.0, dz])
        figures[f"eye_{side}_by"] = "stephan2009"
        figures[f"eye_{side}_shift_mm"] = round(dz, 2)
        figures[f"eye_{side}_apex_in_front_of_ec_mm"] = round(apex + dz - float(ec.position[2]), 2)
    return moves, figures, notes
