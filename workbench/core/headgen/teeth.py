"""Teeth and tongue of the reference head: dental arches, simple tooth solids, tongue.

Units and frame: millimetres, head frame (x to the subject's left, y up, z
forward; Frankfort Horizontal y = 0).

Teeth
-----
16 upper and 16 lower permanent teeth (I1 I2 C PM1 PM2 M1 M2 M3 per side),
with the average crown and root dimensions of Wheeler's table (Nelson & Ash
2010, ch. 1): crown length (cervico-incisal/occlusal), root length,
mesiodistal (MD) and labio/bucco-lingual (LL) diameters of the crown and at
the cervix.  The cervix being narrower than the crown, the cemento-enamel
junction (CEJ) shows as a waist; its position is returned per tooth
(:attr:`Tooth.cej`).

Each tooth is placed along its arch by cumulative mesiodistal width (0.4-0.8 mm
gaps instead of contact points, so that every tooth stays a separate solid), its tip on the occlusal plane (tilted ``occlusal_plane_deg``
to FH, higher posteriorly), its long axis inclined labially for incisors
(upper 20 deg, lower 24 deg to the vertical; interincisal angle ~135 deg,
cf. Proffit 2013).  The lower arch runs inside the upper one so that the
upper incisors overlap the lower ones by about 2 mm vertically (overbite)
and 2.5 mm horizontally (overjet) and the upper buccal cusps lie buccal to
the lower ones; posterior teeth meet on the occlusal plane (0.4 mm apart).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from workbench.core.headgen.sdf import (
    Ellipsoid,
    Function,
    Grid,
    mesh_from_field,
    resample,
    smax,
    smin,
)
from workbench.core.mesh import Mesh

TOOTH_NAMES = ("I1", "I2", "C", "PM1", "PM2", "M1", "M2", "M3")
#: crown length, root length, MD crown, MD cervix, LL crown, LL cervix (mm), Nelson & Ash 2010
UPPER_DIMS = {
    "I1": (10.5, 13.0, 8.5, 7.0, 7.0, 6.0),
    "I2": (9.0, 13.0, 6.5, 5.0, 6.0, 5.0),
    "C": (10.0, 17.0, 7.5, 5.5, 8.0, 7.0),
    "PM1": (8.5, 14.0, 7.0, 5.0, 9.0, 8.0),
    "PM2": (8.5, 14.0, 7.0, 5.0, 9.0, 8.0),
    "M1": (7.5, 12.5, 10.0, 8.0, 11.0, 10.0),
    "M2": (7.0, 11.5, 9.0, 7.0, 11.0, 10.0),
    "M3": (6.5, 11.0, 8.5, 6.5, 10.0, 9.5),
}
LOWER_DIMS = {
    "I1": (9.0, 12.5, 5.0, 3.5, 6.0, 5.3),
    "I2": (9.5, 14.0, 5.5, 4.0, 6.5, 5.8),
    "C": (11.0, 16.0, 7.0, 5.5, 7.5, 7.0),
    "PM1": (8.5, 14.0, 7.0, 5.0, 7.5, 6.5),
    "PM2": (8.0, 14.5, 7.0, 5.0, 8.0, 7.0),
    "M1": (7.5, 14.0, 11.0, 9.0, 10.5, 9.0),
    "M2": (7.0, 13.0, 10.5, 8.0, 10.0, 9.0),
    "M3": (7.0, 11.0, 10.0, 7.5, 9.5, 9.0),
}
#: long-axis inclination to the vertical (deg, crown tipped labially/buccally)
INCLINATION = {
    "I1": 20.0,
    "I2": 18.0,
    "C": 10.0,
    "PM1": 5.0,
    "PM2": 3.0,
    "M1": 0.0,
    "M2": -3.0,
    "M3": -5.0,
}
LOWER_INCLINATION = {
    "I1": 24.0,
    "I2": 22.0,
    "C": 12.0,
    "PM1": 6.0,
    "PM2": 3.0,
    "M1": 0.0,
    "M2": -4.0,
    "M3": -6.0,
}
#: vertical overlap beyond the occlusal plane (mm; upper tips below it, lower tips above it)
OVERLAP = {"I1": 1.0, "I2": 0.8}
#: horizontal inset of the lower arch from the upper one, by tooth of the upper arch (mm)
GAP = 0.4


@dataclass(frozen=True)
class Tooth:
    """One tooth in the head frame (mm).

    ``tip``: middle of the incisal edge / occlusal surface; ``axis``: unit
    vector from the tip toward the root apex; ``mesial``: unit vector toward
    the midline along the arch; ``buccal``: unit labial/buccal direction,
    perpendicular to ``axis`` and ``mesial``;
    ``cej``: point of the long axis at the cemento-enamel junction;
    ``cej_labial``: the CEJ on the labial/buccal face.
    """

    code: str  # e.g. "U_I1_l", "L_M2_r"
    jaw: str
    name: str
    side: str
    tip: np.ndarray
    axis: np.ndarray
    mesial: np.ndarray
    buccal: np.ndarray
    crown: float
    root: float
    md: float
    md_cervix: float
    ll: float
    ll_cervix: float

    @property
    def cej(self) -> np.ndarray:
        return self.tip + self.crown * self.axis

    @property
    def cej_labial(self) -> np.ndarray:
        return self.cej + 0.5 * self.ll_cervix * self.buccal

    @property
    def apex(self) -> np.ndarray:
        return self.tip + (self.crown + self.root) * self.axis


def _arch(ctrl_xz: np.ndarray, y_of_z, widths, start: float):
    """Points, tangents (toward distal) and outward normals at arc lengths for ``widths``."""
    full = np.vstack([ctrl_xz[:0:-1] * [-1, 1], ctrl_xz])  # whole arch: symmetric tangents
    pts = np.column_stack([full[:, 0], np.zeros(len(full)), full[:, 1]])
    s_pts, tang, _ = resample(pts, step=0.1)
    keep = s_pts[:, 0] >= 0.0
    s_pts, tang = s_pts[keep], tang[keep]
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(s_pts, axis=0), axis=1))])
    gaps = np.array([0.0, 0.8, 0.5] + [GAP] * (len(widths) - 3))
    centres = start + np.cumsum(widths) - 0.5 * np.asarray(widths) + np.cumsum(gaps)
    idx = np.clip(np.searchsorted(arc, centres), 0, len(arc) - 1)
    p, t = s_pts[idx].copy(), tang[idx]
    p[:, 1] = y_of_z(p[:, 2])
    normal = np.column_stack([-t[:, 2], np.zeros(len(t)), t[:, 0]])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    return p, t, normal


def _inset(ctrl_xz: np.ndarray, inset: np.ndarray) -> np.ndarray:
    """Offset a left half-arch polyline (x, z) inward by ``inset`` mm per point."""
    full = np.vstack([ctrl_xz[:0:-1] * [-1, 1], ctrl_xz])
    tang = np.gradient(full, axis=0)[len(ctrl_xz) - 1 :]
    normal = np.column_stack([tang[:, 1], -tang[:, 0]])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    out = ctrl_xz + inset[:, None] * normal
    out[0, 0] = 0.0
    return out


def dental_arches(params: dict) -> list[Tooth]:
    """All 32 teeth (upper then lower; left then right) for the skull ``params``."""
    tp = params["teeth"]
    y0, z0 = tp["occlusal_y_incisor"], tp["occlusal_z_incisor"]
    slope = np.tan(np.radians(tp["occlusal_plane_deg"]))

    def plane(z):
        return y0 + (z0 - z) * slope

    upper_ctrl = np.asarray(tp["upper_arch"], float)
    lower_ctrl = _inset(upper_ctrl, np.asarray(tp["lower_inset"], float))
    teeth: list[Tooth] = []
    for jaw, dims, incl in (("U", UPPER_DIMS, INCLINATION), ("L", LOWER_DIMS, LOWER_INCLINATION)):
        d = {k: np.asarray(v, float) for k, v in dims.items()}  # male size; meshes are scaled later
        widths = [d[n][2] for n in TOOTH_NAMES]
        ctrl = upper_ctrl if jaw == "U" else lower_ctrl
        p, t, normal = _arch(ctrl, plane, widths, 0.7)
        for i, name in enumerate(TOOTH_NAMES):
            crown, root, md, mdc, ll, llc = d[name]
            # posterior crowns stand square to the occlusal plane, anterior ones to FH
            tilt = np.arctan(slope) if name[0] in "PM" else 0.0
            up = np.array([0.0, np.cos(tilt), np.sin(tilt)]) * (1.0 if jaw == "U" else -1.0)
            theta = np.radians(incl[name])
            axis = np.cos(theta) * up - np.sin(theta) * normal[i]
            labial = np.cos(theta) * normal[i] + np.sin(theta) * up  # tilted with the tooth
            tip = p[i] - OVERLAP.get(name, 0.0) * up + 0.2 * up
            for side, sx in (("l", 1.0), ("r", -1.0)):
                m = np.array([sx, 1.0, 1.0])
                teeth.append(
                    Tooth(
                        f"{jaw}_{name}_{side}",
                        jaw,
                        name,
                        side,
                        tip * m,
                        axis * m,
                        -t[i] * m,
                        labial * m,
                        crown,
                        root,
                        md,
                        mdc,
                        ll,
                        llc,
                    )
                )
    return teeth


# ---------------------------------------------------------------- tooth solids
def _loft(m, bl, h, hs, a, b, p=2.6):
    """Superellipse cross-sections (half sizes ``a``, ``b`` at heights ``hs``) stacked along h."""
    aa, bb = np.interp(h, hs, a), np.interp(h, hs, b)
    um, ul = np.abs(m / aa) + 1e-9, np.abs(bl / bb) + 1e-9
    q = (um**p + ul**p) ** (1.0 / p)
    grad = q ** (1.0 - p) * np.hypot(um ** (p - 1.0) / aa, ul ** (p - 1.0) / bb)
    d2 = (q - 1.0) / np.maximum(grad, 1e-6)  # first-order distance to the section outline
    dh = np.maximum(hs[0] - h, h - hs[-1])
    return np.minimum(np.maximum(d2, dh), 0.0) + np.hypot(np.maximum(d2, 0.0), np.maximum(dh, 0.0))


def tooth_sdf(tooth: Tooth):
    """Distance function ``f(x, y, z)`` and bounds of one tooth."""
    R = np.stack([tooth.mesial, tooth.buccal, tooth.axis])
    c, r = tooth.crown, tooth.root
    A, Ac, B, Bc = tooth.md / 2, tooth.md_cervix / 2, tooth.ll / 2, tooth.ll_cervix / 2
    kind = tooth.name[0] if tooth.name[0] != "P" else "P"

    def f(x, y, z):
        px, py, pz = x - tooth.tip[0], y - tooth.tip[1], z - tooth.tip[2]
        m, bl, h = (R[i, 0] * px + R[i, 1] * py + R[i, 2] * pz for i in range(3))
        bl = bl * np.where(bl < 0, 1.15, 1.0)  # crowns are thinner and narrower lingually
        m = m * (1.0 + (0.45 if kind in "IC" else 0.15) * np.clip(-bl / B, 0.0, 1.0))
        if kind == "I":  # chisel-shaped: thin at the incisal edge
            crown = (
                _loft(
                    m,
                    bl,
                    h,
                    [0.4, 0.25 * c, 0.7 * c, c],
                    [A * 0.92 - 0.4, A - 0.4, A * 0.95 - 0.4, Ac - 0.4],
                    [0.45, 0.45 * B - 0.1, B - 0.4, Bc - 0.4],
                    p=2.6,
                )
                - 0.4
            )
        elif kind == "C":  # pointed cusp
            crown = (
                _loft(
                    m,
                    bl,
                    h,
                    [0.4, 0.3 * c, 0.65 * c, c],
                    [0.5, A * 0.85 - 0.4, A - 0.4, Ac - 0.4],
                    [0.5, B * 0.8 - 0.4, B - 0.4, Bc - 0.4],
                    p=2.4,
                )
                - 0.4
            )
        else:  # premolar / molar: occlusal table with cusps
            crown = (
                _loft(
                    m,
                    bl,
                    h,
                    [0.5, 0.12 * c, 0.45 * c, c],
                    [A * 0.72 - 0.5, A * 0.93 - 0.5, A - 0.5, Ac - 0.5],
                    [B * 0.72 - 0.5, B * 0.95 - 0.5, B - 0.5, Bc - 0.5],
                    p=2.8,
                )
                - 0.5
            )
            groove = (
                (np.abs(bl) - 0.6) if kind == "P" else np.minimum(np.abs(bl) - 0.6, np.abs(m) - 0.6)
            )
            fossa = np.maximum(groove, h - 1.5)
            crown = smax(crown, -fossa, 0.8)
        root = _loft(
            m,
            bl,
            h,
            [c - 0.5, c + 0.45 * r, c + r],
            [Ac * 0.95, Ac * 0.75, 0.8],
            [Bc * 0.95, Bc * 0.8, 1.0],
            p=2.0,
        )
        if kind == "M":  # mesial and distal roots: cut the furcation
            furcation = _loft(
                m, bl, h, [c + 0.3 * r, c + r + 1.0], [Ac * 0.2, Ac * 0.45], [Bc * 1.3, Bc * 1.3]
            )
            root = smax(root, -furcation, 0.5)
        return smin(crown, root, 0.6)

    ext = c + r + 1.0
    corners = [
        tooth.tip + sm * A * 1.2 * tooth.mesial + sb * B * 1.3 * tooth.buccal + sh * tooth.axis
        for sm in (-1, 1)
        for sb in (-1, 1)
        for sh in (-1.0, ext)
    ]
    return f, np.min(corners, axis=0) - 1.0, np.max(corners, axis=0) + 1.0


def teeth_mesh(teeth: list[Tooth], jaw: str, h: float = 0.35, target_per_tooth: int = 700) -> Mesh:
    """One mesh with a closed component per tooth of ``jaw`` ("U" or "L")."""
    mine = [t for t in teeth if t.jaw == jaw and t.side == "l"]
    sdfs = [tooth_sdf(t) for t in mine]
    lo = np.min([s[1] for s in sdfs], axis=0)
    hi = np.max([s[2] for s in sdfs], axis=0)
    grid = Grid(lo - 2 * h, hi + 2 * h, h, half=True)
    for f, a, b in sdfs:
        grid.union(Function(f, a, b))
    field, origin = grid.full()
    return mesh_from_field(
        field, origin, h, smooth=4, target=target_per_tooth * 2 * len(mine), keep_all=True
    )


# ---------------------------------------------------------------- tongue
def _teeth_distance(teeth: list[Tooth], points: np.ndarray) -> np.ndarray:
    """Distance (mm) from ``points`` to the nearest of ``teeth`` and their mirror images."""
    p = np.asarray(points, float)
    q = np.column_stack([np.abs(p[:, 0]), p[:, 1], p[:, 2]])
    out = np.full(len(p), 50.0)
    for t in teeth:
        f, lo, hi = tooth_sdf(t)
        near = np.all((q > lo - 3.0) & (q < hi + 3.0), axis=1)
        if near.any():
            out[near] = np.minimum(out[near], f(q[near, 0], q[near, 1], q[near, 2]))
    return out


def tongue_mesh(
    teeth: list[Tooth], h: float = 0.8, target: int = 3000, avoid=None, clearance: float = 1.0
) -> Mesh:
    """A rounded tongue resting inside the lower arch, its dorsum just below the occlusal plane.

    Built from the lower teeth: the body fills the arch from behind the
    molars to about 3 mm behind the lingual faces of the incisors.
    ``avoid(points (k, 3)) -> distances (k,)`` (e.g. the mandible's field)
    is kept ``clearance`` mm away, so the tongue rests against the lingual
    side of the jaw without entering it.
    """
    lower = [t for t in teeth if t.jaw == "L" and t.side == "l"]
    inc = next(t for t in lower if t.name == "I1")
    m2 = next(t for t in lower if t.name == "M2")
    pm2 = next(t for t in lower if t.name == "PM2")
    front = inc.tip[2] - 0.5 * inc.ll - 3.0
    back = m2.tip[2] - 22.0
    half_w = pm2.tip[0] - 0.5 * pm2.ll - 3.0
    top = pm2.tip[1] - 2.0
    length = front - back
    body = Ellipsoid((0.0, top - 9.0, back + 0.5 * length), (half_w, 9.0, 0.5 * length))
    tip = Ellipsoid((0.0, top - 5.0, front - 9.0), (0.6 * half_w, 4.5, 9.0))
    root = Ellipsoid((0.0, top - 15.0, back + 0.45 * length), (0.8 * half_w, 9.0, 0.42 * length))
    grid = Grid(np.minimum(body.lo, root.lo) - 3, np.maximum(body.hi, tip.hi) + 3, h, half=True)
    grid.union(body).union(tip, k=4.0).union(root, k=5.0)
    keep_clear = [lambda q: _teeth_distance(lower, q)] + ([avoid] if avoid is not None else [])
    ax = [grid.origin[d] + grid.h * np.arange(grid.shape[d]) for d in range(3)]
    pts = np.stack(np.meshgrid(*ax, indexing="ij"), axis=-1).reshape(-1, 3)
    inside = grid.field.ravel() < 3.0
    for other in keep_clear:
        d = np.full(len(pts), 50.0, np.float32)
        d[inside] = other(pts[inside])
        grid.field = smax(grid.field, -(d.reshape(grid.shape) - clearance), 1.5).astype(np.float32)
    field, origin = grid.full()
    return mesh_from_field(field, origin, h, smooth=6, target=target)
