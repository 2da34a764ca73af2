"""The registration's self-check: confident, *check*, or refused (issue 28).

A skull oriented from the bone alone can come out wrong, and a wrong face
written with exit status 0 is the worst outcome a forensic tool can have.
So every registration judges itself on figures that a wrong orientation
cannot hide (:func:`workbench.services.registration.skull_registration.register_skull`
computes them, head frame, mm and degrees):

``face_observed``
    Share of the reference's facial skeleton (brow, orbits, nasal bones,
    zygomas, maxilla: :func:`workbench.core.skull_pose.face_mask`) that found
    bone after the dense registration.  A face skeleton laid on a vault, the
    skull base or the C-spine cannot find bone over most of itself.  On the
    development cases (VHP female and male, headsq; open, missing and
    detached jaws; other isos) right orientations gave 0.80–0.91 and wrong
    ones 0.65–0.73.
``symmetry_deg``
    Angle between the target's own bilateral-symmetry plane and the
    registered midsagittal plane (0.2–2.2° right; up to 8° wrong).
``asymmetry_mm``
    Median mismatch of the registered bilateral landmark pairs mirrored
    across the midsagittal plane (1.5–3.6 mm right).
``scale``
    The reference's scale onto the target (adult skulls 0.9–1.15).
``jaw_shift_mm``
    How far the fitted mandible's joint left its fossa.

Three outcomes: **confident**; **check** (the result is written, and the
first reason heads the command's output, the window's status and the
report's first page); **refused** (only from the bone alone: an orientation
the figures call wrong raises :class:`OrientationRefused`, which tells the
user what to give).  A hinted or landmark-seeded registration is never
refused — the user chose its orientation — but its figures still raise a
*check*.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from workbench.core.errors import InputError

#: below this share of the facial skeleton on bone the orientation is refused (from the
#: bone alone), below the second it is to be checked
FACE_REFUSE = 0.70
FACE_CHECK = 0.80
#: symmetry plane off the registered midline (degrees), bilateral mismatch (mm)
SYMMETRY_CHECK_DEG = 8.0
ASYMMETRY_CHECK_MM = 8.0
#: plausible scale of the reference onto an adult skull
SCALE_RANGE = (0.85, 1.2)
#: a fitted jaw whose joint moved farther than this from its fossa (mm)
JAW_SHIFT_CHECK_MM = 8.0
#: unexplained bone in the jaw's reach, as a share of the mandible's area, above which a
#: missing mandible is doubted (a mandible has 1.3-1.7 of it; the hyoid and the C-spine
#: beside a missing one about 0.5)
JAW_BONE_CHECK = 0.9

OUTCOMES = ("confident", "check", "refused")
#: exit status of a command whose outputs were written but whose registration asks for a
#: check: scripts and batch jobs must not take such a face as a plain success (a refusal
#: is a ``WorkbenchError``: exit 2)
EXIT_CHECK = 3

WHAT_TO_GIVE = (
    "give the orientation (--anterior X,Y,Z --superior X,Y,Z in the file's axes; in the "
    "window: Orientation in the Dowels dock) or place three skull landmarks (e.g. nasion and "
    "both porions) and run again"
)


class OrientationRefused(InputError):
    """The orientation found from the bone alone failed the self-check."""


@dataclass(frozen=True)
class SelfCheck:
    """Outcome of :func:`judge`: ``outcome`` in :data:`OUTCOMES` and the reasons, worst first."""

    outcome: str
    reasons: tuple[str, ...]
    #: some reason doubts the orientation itself (not only the jaw or the size)
    orientation_doubt: bool = False

    def to_dict(self) -> dict:
        return {
            "outcome": self.outcome,
            "reasons": list(self.reasons),
            "orientation_doubt": self.orientation_doubt,
        }

    @property
    def headline(self) -> str | None:
        """The line a user must read first, or None when confident."""
        if self.outcome == "confident":
            return None
        return f"{self.outcome.upper()}: {self.reasons[0]}"


def judge(measures: Mapping[str, object], method: str, jaw: Mapping[str, object]) -> SelfCheck:
    """Judge a registration by its figures (see the module docstring).

    ``method`` is the orientation's source (``"search"``, ``"hint"`` or
    ``"seeds"``); ``jaw`` the jaw pose's figures.
    """
    refuse: list[str] = []
    check: list[str] = []
    face = _number(measures.get("face_observed"))
    if face is not None:
        text = (
            f"only {100 * face:.0f} % of the reference's facial skeleton found bone after the "
            "registration: the orientation is likely wrong, or the face is missing or damaged"
        )
        if face < FACE_REFUSE:
            refuse.append(text)
        elif face < FACE_CHECK:
            check.append(text)
    sym = _number(measures.get("symmetry_deg"))
    if sym is not None and sym > SYMMETRY_CHECK_DEG:
        check.append(f"the skull's own symmetry plane lies {sym:.0f}° off the registered midline")
    asym = _number(measures.get("asymmetry_mm"))
    if asym is not None and asym > ASYMMETRY_CHECK_MM:
        check.append(
            f"left and right landmarks of the registered skull disagree by {asym:.0f} mm "
            "(median over the pairs)"
        )
    doubt = bool(refuse or check)  # the reasons so far doubt the orientation itself
    scale = _number(measures.get("scale"))
    if scale is not None and not SCALE_RANGE[0] <= scale <= SCALE_RANGE[1]:
        check.append(
            f"the reference had to be scaled by {scale:.2f} to fit (a child's skull, or the "
            "wrong units?)"
        )
    shift = _number(measures.get("jaw_shift_mm"))
    if shift is not None and shift > JAW_SHIFT_CHECK_MM:
        check.append(f"the fitted mandible's joints lie {shift:.0f} mm out of their fossae")
    if not jaw.get("present") and (_number(jaw.get("bone_area")) or 0.0) >= JAW_BONE_CHECK:
        check.append(
            "bone lies where the mandible would be, but no mandible fitted it (a damaged "
            "or unusual jaw, or a wrong orientation)"
        )
    if refuse and method == "search":
        return SelfCheck("refused", tuple(refuse + check), True)
    if refuse or check:
        return SelfCheck("check", tuple(refuse + check), doubt)
    return SelfCheck("confident", ())


def refusal(check: SelfCheck, source: str) -> OrientationRefused:
    """The error a refused registration raises, naming ``source`` and what to give."""
    return OrientationRefused(
        source,
        "the orientation found from the bone alone failed its self-check: "
        + "; ".join(check.reasons),
        hint=WHAT_TO_GIVE,
    )


def _number(value: object) -> float | None:
    if isinstance(value, bool) or value is None:
        return None
    try:
        out = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return None
    return out if out == out else None
