"""Skull landmark construction for the procedural reference skull.

Every landmark is a ray hit on the cranium or mandible mesh, cast from a
construction point in a known direction (units: mm, head frame: x to the
subject's left, y up, z forward).  Left-side points are built; the caller
mirrors them.  Split out of :mod:`workbench.core.headgen.skull`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from workbench.core.raycast import RayCaster


class _Rays:
    """First hits of rays on one mesh; misses are NaN rows.

    ``affine`` (4x4, an invertible affine map) lets the caster built on the
    untransformed mesh answer queries about the mesh mapped by it: rays are
    pulled back, hits pushed forward (affine maps keep lines and their order
    of intersections), so one acceleration structure serves the whole build.
    """

    def __init__(self, mesh_or_caster, affine: np.ndarray | None = None):
        self.caster = (
            mesh_or_caster if isinstance(mesh_or_caster, RayCaster) else RayCaster(mesh_or_caster)
        )
        self.A = np.eye(4) if affine is None else np.asarray(affine, float)
        self.inv = np.linalg.inv(self.A)

    def mapped(self, affine: np.ndarray) -> _Rays:
        return _Rays(self.caster, affine)

    def __call__(self, origins, directions) -> np.ndarray:
        o = np.atleast_2d(np.asarray(origins, float))
        d = np.atleast_2d(np.asarray(directions, float))
        if len(d) == 1 and len(o) > 1:
            d = np.repeat(d, len(o), axis=0)
        o = o @ self.inv[:3, :3].T + self.inv[:3, 3]
        d = d @ self.inv[:3, :3].T
        hits = self.caster.first_hits(o, d).points
        return hits @ self.A[:3, :3].T + self.A[:3, 3]

    def one(self, origin, direction, what: str) -> np.ndarray:
        hit = self(origin, direction)[0]
        if not np.isfinite(hit).all():
            raise RuntimeError(f"landmark construction failed: no surface hit for {what}")
        return hit


_X, _Y, _Z = np.eye(3)


def _scan(rays: _Rays, start, step, n: int, direction) -> np.ndarray:
    """Hits of ``n`` parallel rays whose origins step from ``start`` by ``step``."""
    origins = np.asarray(start, float) + np.arange(n)[:, None] * np.asarray(step, float)
    return rays(origins, direction)


def _pick(hits: np.ndarray, key, what: str, mask=None) -> np.ndarray:
    ok = np.isfinite(hits).all(axis=1) if mask is None else np.isfinite(hits).all(axis=1) & mask
    if not ok.any():
        raise RuntimeError(f"landmark construction failed: no surface hit for {what}")
    idx = np.flatnonzero(ok)
    return hits[idx[int(np.argmax(key(hits[idx])))]]


def _profile(rays: _Rays, y0: float, y1: float, x: float = 0.0, step: float = 0.1) -> np.ndarray:
    """Hits of rays along -z (from the front) at heights ``y0 .. y1``."""
    n = int(abs(y1 - y0) / step) + 1
    return _scan(rays, (x, y0, 400.0), (0.0, np.sign(y1 - y0) * step, 0.0), n, -_Z)


def _behind(q: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """How far the midline points ``q`` lie behind the profile chord ``a``-``b`` (mm)."""
    d = (b - a)[1:] / np.linalg.norm((b - a)[1:])
    rel = q[:, 1:] - a[1:]
    return -(rel[:, 1] * d[0] - rel[:, 0] * d[1]) * np.sign(d[0])


def _orbit_edge(rays: _Rays, oc, frame, u: float, sign: float) -> np.ndarray:
    """Margin point of the orbital opening above (sign +1) or below (-1) the centre at offset ``u``."""
    e1, e2, e3 = frame
    hits = _scan(rays, oc + u * e1 + 8.0 * e3, sign * 0.1 * e2, 320, -e3)
    depth = (hits - oc) @ e3
    shallow = np.isfinite(depth) & (depth > -6.0)
    first = int(np.argmax(shallow)) if shallow.any() else None
    if first is None or first == 0:
        raise RuntimeError("landmark construction failed: orbital margin not found")
    return hits[first]


_Put = Callable[[str, Any, str, str], None]


def _place_left(cr: _Rays, md: _Rays, h: dict) -> dict:
    """Midline and left-side landmarks: code -> (position, part, construction).

    The groups are placed in a fixed order (cranial midline, mandibular
    midline, orbit, lateral face, aperture and alveoli, ramus); later groups
    read points placed by earlier ones (glabella, orbitale, menton, pogonion).
    """
    out: dict = {}
    put = lambda code, q, part, how: out.__setitem__(code, (np.asarray(q, float), part, how))  # noqa: E731
    g = _place_cranial_midline(cr, h, put)
    _place_mandibular_midline(md, h, put)
    _place_orbit(cr, h, g, put, out)
    _place_lateral_face(cr, h, put)
    _place_aperture_and_alveoli(cr, md, h, put)
    _place_ramus(md, h, put, out)
    return out


def _place_cranial_midline(cr: _Rays, h: dict, put: _Put) -> np.ndarray:
    """Midline profile of the cranium, glabella to basion; returns glabella (mm, head frame)."""
    gl = h["glabella"]
    g = _pick(_profile(cr, gl[1] - 10, gl[1] + 15), lambda q: q[:, 2], "g")
    put("g", g, "cranium", "most anterior point of the midline profile between the brows")
    put(
        "sg",
        cr.one((0, g[1] + 10, 400), -_Z, "sg"),
        "cranium",
        "midline profile 10 mm above glabella",
    )
    prof = _profile(cr, g[1], g[1] - 45)
    z = prof[:, 2]
    deep = ~np.isfinite(z) | (np.r_[z[0], z[:-1]] - z > 6.0)  # the profile drops into the aperture
    i_rhi = int(np.argmax(deep)) - 1
    rhi = prof[i_rhi]
    n = _pick(prof[: i_rhi + 1], lambda q: _behind(q, g, rhi), "n")
    put("n", n, "cranium", "deepest point of the midline profile behind the chord glabella-rhinion")
    put(
        "rhi",
        rhi,
        "cranium",
        "lowest midline point of the nasal bones (profile drops into the aperture)",
    )
    put(
        "mn",
        cr.one((0, 0.5 * (n[1] + rhi[1]), 400), -_Z, "mn"),
        "cranium",
        "midline profile halfway between n and rhi",
    )
    ans = _pick(_profile(cr, h["ans_y"] - 5, h["ans_y"] + 5), lambda q: q[:, 2], "ans")
    put("ans", ans, "cranium", "most anterior point of the anterior nasal spine")
    low = _profile(cr, ans[1] - 2, h["upper_crest_y"] - 6)
    front = np.isfinite(low).all(axis=1) & (low[:, 2] > ans[2] - 25)
    pr = low[np.flatnonzero(front)[-1]]
    ss = _pick(low[: np.flatnonzero(front)[-1]], lambda q: _behind(q, ans, pr), "ss")
    put("ss", ss, "cranium", "deepest midline point of the profile behind the line ans-pr")
    put(
        "pr",
        pr,
        "cranium",
        "lowest point of the midline alveolar profile (between the upper central incisors)",
    )
    put(
        "mp",
        cr.one((0, 0.5 * (ss[1] + pr[1]), 400), -_Z, "mp"),
        "cranium",
        "midline profile halfway between ss and pr",
    )
    v = _pick(_scan(cr, (0, 400, -60), (0, 0, 0.25), 480, -_Y), lambda q: q[:, 1], "v")
    put("v", v, "cranium", "highest midline point of the vault (FH orientation)")
    tilt = np.radians(10.0)
    put(
        "b",
        cr.one((0, 0, 0), (0, np.cos(tilt), np.sin(tilt)), "b"),
        "cranium",
        "midline vault point 10 deg forward of vertical from the porion midpoint (no sutures modelled)",
    )
    ang = np.radians(np.arange(-60.0, 60.0, 0.25))
    back = cr((0.0, 30.0, -20.0), np.column_stack([0 * ang, np.sin(ang), -np.cos(ang)]))
    op = _pick(back, lambda q: np.linalg.norm(q - g, axis=1), "op")
    put("op", op, "cranium", "midline point farthest from glabella")
    fm = h["foramen_magnum"]
    col = _scan(cr, (0, -300, fm[1]), (0, 0, 0.1), int((fm[2] + 8) / 0.1), _Y)
    outside = np.isfinite(col[:, 1]) & (col[:, 1] < fm[0] + 0.5 * fm[3])
    put(
        "ba",
        col[int(np.argmax(outside))],
        "cranium",
        "anterior rim of the foramen magnum in the midline",
    )
    return g


def _place_mandibular_midline(md: _Rays, h: dict, put: _Put) -> None:
    """Midline points of the mandible: alveolar crest, chin and symphysis (mm, head frame)."""
    id_ = _pick(
        _profile(md, h["lower_crest_y"] + 6, h["lower_crest_y"] - 8),
        lambda q: np.where(q[:, 2] > 60, q[:, 1], -1e9),
        "id",
    )
    put("id", id_, "mandible", "highest point of the midline lower alveolar profile")
    me = _pick(_scan(md, (0, -300, 50), (0, 0, 0.2), 250, _Y), lambda q: -q[:, 1], "me")
    put("me", me, "mandible", "lowest midline point of the symphysis")
    pg = _pick(_profile(md, me[1] + 3, id_[1] - 10), lambda q: q[:, 2], "pg")
    put("pg", pg, "mandible", "most anterior midline point of the chin")
    alv = _pick(
        _profile(md, id_[1] - 14, id_[1] - 1), lambda q: q[:, 2], "sm"
    )  # alveolar convexity
    put(
        "sm",
        _pick(_profile(md, pg[1], alv[1]), lambda q: _behind(q, alv, pg), "sm"),
        "mandible",
        "deepest midline point of the concavity between the alveolar convexity below id and pg",
    )
    put(
        "gn",
        md.one((0, pg[1], me[2]), (0, -1, 1), "gn"),
        "mandible",
        "chin outline on the bisector between the facial profile and the lower border",
    )


def _place_orbit(cr: _Rays, h: dict, g: np.ndarray, put: _Put, out: dict) -> None:
    """Left orbital margin points and their neighbours on the frontal and zygomatic bones.

    ``g`` is glabella (mm, head frame); ``out`` holds the points placed so far
    (orbitale is read back from it).
    """
    oc, frame = h["orbit_centre"], h["orbit_frame"]
    e1, e2, e3 = frame
    put(
        "mso_l",
        _orbit_edge(cr, oc, frame, 0.0, 1.0),
        "cranium",
        "upper orbital margin on the orbit's vertical bisector",
    )
    put(
        "mio_l",
        _orbit_edge(cr, oc, frame, 0.0, -1.0),
        "cranium",
        "lower orbital margin on the orbit's vertical bisector",
    )
    lows = np.array([_orbit_edge(cr, oc, frame, u, -1.0) for u in np.arange(-14.0, 14.5, 0.5)])
    put("or_l", lows[np.argmin(lows[:, 1])], "cranium", "lowest point of the lower orbital margin")
    ec = cr.one(oc, e1, "ec")
    put("ec_l", ec, "cranium", "lateral orbital margin on the orbit's horizontal bisector")
    put(
        "d_l",
        cr.one(oc - 5 * e3 + 6 * e2, -e1, "d"),
        "cranium",
        "medial orbital wall, 5 mm inside the opening, 6 mm above its centre",
    )
    put(
        "lo_l",
        cr.one(ec + (30, -10, 30), (-1, 0, -1), "lo"),
        "cranium",
        "zygomatic bone 10 mm below ec",
    )
    put(
        "im_l",
        cr.one((ec[0] - 10, out["or_l"][0][1] - 22, 400), -_Z, "im"),
        "cranium",
        "front of the zygomaxillary junction, 22 mm below orbitale",
    )
    put(
        "fe_l",
        cr.one((28.0, g[1] + 32, 400), -_Z, "fe"),
        "cranium",
        "frontal bone 28 mm lateral, 32 mm above glabella",
    )


def _place_lateral_face(cr: _Rays, h: dict, put: _Put) -> None:
    """Zygomatic arch, mastoid and ear-canal points of the left side, by rays along -x."""
    yy, zz = np.meshgrid(np.arange(-12.0, 6.0, 0.5), np.arange(10.0, 55.0, 0.5), indexing="ij")
    grid = np.column_stack([np.full(yy.size, 300.0), yy.ravel(), zz.ravel()])
    put(
        "zy_l",
        _pick(cr(grid, -_X), lambda q: q[:, 0], "zy"),
        "cranium",
        "most lateral point of the zygomatic arch",
    )
    yy, zz = np.meshgrid(np.arange(-26.0, -10.0, 0.5), np.arange(-25.0, 0.0, 0.5), indexing="ij")
    grid = np.column_stack([np.full(yy.size, 300.0), yy.ravel(), zz.ravel()])
    put(
        "ms_l",
        _pick(cr(grid, -_X), lambda q: q[:, 0], "ms"),
        "cranium",
        "most lateral point of the mastoid process",
    )
    put(
        "sgl_l",
        cr.one((300, 6.0, 10.0), -_X, "sgl"),
        "cranium",
        "zygomatic root 6 mm above and 10 mm in front of porion",
    )
    xs = cr.one((300, h["canal"][0] + h["canal"][2] + 3.0, h["canal"][1]), -_X, "po")[0]
    put(
        "po_l",
        cr.one((xs - 2.0, h["canal"][0], h["canal"][1]), _Y, "po"),
        "cranium",
        "roof of the ear canal 2 mm inside its opening",
    )


def _place_aperture_and_alveoli(cr: _Rays, md: _Rays, h: dict, put: _Put) -> None:
    """Left piriform aperture margin and the alveolar bone over the canines and second molars."""
    y0, y1 = h["ans_y"] + 3.0, h["rhinion_y"] - 3.0
    aps = _scan(cr, (1.5, y0, h["aperture_z"]), (0, 0.25, 0), int((y1 - y0) / 0.25), _X)
    apl = _pick(aps, lambda q: q[:, 0], "apl", mask=aps[:, 0] < 25)
    put("apl_l", apl, "cranium", "most lateral point of the piriform aperture margin")
    put(
        "ac_l",
        cr.one((apl[0] + 5, apl[1], 400), -_Z, "ac"),
        "cranium",
        "maxilla 5 mm lateral of apl",
    )
    t = h["teeth"]
    uc, lc, um2, lm2 = t["U_C_l"], t["L_C_l"], t["U_M2_l"], t["L_M2_l"]
    put(
        "sC_l",
        cr.one(uc.cej + 4 * uc.axis + 25 * uc.buccal, -uc.buccal, "sC"),
        "cranium",
        "alveolar bone over the upper canine root, 4 mm above its CEJ",
    )
    put(
        "iC_l",
        md.one(lc.cej + 4 * lc.axis + 25 * lc.buccal, -lc.buccal, "iC"),
        "mandible",
        "alveolar bone over the lower canine root, 4 mm below its CEJ",
    )
    put(
        "ecm2s_l",
        cr.one((300, um2.cej[1] + 2.5, um2.cej[2]), -_X, "ecm2s"),
        "cranium",
        "buccal alveolar margin at the upper second molar",
    )
    put(
        "ecm2i_l",
        md.one((300, lm2.cej[1] - 2.5, lm2.cej[2]), -_X, "ecm2i"),
        "mandible",
        "buccal alveolar margin at the lower second molar",
    )


def _place_ramus(md: _Rays, h: dict, put: _Put, out: dict) -> None:
    """Ramus, angle and lower-border landmarks of the left side."""

    def breadth(y):  # rearmost contiguous run of lateral hits = the ramus at height y
        hits = _scan(md, (300, y, -10.0), (0, 0, 0.25), 240, -_X)
        idx = np.flatnonzero(np.isfinite(hits[:, 0]) & (hits[:, 0] > h["ramus_x"] - 6.0))
        gaps = np.flatnonzero(np.diff(idx) > 1)
        return hits[idx[0]], hits[idx[gaps[0]] if len(gaps) else idx[-1]]

    ys = np.arange(-50.0, -30.0, 1.0)
    spans = [breadth(y) for y in ys]
    widths = [b[2] - a[2] for a, b in spans]
    a, b = spans[int(np.argmin(widths))]
    y_mr = a[1]
    put(
        "mr_l",
        md.one((300, y_mr, 0.5 * (a[2] + b[2])), -_X, "mr"),
        "mandible",
        "middle of the narrowest ramus breadth",
    )
    a, b = breadth(h["ramus_occlusal_y"])
    put(
        "ol_l",
        md.one((300, a[1], 0.5 * (a[2] + b[2])), -_X, "ol"),
        "mandible",
        "middle of the ramus breadth at the occlusal plane",
    )
    # lower border profile (lowest points) and posterior border profile (rearmost points)
    zs = np.arange(-5.0, 70.0, 0.5)
    xs = np.arange(0.0, 56.0, 1.0)
    xx, zz = np.meshgrid(xs, zs, indexing="ij")
    low = md(np.column_stack([xx.ravel(), np.full(xx.size, -300.0), zz.ravel()]), _Y).reshape(
        len(xs), len(zs), 3
    )
    lowy = np.where(np.isfinite(low[..., 1]), low[..., 1], np.inf)
    border = low[np.argmin(lowy, axis=0), np.arange(len(zs))]
    yb = np.arange(-62.0, -20.0, 0.5)
    xx, yy = np.meshgrid(np.arange(36.0, 56.0, 1.0), yb, indexing="ij")
    rear = md(np.column_stack([xx.ravel(), yy.ravel(), np.full(xx.size, -300.0)]), _Z).reshape(
        xx.shape + (3,)
    )
    rearz = np.where(np.isfinite(rear[..., 2]), rear[..., 2], np.inf)
    post = rear[np.argmin(rearz, axis=0), np.arange(len(yb))]
    me = out["me"][0]
    top = post[-1]
    ok = np.isfinite(border).all(axis=1) & (border[:, 2] < np.nanmin(post[:, 2]) + 15.0)
    tb = border[np.flatnonzero(ok)[np.argmin(border[ok, 1])]]  # lowest point of the angle region
    ok = np.isfinite(post).all(axis=1) & (post[:, 1] < -40.0)
    s2 = (post[:, 2] - top[2]) / np.maximum(top[1] - post[:, 1], 1e-6)
    tr = post[np.flatnonzero(ok)[np.argmin(s2[ok])]]  # tangent point of the ramus line
    d1 = (me - tb)[1:] / np.linalg.norm((me - tb)[1:])  # (y, z) along the lower border, forward
    d2 = (top - tr)[1:] / np.linalg.norm((top - tr)[1:])  # up the ramus
    mat = np.column_stack([d1, -d2])
    s = np.linalg.solve(mat, (tr - tb)[1:])
    vertex = tb[1:] + s[0] * d1
    bis = d1 + d2
    edge = md.one((tb[0], vertex[0], vertex[1]), (0, bis[0], bis[1]), "go")
    inward = 2.5 * bis / np.linalg.norm(bis)
    go = md.one((300.0, edge[1] + inward[0], edge[2] + inward[1]), -_X, "go")
    put(
        "go_l",
        go,
        "mandible",
        "lateral surface of the angle, 2.5 mm inside the point where the bisector "
        "of the ramus line and the mandibular line (menton to the lowest point of the angle) meets the border",
    )
    pg = out["pg"][0]
    zm = 0.5 * (go[2] + pg[2])
    put(
        "mmb_l",
        border[int(np.argmin(np.abs(zs - zm)))],
        "mandible",
        "lowest point of the lower border halfway between gonion and pogonion",
    )
