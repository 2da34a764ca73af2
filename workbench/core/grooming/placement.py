"""Where hair grows on a head, from its skin landmarks.

Everything is placed in the head's own axes (:class:`HeadAxes`), found from
its landmarks rather than from the file's axes, so a head written in a
scanner's frame (turned, or mirrored) is groomed the same way as one in the
Frankfort frame.  Positions along the axes are in mm from the midpoint of
the two tragions; the azimuth is measured about the up axis from straight
ahead (0°) to straight back (180°), the same on both sides.

The hairline, the brows and the beard line follow the landmarks of the
project's code system (tr trichion, v vertex, t tragion, sba subaurale,
sci/scl/mso the brow and orbit points, sn, ls, li, ch, chk, go, gn).
Their heights between landmarks are artistic defaults chosen by eye on the
reference heads, not measurements; what a style changes is said in
:mod:`workbench.core.grooming.library`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from workbench.core.errors import InputError
from workbench.core.grooming.shell import _unit

Landmarks = Mapping[str, np.ndarray]

#: bilateral landmarks whose left-minus-right differences give the lateral axis
LATERAL_PAIRS = ("t", "po", "ex", "en", "zy", "go", "ch")
#: landmarks every style needs
NEEDED = ("tr", "v", "gn", "sn", "t_l", "t_r", "sba_l", "sba_r")


class GroomingError(InputError, ValueError):
    """The head lacks what a hair style needs (names the landmarks)."""


def _get(lm: Landmarks, code: str) -> np.ndarray:
    return np.asarray(lm[code], float)


@dataclass(frozen=True)
class HeadAxes:
    """The head's own axes, unit vectors in the skin's frame.

    ``lateral`` points to the subject's left, ``up`` to the vertex and
    ``forward`` out of the face, whatever the handedness of the file.
    """

    origin: np.ndarray
    lateral: np.ndarray
    up: np.ndarray
    forward: np.ndarray

    def coords(self, points: np.ndarray) -> np.ndarray:
        """``(k, 3)`` points as (lateral, up, forward) mm from the origin."""
        d = np.asarray(points, float).reshape(-1, 3) - self.origin
        return np.stack([d @ self.lateral, d @ self.up, d @ self.forward], axis=1)

    def vector(self, lat: np.ndarray, up: np.ndarray, fwd: np.ndarray) -> np.ndarray:
        """Vectors ``(k, 3)`` in the skin's frame from their components along the axes."""
        return (
            np.asarray(lat, float)[..., None] * self.lateral
            + np.asarray(up, float)[..., None] * self.up
            + np.asarray(fwd, float)[..., None] * self.forward
        )


def check_landmarks(lm: Landmarks, needed: tuple[str, ...], what: str) -> None:
    missing = [c for c in needed if c not in lm]
    if missing:
        raise GroomingError(
            what,
            f"the head has no skin landmark {', '.join(missing)}",
            "hair and brows are placed from the reference head's landmarks; "
            "use a head made by the workbench (reconstruction, scan fit, age)",
        )


def head_axes(lm: Landmarks) -> HeadAxes:
    """The head's axes from its landmarks (:class:`HeadAxes`)."""
    check_landmarks(lm, NEEDED, "hair and brows")
    diffs = [
        _get(lm, f"{c}_l") - _get(lm, f"{c}_r")
        for c in LATERAL_PAIRS
        if f"{c}_l" in lm and f"{c}_r" in lm
    ]
    lateral = _unit(np.mean(diffs, axis=0))
    origin = 0.5 * (_get(lm, "t_l") + _get(lm, "t_r"))
    up = _get(lm, "v") - _get(lm, "gn")
    up = _unit(up - (up @ lateral) * lateral)
    fwd = _get(lm, "sn") - origin
    fwd = fwd - (fwd @ lateral) * lateral - (fwd @ up) * up
    return HeadAxes(origin, lateral, up, _unit(fwd))


def azimuth_deg(c: np.ndarray) -> np.ndarray:
    """``(k,)`` azimuth about the up axis, 0° ahead to 180° behind, both sides alike."""
    return np.degrees(np.arctan2(np.abs(c[:, 0]), c[:, 2]))


def smooth_above(x: np.ndarray, edge: np.ndarray | float, soft: float) -> np.ndarray:
    """0 below ``edge - soft``, 1 above ``edge + soft``, smooth in between."""
    t = np.clip((x - edge + soft) / (2.0 * soft), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


@dataclass(frozen=True)
class Marks:
    """The landmark heights and azimuths placement uses, in :class:`HeadAxes` coordinates."""

    axes: HeadAxes
    at: Mapping[str, np.ndarray]  # code -> (lateral, up, forward); bilateral codes averaged

    def y(self, code: str) -> float:
        return float(self.at[code][1])

    def az(self, code: str) -> float:
        return float(azimuth_deg(self.at[code][None])[0])

    def x(self, code: str) -> float:
        return float(abs(self.at[code][0]))


def marks(lm: Landmarks) -> Marks:
    axes = head_axes(lm)
    at: dict[str, np.ndarray] = {}
    for code in lm:
        base = code[:-2] if code.endswith(("_l", "_r")) else code
        if base in at:
            continue
        if code.endswith(("_l", "_r")):
            pair = [lm[f"{base}_{s}"] for s in ("l", "r") if f"{base}_{s}" in lm]
            c = axes.coords(np.asarray(pair, float))
            c[:, 0] = np.abs(c[:, 0])
            at[base] = c.mean(axis=0)
        else:
            at[base] = axes.coords(np.asarray(lm[code], float))[0]
    return Marks(axes, at)


def hairline_height(m: Marks, az: np.ndarray) -> np.ndarray:
    """The lowest height (mm, up axis) the scalp hair reaches at each azimuth.

    Trichion in front; the temple corner a little lower; down to tragion
    level just in front of the ear (the sideburn); the nape hairline 8 mm
    below subaurale, behind.
    """
    tr, t, sba = m.y("tr"), m.y("t"), m.y("sba")
    brow = m.y("sci") if "sci" in m.at else tr - 40.0
    knots = [0.0, 35.0, 62.0, 82.0, 100.0, 130.0, 180.0]
    heights = [
        tr,
        tr - 0.12 * (tr - brow),
        0.5 * (brow + t) + 8.0,
        t,
        t + 2.0,
        sba - 2.0,
        sba - 8.0,
    ]
    return np.interp(az, knots, heights)


def near_any(points: np.ndarray, targets: np.ndarray, radius: float) -> np.ndarray:
    """``(k,)`` bool: within ``radius`` mm of any of ``targets``."""
    if len(targets) == 0:
        return np.zeros(len(points), bool)
    from scipy.spatial import cKDTree

    d, _ = cKDTree(targets).query(points, distance_upper_bound=radius)
    return np.isfinite(d)


__all__ = [
    "GroomingError",
    "HeadAxes",
    "Marks",
    "azimuth_deg",
    "check_landmarks",
    "hairline_height",
    "head_axes",
    "marks",
    "near_any",
    "smooth_above",
]
