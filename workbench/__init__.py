"""Forensic and anthropometry workbench.

Skull-to-face reconstruction, growth and age simulation and scan fitting with
one anatomical reference head deformed by landmark thin-plate-spline warps.

All geometry is in millimetres.  Heads are handled in the head frame defined
in :mod:`workbench.core.frame` (Frankfort Horizontal, x = 0 midsagittal).
"""

from __future__ import annotations

__version__ = "0.1.0"
