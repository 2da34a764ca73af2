"""Is a refit safe to show in place of the face before it?  An edit must not break the face.

An artist edits one landmark, a guide or a depth and the face is fitted again.
A refit that turns the head, or moves the face where nothing was edited, is
almost always a registration that slipped (issue 33: one snap turned the face
30-90 degrees off the skull while the status bar said "Face fitted").
:func:`compare_refit` measures the new fit against the previous one:

- the rotation between the two fits' skull-to-head frames (degrees);
- when only landmarks changed, how far the face moved away from them: the
  95th percentile of the displacement of the face vertices more than
  :data:`EDIT_RADIUS_MM` from every changed landmark (old and new place);
- the registration's self-check, when it asks for a check and did not before.

Each limit passed is a reason, said in words; a refit with reasons is not
applied by the window without the user's consent (it shows the new face as a
ghost and asks).  Units mm, degrees; positions in the skull file's frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from workbench.core.rigid_search import rigid_motion

if TYPE_CHECKING:
    from workbench.core.landmarks import LandmarkSet
    from workbench.services.reconstruction.service import FitInputs, FitResult

#: a refit may turn the face by at most this against the previous fit (degrees)
MAX_ROTATION_DEG = 5.0
#: face vertices farther than this from every edited landmark count as "away from the edit"
EDIT_RADIUS_MM = 30.0
#: away from the edit, the face may move this much (95th percentile of the vertices, mm)
MAX_AWAY_MM = 3.0
#: a landmark counts as edited when it moved more than this (mm)
EDITED_MM = 0.01


@dataclass(frozen=True)
class RefitChange:
    """How a refit differs from the fit before it (mm, degrees) and why it is not safe."""

    rotation_deg: float
    #: 95th percentile displacement of the face away from the edit (NaN: not measured)
    away_mm: float
    #: landmark codes whose positions differ between the two fits' inputs
    edited: tuple[str, ...]
    reasons: tuple[str, ...]

    @property
    def safe(self) -> bool:
        return not self.reasons

    def text(self) -> str:
        """The reasons in one sentence for a status line or a dialog."""
        return "; ".join(self.reasons)


def _angle_deg(r: np.ndarray) -> float:
    """The angle of rotation matrix ``r`` (degrees)."""
    return float(np.degrees(np.arccos(np.clip((np.trace(r) - 1.0) / 2.0, -1.0, 1.0))))


def _rotation_deg(a: np.ndarray, b: np.ndarray) -> float:
    """The angle of the rotation between two similarity frames' linear parts (degrees)."""
    r = np.asarray(a, float)[:3, :3] @ np.linalg.inv(np.asarray(b, float)[:3, :3])
    return _angle_deg(r / np.cbrt(abs(np.linalg.det(r))))


def face_turn_deg(before: np.ndarray, after: np.ndarray) -> float:
    """How far a face turned between two fits: the angle (degrees) of the best rigid motion
    of its vertices ``before`` onto ``after`` (same vertex order, mm)."""
    a, b = np.asarray(before, float), np.asarray(after, float)
    r, _t = rigid_motion(a, b, np.ones(len(a)))
    return _angle_deg(r)


def moved_landmarks(
    old_set: LandmarkSet | None, new_set: LandmarkSet | None
) -> dict[str, np.ndarray]:
    """Codes whose positions differ between two landmark sets, with their old and new places
    ((k, 3) points, mm); a landmark added or removed counts with its one place."""
    old = {} if old_set is None else old_set.as_dict()
    new = {} if new_set is None else new_set.as_dict()
    out: dict[str, np.ndarray] = {}
    for code in sorted(set(old) | set(new)):
        places = [p for p in (old.get(code), new.get(code)) if p is not None]
        if len(places) == 2 and np.linalg.norm(places[0] - places[1]) <= EDITED_MM:
            continue
        out[code] = np.asarray(places, float).reshape(-1, 3)
    return out


def edited_landmarks(before: FitInputs, after: FitInputs) -> dict[str, np.ndarray]:
    """:func:`moved_landmarks` between two fits' inputs (input frame)."""
    return moved_landmarks(before.landmarks, after.landmarks)


def _only_landmarks_changed(before: FitInputs, after: FitInputs) -> bool:
    """True when the two fits differ in their landmarks alone (settings, guides the same)."""
    same = (
        before.dowels == after.dowels
        and before.orientation == after.orientation
        and before.guides == after.guides
        and before.template == after.template
        and before.templates == after.templates
        and before.rules == after.rules
        and before.use_guides == after.use_guides
    )
    return bool(same)


def _self_check(fit: FitResult) -> dict:
    reg = fit.recon.registration
    return {} if reg is None else dict(reg.figures.get("self_check") or {})


def compare_refit(previous: FitResult, new: FitResult) -> RefitChange:
    """How ``new`` differs from ``previous`` (the fit shown before the edit), with the reasons
    not to show it in its place (see the module docstring)."""
    reasons: list[str] = []
    rotation = _rotation_deg(new.recon.input_to_head, previous.recon.input_to_head)
    if rotation > MAX_ROTATION_DEG:
        reasons.append(
            f"it is turned {rotation:.0f} degrees against the face shown "
            f"(more than {MAX_ROTATION_DEG:g}): the skull's registration slipped"
        )
    was_in, now_in = previous.inputs, new.inputs
    edited = {} if was_in is None or now_in is None else edited_landmarks(was_in, now_in)
    away = float("nan")
    before_face, after_face = previous.recon.face.vertices, new.recon.face.vertices
    if (
        edited
        and was_in is not None
        and now_in is not None
        and _only_landmarks_changed(was_in, now_in)
    ):
        if before_face.shape == after_face.shape:
            places = np.vstack(list(edited.values()))
            near = np.min(np.linalg.norm(before_face[:, None, :] - places[None], axis=2), axis=1)
            far = near > EDIT_RADIUS_MM
            if far.any():
                moved = np.linalg.norm(after_face[far] - before_face[far], axis=1)
                away = float(np.percentile(moved, 95))
                if away > MAX_AWAY_MM:
                    reasons.append(
                        f"it moved {away:.1f} mm (95th percentile) more than "
                        f"{EDIT_RADIUS_MM:g} mm away from the landmark(s) changed "
                        f"({', '.join(edited)})"
                    )
    now, was = _self_check(new), _self_check(previous)
    if now.get("outcome") == "check" and was.get("outcome") != "check":
        why = (now.get("reasons") or ["the registration's self-check"])[0]
        reasons.append(f"the registration now asks for a check: {why}")
    return RefitChange(rotation, away, tuple(edited), tuple(reasons))
