"""Head frame (Frankfort Horizontal) from a landmark set.

Uses the catalogue codes: porions ``po_l``/``po_r`` and orbitales
``or_l``/``or_r`` (skull or skin surface alike), midline landmarks for the
midsagittal plane, and landmarks known to lie above or below FH to detect a
mirrored (left/right-swapped) input.  See :mod:`workbench.core.frame` for the
frame's definition.
"""

from __future__ import annotations

import numpy as np

from workbench.core.errors import LandmarkError
from workbench.core.frame import HeadFrame, frankfort_frame
from workbench.core.landmarks import LandmarkSet

# midline points that define the midsagittal plane well (spread front to back)
MIDLINE = {
    "skull": ("g", "n", "rhi", "ans", "ss", "pr", "id", "pg", "gn", "me", "b", "v", "op", "ba"),
    "skin": ("g", "n", "se", "prn", "sn", "ls", "li", "pg", "gn", "me", "v", "op"),
}
ABOVE_FH = {"skull": ("g", "n", "b", "v", "mso_l", "mso_r"), "skin": ("g", "n", "se", "v", "tr")}
BELOW_FH = {
    "skull": ("pr", "id", "pg", "gn", "me", "go_l", "go_r"),
    "skin": ("sn", "ls", "li", "pg", "gn", "me", "go_l", "go_r"),
}


def head_frame_from_landmarks(landmarks: LandmarkSet) -> HeadFrame:
    """Frankfort frame of a skull or skin landmark set (positions in mm).

    Raises
    ------
    LandmarkError
        Naming the missing FH landmarks (both porions and at least one
        orbitale are needed).
    """
    defined = landmarks.as_dict()
    missing = [c for c in ("po_l", "po_r") if c not in defined]
    if "or_l" not in defined and "or_r" not in defined:
        missing.append("or_l or or_r")
    if missing:
        raise LandmarkError(
            f"the Frankfort Horizontal needs both porions and an orbitale; missing on the "
            f"{landmarks.surface}: {', '.join(missing)}"
        )
    or_l = defined.get("or_l")
    or_r = defined.get("or_r")
    if or_l is None:  # classic FH uses the left orbitale; use the right one alone if needed
        or_l, or_r = or_r, None
    if or_l is None:  # ruled out by the check above
        raise LandmarkError("the Frankfort Horizontal needs an orbitale")
    surface = landmarks.surface

    def pick(codes: tuple[str, ...]) -> list:
        return [defined[c] for c in codes if c in defined]

    return frankfort_frame(
        defined["po_l"],
        defined["po_r"],
        or_l,
        or_r,
        midline=pick(MIDLINE[surface]) or None,
        above=pick(ABOVE_FH[surface]),
        below=pick(BELOW_FH[surface]),
    )


def input_frame(landmarks: LandmarkSet) -> tuple[np.ndarray, bool]:
    """``(input → head 4x4, mirrored)`` from skull landmarks (FH + midline)."""
    defined = landmarks.defined()
    frame = head_frame_from_landmarks(defined)
    if not frame.mirrored_input:
        return frame.input_to_head, False
    flip = np.diag([-1.0, 1.0, 1.0, 1.0])
    again = head_frame_from_landmarks(defined.transformed(flip))
    if again.mirrored_input:
        raise LandmarkError(
            "the skull landmarks contradict each other about left and right "
            "(check the porions, orbitales and the _l/_r labels)"
        )
    return again.input_to_head @ flip, True
