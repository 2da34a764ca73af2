"""The colours a user chose for the fitted face: one case part, ``appearance``.

Kähler (2003, §8.6.6) colours the finished head so it reads as a face: a
skin tone over the whole skin and regions (lips, brows, cheeks, the skin
around the eyes) tinted on top of it.  :class:`Appearance` records those
choices; ``None`` (the default, and what older case files load as) means no
colouring was chosen and the shared defaults of
:mod:`workbench.core.appearance` apply.

**The colours are an artistic choice, not evidence.**  A skull says nothing
about the colour of skin, lips, brows or eyes; wherever the colours are
shown or exported the workbench says so (:data:`ARTISTIC_NOTE`).

Fields
------
``tone``
    A skin-tone preset of :data:`workbench.core.appearance.SKIN_TONES`
    (``mst1`` ... ``mst10`` of the Monk Skin Tone scale, or ``light``,
    ``medium``, ``dark``): the base colour of the skin.
``regions``
    Colours the user set by hand, per region of :data:`REGIONS`, each an
    :class:`Hsv`.  An entry for ``skin`` replaces the preset as the base (a
    base given in HSV); an entry for another region replaces that region's
    colour, which otherwise follows the base by a rule (see
    :mod:`workbench.services.appearance`).  Regions without an entry are
    absent, never stored as ``None``.
``iris``
    An iris colour of :data:`workbench.core.appearance.IRIS_COLOURS`, used
    when the head's eyes are exported.

Notes
-----
HSV components are fractions 0-1: the hue as a fraction of a turn (0 red,
1/3 green, 2/3 blue; 1.0 is stored as 0.0), saturation and value (the
brightest channel) of sRGB, as :func:`workbench.core.appearance.rgb_to_hsv`.
Nothing here is a length.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

from workbench.core.appearance import DEFAULT_IRIS, DEFAULT_SKIN_TONE, IRIS_COLOURS, SKIN_TONES
from workbench.core.errors import InputError

#: the regions a colour can be set for, in the order they are drawn over the base
#: (``skin`` is the base itself; ``eyes`` is the skin around the eyes, not the eyeballs)
REGIONS = ("skin", "cheeks", "eyes", "brows", "lips")
#: what the window calls each region
REGION_TITLES = {
    "skin": "Skin (base)",
    "cheeks": "Cheeks",
    "eyes": "Around the eyes",
    "brows": "Brows",
    "lips": "Lips",
}
#: said wherever the colours are shown or written
ARTISTIC_NOTE = (
    "Colours are an artistic choice, not evidence: a skull says nothing about the "
    "colour of skin, lips, brows or eyes."
)


class AppearanceError(InputError, ValueError):
    """An invalid colour setting (names the setting and the problem)."""


def _fraction(value: Any, what: str) -> float:
    number = isinstance(value, (int, float)) and not isinstance(value, bool)
    x = float(value) if number else math.nan  # text is refused: state and widgets give numbers
    if not (math.isfinite(x) and 0.0 <= x <= 1.0):
        raise AppearanceError(what, f"{value!r} is not a fraction in 0-1")
    return x


@dataclass(frozen=True)
class Hsv:
    """A colour as hue, saturation and value, each a fraction 0-1 (see the module notes)."""

    h: float
    s: float
    v: float

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "h", _fraction(self.h, "hue") % 1.0)
        set_(self, "s", _fraction(self.s, "saturation"))
        set_(self, "v", _fraction(self.v, "value"))

    def to_state(self) -> list[float]:
        return [self.h, self.s, self.v]

    @classmethod
    def from_state(cls, state: Any) -> Hsv:
        if isinstance(state, Hsv):
            return state
        if isinstance(state, (str, bytes)) or not hasattr(state, "__len__") or len(state) != 3:
            raise AppearanceError("colour", f"expected [hue, saturation, value], got {state!r}")
        return cls(*state)


@dataclass(frozen=True)
class Appearance:
    """The colouring chosen for a case's face (frozen; compares by value).

    Attributes
    ----------
    tone : str
        Skin-tone preset (the base unless ``regions`` sets ``skin``).
    regions : tuple of (str, Hsv)
        Colours set by hand, in :data:`REGIONS` order; a mapping
        ``{region: Hsv or [h, s, v]}`` is accepted.
    iris : str
        Iris colour of an exported head's eyes.
    """

    tone: str = DEFAULT_SKIN_TONE
    regions: tuple[tuple[str, Hsv], ...] = ()
    iris: str = DEFAULT_IRIS

    def __post_init__(self) -> None:
        if self.tone not in SKIN_TONES:
            raise AppearanceError(
                "skin tone", f"unknown preset {self.tone!r}", f"use one of {', '.join(SKIN_TONES)}"
            )
        if self.iris not in IRIS_COLOURS:
            raise AppearanceError(
                "iris colour", f"unknown {self.iris!r}", f"use one of {', '.join(IRIS_COLOURS)}"
            )
        given = self.regions
        pairs = list(given.items()) if isinstance(given, Mapping) else list(given)
        found: dict[str, Hsv] = {}
        for pair in pairs:
            if isinstance(pair, (str, bytes)) or len(pair) != 2:
                raise AppearanceError("region colours", f"expected (region, colour), got {pair!r}")
            name, colour = pair
            if name not in REGIONS:
                raise AppearanceError(
                    "region colours", f"unknown region {name!r}", f"use {', '.join(REGIONS)}"
                )
            if name in found:
                raise AppearanceError("region colours", f"{name!r} given twice")
            try:
                found[name] = Hsv.from_state(colour)
            except AppearanceError as exc:
                raise AppearanceError(f"{name} colour", exc.problem) from None
        object.__setattr__(self, "regions", tuple((r, found[r]) for r in REGIONS if r in found))

    # ------------------------------------------------------------ reading
    def colour(self, region: str) -> Hsv | None:
        """The colour set by hand for ``region``, or None (the region follows the base)."""
        if region not in REGIONS:
            raise AppearanceError("region", f"unknown region {region!r}")
        return dict(self.regions).get(region)

    @property
    def custom_base(self) -> bool:
        """The base is an HSV colour set by hand, not the preset ``tone``."""
        return self.colour("skin") is not None

    # ------------------------------------------------------------ changed copies
    def replaced(self, **fields_: Any) -> Appearance:
        """A copy with some fields changed (validated)."""
        return replace(self, **fields_)

    def with_colour(self, region: str, colour: Hsv | None) -> Appearance:
        """A copy with ``region``'s colour set by hand (``None``: back to the rule)."""
        self.colour(region)  # checks the name
        rest = {r: c for r, c in self.regions if r != region}
        if colour is not None:
            rest[region] = colour
        return replace(self, regions=tuple(rest.items()))

    def with_tone(self, tone: str) -> Appearance:
        """A copy on preset ``tone``, the hand-set base dropped (other regions kept)."""
        return replace(self.with_colour("skin", None), tone=tone)

    def changed_fields(self, other: Appearance | None) -> tuple[str, ...]:
        """What differs from ``other`` ("tone", "iris", region names); all if None."""
        if other is None:
            return ("tone", "iris", *(r for r, _ in self.regions))
        out = [f for f in ("tone", "iris") if getattr(self, f) != getattr(other, f)]
        out += [r for r in REGIONS if self.colour(r) != other.colour(r)]
        return tuple(out)

    # ------------------------------------------------------------ state
    def to_state(self) -> dict[str, Any]:
        return {
            "tone": self.tone,
            "regions": {r: c.to_state() for r, c in self.regions},
            "iris": self.iris,
        }

    @classmethod
    def from_state(cls, state: Mapping[str, Any]) -> Appearance:
        if not isinstance(state, Mapping):
            raise AppearanceError("appearance", f"expected an object, got {type(state).__name__}")
        known = {"tone", "regions", "iris"}
        unknown = sorted(set(state) - known)
        if unknown:
            raise AppearanceError("appearance", f"unknown fields {', '.join(unknown)}")
        missing = sorted(known - set(state))
        if missing:
            raise AppearanceError("appearance", f"missing fields {', '.join(missing)}")
        regions = state["regions"]
        if not isinstance(regions, Mapping):
            raise AppearanceError("region colours", "expected an object {region: [h, s, v]}")
        return cls(tone=state["tone"], regions=tuple(regions.items()), iris=state["iris"])


# ------------------------------------------------------------------ part codec
def appearance_to_state(value: Appearance | None) -> dict[str, Any] | None:
    return None if value is None else value.to_state()


def appearance_from_state(state: Any) -> Appearance | None:
    return None if state is None else Appearance.from_state(state)
