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
``grooming``
    The hair, brow, beard and moustache styles chosen from the library of
    :mod:`workbench.core.grooming` (artistic additions, not evidence:
    :data:`workbench.core.grooming.ARTISTIC_NOTE`), per kind of
    :data:`~workbench.core.grooming.KINDS`; kinds without an entry have none.
    Case files written before this field load without it.  The ``hair``
    region's colour (set by hand, else :data:`~workbench.core.appearance.HAIR`)
    colours the hair, beard and moustache; the brows take the ``brows``
    region's colour when it is set by hand, else the hair's.

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
from workbench.core.grooming import KINDS, NONE, GroomingError, check_style

#: the regions a colour can be set for, in the order they are drawn over the base
#: (``skin`` is the base itself; ``eyes`` is the skin around the eyes, not the eyeballs;
#: ``hair`` colours the hair, beard and moustache and the skin they grow from)
REGIONS = ("skin", "cheeks", "eyes", "brows", "lips", "hair")
#: what the window calls each region
REGION_TITLES = {
    "skin": "Skin (base)",
    "cheeks": "Cheeks",
    "eyes": "Around the eyes",
    "brows": "Brows",
    "lips": "Lips",
    "hair": "Hair and beard",
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
    grooming : tuple of (str, str)
        ``(kind, style)`` of the hair, brows, beard and moustache chosen, in
        :data:`~workbench.core.grooming.KINDS` order (``none`` is not stored);
        a mapping ``{kind: style}`` is accepted.
    """

    tone: str = DEFAULT_SKIN_TONE
    regions: tuple[tuple[str, Hsv], ...] = ()
    iris: str = DEFAULT_IRIS
    grooming: tuple[tuple[str, str], ...] = ()

    def __post_init__(self) -> None:
        self._check_grooming()
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

    def _check_grooming(self) -> None:
        given = self.grooming
        pairs = list(given.items()) if isinstance(given, Mapping) else list(given)
        found: dict[str, str] = {}
        for pair in pairs:
            if isinstance(pair, (str, bytes)) or len(pair) != 2:
                raise AppearanceError("hair and brows", f"expected (kind, style), got {pair!r}")
            kind, style = pair
            if not isinstance(style, str):
                raise AppearanceError(f"{kind} style", f"expected a name, got {style!r}")
            try:
                check_style(str(kind), style)
            except GroomingError as exc:
                raise AppearanceError(exc.source, exc.problem, exc.hint) from None
            if kind in found:
                raise AppearanceError("hair and brows", f"{kind!r} given twice")
            found[kind] = style
        kept = tuple((k, found[k]) for k in KINDS if found.get(k, NONE) != NONE)
        object.__setattr__(self, "grooming", kept)

    # ------------------------------------------------------------ reading
    def style(self, kind: str) -> str:
        """The style chosen for ``kind`` (hair, brows, beard, moustache), or ``"none"``."""
        if kind not in KINDS:
            raise AppearanceError("hair and brows", f"unknown kind {kind!r}")
        return dict(self.grooming).get(kind, NONE)

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

    def with_style(self, kind: str, style: str) -> Appearance:
        """A copy with ``style`` (``"none"``: nothing) chosen for ``kind``."""
        self.style(kind)  # checks the kind
        rest = dict(self.grooming)
        rest[kind] = style
        return replace(self, grooming=tuple(rest.items()))

    def changed_fields(self, other: Appearance | None) -> tuple[str, ...]:
        """What differs from ``other`` ("tone", "iris", region names, kinds of
        :data:`~workbench.core.grooming.KINDS` as e.g. "hair style"); all if None."""
        if other is None:
            styles = tuple(f"{k} style" for k, _ in self.grooming)
            return ("tone", "iris", *(r for r, _ in self.regions), *styles)
        out = [f for f in ("tone", "iris") if getattr(self, f) != getattr(other, f)]
        out += [r for r in REGIONS if self.colour(r) != other.colour(r)]
        out += [f"{k} style" for k in KINDS if self.style(k) != other.style(k)]
        return tuple(out)

    # ------------------------------------------------------------ state
    def to_state(self) -> dict[str, Any]:
        state: dict[str, Any] = {
            "tone": self.tone,
            "regions": {r: c.to_state() for r, c in self.regions},
            "iris": self.iris,
        }
        if self.grooming:  # absent when empty, so cases without hair read as before
            state["grooming"] = dict(self.grooming)
        return state

    @classmethod
    def from_state(cls, state: Mapping[str, Any]) -> Appearance:
        if not isinstance(state, Mapping):
            raise AppearanceError("appearance", f"expected an object, got {type(state).__name__}")
        known = {"tone", "regions", "iris"}
        unknown = sorted(set(state) - known - {"grooming"})
        if unknown:
            raise AppearanceError("appearance", f"unknown fields {', '.join(unknown)}")
        missing = sorted(known - set(state))
        if missing:
            raise AppearanceError("appearance", f"missing fields {', '.join(missing)}")
        regions = state["regions"]
        if not isinstance(regions, Mapping):
            raise AppearanceError("region colours", "expected an object {region: [h, s, v]}")
        grooming = state.get("grooming", {})
        if not isinstance(grooming, Mapping):
            raise AppearanceError("hair and brows", "expected an object {kind: style}")
        return cls(
            tone=state["tone"],
            regions=tuple(regions.items()),
            iris=state["iris"],
            grooming=tuple(grooming.items()),
        )


# ------------------------------------------------------------------ part codec
def appearance_to_state(value: Appearance | None) -> dict[str, Any] | None:
    return None if value is None else value.to_state()


def appearance_from_state(state: Any) -> Appearance | None:
    return None if state is None else Appearance.from_state(state)
