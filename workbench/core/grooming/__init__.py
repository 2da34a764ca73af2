"""Brows, hair, beards and moustaches grown on a head's skin (artistic additions).

- :mod:`~workbench.core.grooming.shell`: points tied to the skin, so pieces
  follow build variants, age change and expressions;
- :mod:`~workbench.core.grooming.strands`: strands grown over the skin and
  their ribbons;
- :mod:`~workbench.core.grooming.placement`: the head's own axes and the
  hairline from its landmarks;
- :mod:`~workbench.core.grooming.library`: the styles and :func:`groom`.

Units: millimetres, in the skin's own frame.
"""

from workbench.core.grooming.library import (
    ARTISTIC_NOTE,
    KINDS,
    LIBRARY,
    NONE,
    Grooming,
    HairPiece,
    HeadParts,
    Ribbons,
    Style,
    check_style,
    groom,
    style_names,
)
from workbench.core.grooming.placement import GroomingError

__all__ = [
    "ARTISTIC_NOTE",
    "KINDS",
    "LIBRARY",
    "NONE",
    "Grooming",
    "GroomingError",
    "HairPiece",
    "HeadParts",
    "Ribbons",
    "Style",
    "check_style",
    "groom",
    "style_names",
]
