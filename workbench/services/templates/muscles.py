"""Kähler's 24 facial muscles (Table 7.1) laid out as grids on the template skin.

:func:`layout_muscles` builds one :class:`~workbench.model.muscles.MuscleGrid`
per row of ``data_tables/muscles/table71.csv`` from anatomical rules written
in terms of the skin landmarks and the eye / mouth openings of a
:class:`~workbench.core.headgen.skin.SkinTemplate`:

* **linear muscles** are drawn row by row from the fixed (bone) end to the
  free end (Kähler §7.4); each row is a short segment across the muscle;
* **sphincters** are open rings (no facial muscle is a true ring, digest
  §9.2) drawn at several offsets around an opening, outer ring first, with a
  two-point contraction axis (a skin point pushed 10 and 20 mm inward along
  the normal).  The orbicularis oris is two sphincters: upper lip (skull)
  and lower lip (jaw), each with its own axis.

Every guide point is cast onto the skin along an outward ray (radial from a
vertical axis behind the face, or upward for the submental mylohyoideus), so
grid points are stored *exactly on the skin* as (triangle, barycentric) and
follow any warp of the skin.  Their depth is Kähler's initial depth
``τs + (τm_min + τm_max)/4 = 2 + (2 + 6)/4 = 4 mm`` (digest §10.2; the /4 vs /2
inconsistency of §10.3 is noted there).  Right-side muscles are the exact
mirror (x -> -x, same barycentric weights on the partner triangle) of the
left ones; the skin is exactly symmetric.

Grid sizes follow Table 7.1's ``n_points`` (upper orbicularis oris 5 x 11,
lower 3 x 7, orbicularis oculi 2 rings of 7 / 9, linear muscles 4-6 points).
"""

from __future__ import annotations

import csv
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from workbench.core.data_paths import data_tables_dir
from workbench.core.headgen.muscle_paths import (
    MIRROR,
    linear_rows,
    mirror_maps,
    mirror_surface_points,
    polar_radius,
    unit,
)
from workbench.core.headgen.skin import SkinTemplate
from workbench.core.raycast import RayCaster
from workbench.core.spatial import MeshIndex
from workbench.model.muscles import MuscleGrid, SurfacePoints

TAU_SKIN = 2.0
TAU_MUSCLE = (2.0, 6.0)
GRID_DEPTH_MM = TAU_SKIN + (TAU_MUSCLE[0] + TAU_MUSCLE[1]) / 4.0  # 4 mm (Kähler §7.4)
AXIS_DEPTHS_MM = (10.0, 20.0)
RAY_AXIS_Z = 10.0  # radial rays leave a vertical axis at (x=0, z=RAY_AXIS_Z)
RAY_BACKOFF = 40.0  # rays start this far outside the guide point
MAX_GUIDE_GAP = 15.0  # a hit farther than this from the guide point is rejected


def read_table71() -> list[dict[str, str]]:
    """Rows of ``data_tables/muscles/table71.csv`` (comment lines skipped)."""
    path = data_tables_dir() / "muscles" / "table71.csv"
    with open(path, encoding="utf-8") as fh:
        lines = [ln for ln in fh if not ln.startswith("#")]
    return list(csv.DictReader(lines))


@dataclass
class _Ctx:
    skin: SkinTemplate
    lm: dict[str, np.ndarray]

    @property
    def v(self) -> np.ndarray:
        return self.skin.mesh.vertices

    @property
    def f(self) -> np.ndarray:
        return self.skin.mesh.faces

    @cached_property
    def rays(self) -> RayCaster:
        return RayCaster(self.skin.mesh)

    @cached_property
    def index(self) -> MeshIndex:
        return MeshIndex(self.skin.mesh)


def _radial(p: np.ndarray) -> np.ndarray:
    p = np.atleast_2d(p)
    return unit(np.stack([p[:, 0], np.zeros(len(p)), p[:, 2] - RAY_AXIS_Z], axis=1)).reshape(
        np.shape(p)
    )


def _below(p: np.ndarray) -> np.ndarray:
    return np.tile([0.0, -1.0, 0.0], (len(np.atleast_2d(p)), 1))


def _project(
    ctx: _Ctx, pts: np.ndarray, outward: Callable = _radial
) -> tuple[np.ndarray, np.ndarray]:
    """Cast guide points onto the skin: first hit coming in along -outward."""
    pts = np.asarray(pts, float).reshape(-1, 3)
    u = outward(pts)
    hits = ctx.rays.first_hits(pts + RAY_BACKOFF * u, -u)
    fid, bary, t = hits.face_ids.copy(), hits.barycentric.copy(), hits.distance
    # a miss, or a hit far from the guide point (through an opening, or on
    # another part of the head), falls back to the closest skin point
    miss = (fid < 0) | (np.abs(t - RAY_BACKOFF) > MAX_GUIDE_GAP)
    if miss.any():  # fall back to the closest skin point
        cp = ctx.index.closest_points(pts[miss])
        fid[miss], bary[miss] = cp.face_ids, cp.barycentric
    return fid, bary


def _surface(fid: np.ndarray, bary: np.ndarray, depth: float | np.ndarray) -> SurfacePoints:
    return SurfacePoints(fid, bary, np.broadcast_to(np.asarray(depth, float), (len(fid),)).copy())


# ------------------------------------------------------------------ linear muscles (left / midline)
def _linear_specs(ctx: _Ctx) -> dict[str, tuple]:
    """code -> (fixed centre, free centre, row lengths, (w_fixed, w_free), outward)."""
    L = ctx.lm
    lerp = lambda a, b, t: (1 - t) * L[a] + t * L[b]  # noqa: E731
    ch = L["ch_l"]
    brow_y = 0.5 * (L["sci_l"][1] + L["ex_l"][1]) + 10.0  # brow line above the eye
    top_y = L["tr"][1] - 8.0  # just below the hairline
    return {
        # corrugator: medial brow near g/n -> laterally above the eye (mid brow)
        "corrugator": (
            0.5 * (L["g"] + L["n"]) + [10.0, 0.0, -3.0],
            L["sci_l"] + [2.0, -4.0, 0.0],
            (2, 2, 2),
            (6.0, 5.0),
            _radial,
        ),
        # zygomaticus major: skin over the zygomatic body, anterior-inferior of zy -> just lateral of ch
        "zygomaticus_major": (
            lerp("zy_l", "ch_l", 0.3) + [0.0, -2.0, 4.0],
            ch + [3.0, 1.0, -1.0],
            (2, 2),
            (8.0, 5.0),
            _radial,
        ),
        # risorius: cheek over the masseter (towards go / ol) horizontally to ch
        "risorius": (
            np.array([L["ol_l"][0], ch[1], L["ol_l"][2]]) + [0.0, 0.0, 6.0],
            ch + [4.0, 0.0, -2.0],
            (2, 2),
            (8.0, 5.0),
            _radial,
        ),
        # levator labii superioris: below the infraorbital margin -> upper lip lateral of the philtrum
        "levator_labii": (
            np.array([lerp("en_l", "ex_l", 0.3)[0], L["or_l"][1] - 5.0, L["or_l"][2] + 2.0]),
            0.5 * (L["cph_l"] + L["mvs_l"]) + [0.0, 2.0, 0.0],
            (3, 2),
            (12.0, 6.0),
            _radial,
        ),
        # frontalis: vertical strips from the hairline down to the brow above the inner / outer eye
        "frontalis_inner": (
            np.array([L["en_l"][0], top_y, L["g"][2] - 8.0]),
            np.array([L["en_l"][0], brow_y, L["g"][2] - 4.0]),
            (2, 2, 2),
            (10.0, 10.0),
            _radial,
        ),
        "frontalis_outer": (
            np.array([lerp("en_l", "ex_l", 0.7)[0], top_y - 4.0, L["g"][2] - 20.0]),
            np.array([lerp("en_l", "ex_l", 0.7)[0], brow_y, L["ex_l"][2] + 8.0]),
            (2, 2, 2),
            (12.0, 12.0),
            _radial,
        ),
        # triangularis: mandible border below ch -> up to ch
        "triangularis": (
            lerp("mmb_l", "ch_l", 0.12),
            ch + [1.0, -2.0, 0.0],
            (2, 2, 2),
            (14.0, 5.0),
            _radial,
        ),
        # quadratus labii inferioris: mandible border (medial) -> lower lip lateral of li
        "quadratus_labii": (
            lerp("gn", "mmb_l", 0.45) + [0.0, 3.0, 0.0],
            np.array([9.0, L["li"][1] + 1.0, L["li"][2] - 2.0]),
            (2, 2, 2),
            (10.0, 7.0),
            _radial,
        ),
        # mentalis (midline, jaw): chin (pg) up toward the labiomental sulcus (sl)
        "mentalis": (
            L["pg"] + [0.0, -2.0, 0.0],
            L["sl"] + [0.0, -2.0, 0.0],
            (3, 2),
            (16.0, 10.0),
            _radial,
        ),
        # mylohyoideus (midline, jaw): under the chin, from behind me back towards the hyoid
        "mylohyoideus": (
            L["me"] + [0.0, 0.0, -6.0],
            L["me"] + [0.0, 0.0, -22.0],
            (2, 2),
            (30.0, 24.0),
            _below,
        ),
    }


# ------------------------------------------------------------------ sphincters
def _mouth_arcs(ctx: _Ctx) -> tuple[np.ndarray, np.ndarray]:
    """Upper and lower halves of the mouth loop, each sorted by x."""
    loop = ctx.v[ctx.skin.openings["mouth"]]
    i0, i1 = int(np.argmin(loop[:, 0])), int(np.argmax(loop[:, 0]))
    a, b = sorted((i0, i1))
    arc1 = loop[a : b + 1]
    arc2 = np.vstack([loop[b:], loop[: a + 1]])
    upper, lower = (arc1, arc2) if arc1[:, 1].mean() > arc2[:, 1].mean() else (arc2, arc1)
    return upper[np.argsort(upper[:, 0])], lower[np.argsort(lower[:, 0])]


def _oris_rings(ctx: _Ctx, upper: bool) -> list[np.ndarray]:
    """Open rings over the upper (or under the lower) lip, outer first; ends at the modioli."""
    L = ctx.lm
    arc = _mouth_arcs(ctx)[0 if upper else 1]
    sign = 1.0 if upper else -1.0
    if upper:
        n_rings, n_pts, height = 5, 11, 0.7 * (L["sn"][1] - L["sts"][1])
    else:
        n_rings, n_pts, height = 3, 7, 0.75 * (L["sti"][1] - L["sl"][1])
    s = np.linspace(-1.0, 1.0, n_pts)
    rings = []
    for f in np.linspace(1.0, 0.0, n_rings):  # outer ring first
        half = L["ch_l"][0] + 1.0 + 7.0 * f
        x = s * half
        xc = np.clip(x, arc[0, 0], arc[-1, 0])
        y = np.interp(xc, arc[:, 0], arc[:, 1]) + sign * (
            1.5 + f * height * np.sqrt(1 - np.abs(s) ** 3)
        )
        z = np.interp(xc, arc[:, 0], arc[:, 2]) - 3.0 * np.abs(s) * f
        rings.append(np.stack([x, y, z], axis=1))
    return rings


def _eye_rings(ctx: _Ctx, part: str) -> tuple[list[np.ndarray], np.ndarray]:
    """Open rings around the left eye opening (gap at the medial side), outer first."""
    loop = ctx.v[ctx.skin.openings["eye_l"]]
    c = loop.mean(axis=0)
    if part == "orbital":  # brow and upper cheek, beyond the orbital rim
        offsets, n_pts, span = ((17.0, 0.8), (9.0, 0.8)), 7, np.deg2rad(150.0)
    else:  # in the lids
        offsets, n_pts, span = ((6.5, 1.0), (2.0, 1.0)), 9, np.deg2rad(160.0)
    th = np.linspace(span, -span, n_pts)  # upper-medial, lateral, lower-medial
    r = polar_radius(loop[:, :2], c[:2], th)
    rings = []
    for off, lat in offsets:
        rr = r + off
        x = c[0] + rr * np.cos(th) * np.where(np.cos(th) > 0, lat, 1.0)
        y = c[1] + rr * np.sin(th)
        z = np.full(n_pts, c[2] + 4.0)
        rings.append(np.stack([x, y, z], axis=1))
    top = np.array(
        [c[0], c[1] + polar_radius(loop[:, :2], c[:2], np.array([np.pi / 2]))[0] + 3.0, c[2] + 4.0]
    )
    return rings, top


def _axis(ctx: _Ctx, point: np.ndarray) -> SurfacePoints:
    fid, bary = _project(ctx, np.asarray(point, float)[None])
    return SurfacePoints(np.repeat(fid, 2), np.repeat(bary, 2, axis=0), np.array(AXIS_DEPTHS_MM))


# ------------------------------------------------------------------ assembly
def _base(code: str) -> str:
    return code[:-2] if code.endswith(("_l", "_r")) else code


def _left_or_midline_grid(
    ctx: _Ctx, row: dict[str, str], specs: dict
) -> tuple[list[np.ndarray], Callable, np.ndarray | None]:
    base = _base(row["code"])
    if row["kind"] == "linear":
        fixed, free, lengths, widths, outward = specs[base]
        return (
            linear_rows(fixed, free, lengths, widths, lambda p: outward(p[None])[0]),
            outward,
            None,
        )
    L = ctx.lm
    if base == "orbicularis_oris_upper":
        h = L["sn"][1] - L["sts"][1]
        return (
            _oris_rings(ctx, True),
            _radial,
            np.array([0.0, L["sts"][1] + 1.5 + 0.35 * h, L["ls"][2]]),
        )
    if base == "orbicularis_oris_lower":
        h = L["sti"][1] - L["sl"][1]
        return (
            _oris_rings(ctx, False),
            _radial,
            np.array([0.0, L["sti"][1] - 1.5 - 0.35 * h, L["li"][2]]),
        )
    part = "orbital" if "orbital" in base else "palpebral"
    rings, top = _eye_rings(ctx, part)
    return rings, _radial, top


def layout_muscles(skin: SkinTemplate) -> tuple[MuscleGrid, ...]:
    """The 24 muscles of Table 7.1 as grids on ``skin`` (order of the table).

    Rows run from the fixed (bone) end to the free end (linear) or from the
    outer to the inner ring (sphincter).  Points are stored on the skin with
    depth :data:`GRID_DEPTH_MM`; sphincter axes are two skin points pushed
    :data:`AXIS_DEPTHS_MM` inward.  Right muscles mirror the left ones exactly.
    """
    ctx = _Ctx(skin, {lm.code: np.asarray(lm.position, float) for lm in skin.landmarks})
    specs = _linear_specs(ctx)
    table = read_table71()
    vp, fp = mirror_maps(skin.mesh.vertices, skin.mesh.faces)
    built: dict[str, MuscleGrid] = {}
    for row in table:  # left and midline muscles first
        if row["side"] == "right":
            continue
        rows, outward, axis_pt = _left_or_midline_grid(ctx, row, specs)
        fid, bary = _project(ctx, np.vstack(rows), outward)
        axis = None
        if row["kind"] == "sphincter":
            if axis_pt is None:
                raise ValueError(f"sphincter {row['code']} has no axis point")
            axis = _axis(ctx, axis_pt)
        built[row["code"]] = MuscleGrid(
            row["code"],
            row["name"],
            row["kind"],
            row["attachment"],
            row["side"],
            tuple(len(r) for r in rows),
            _surface(fid, bary, GRID_DEPTH_MM),
            axis,
        )
    faces = skin.mesh.faces
    for row in table:  # right = mirror of the left partner
        if row["side"] != "right":
            continue
        left = built[row["code"][:-2] + "_l"]

        def mirror(sp: SurfacePoints) -> SurfacePoints:
            f, b = mirror_surface_points(faces, vp, fp, sp.faces, sp.barycentric)
            return SurfacePoints(f, b, sp.depth_mm.copy())

        built[row["code"]] = MuscleGrid(
            row["code"],
            row["name"],
            row["kind"],
            row["attachment"],
            "right",
            left.row_lengths,
            mirror(left.points),
            None if left.axis is None else mirror(left.axis),
        )
    return tuple(built[row["code"]] for row in table)


def muscle_polylines(grid: MuscleGrid, mesh) -> list[np.ndarray]:
    """Rows and columns of a grid as polylines on ``mesh`` (for drawing), depth ignored."""
    pts = SurfacePoints(grid.points.faces, grid.points.barycentric).evaluate(mesh)
    bounds = np.cumsum((0, *grid.row_lengths))
    rows = [pts[a:b] for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
    lines = [r for r in rows if len(r) > 1]
    if grid.kind == "linear":
        n = min(len(r) for r in rows)
        for j in range(n):
            lines.append(np.array([r[round(j * (len(r) - 1) / max(n - 1, 1))] for r in rows]))
    return lines


__all__ = [
    "GRID_DEPTH_MM",
    "AXIS_DEPTHS_MM",
    "layout_muscles",
    "muscle_polylines",
    "read_table71",
    "MIRROR",
]
