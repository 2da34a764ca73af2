"""Control-mesh layout for the half head (x >= 0): feature rings, landmarks, free points."""
from __future__ import annotations

import numpy as np

import geom
import headsdf as H

# ------------------------------------------------------------------ eye fissure
EN = (16.35, 10.5)
EX = (44.4, 12.5)
HU, HL = 5.9, 4.0
A_UP = np.log(0.5) / np.log(0.47)
A_LO = np.log(0.5) / np.log(0.57)


def fissure(t, upper=True):
    x = EN[0] + (EX[0] - EN[0]) * t
    base = EN[1] + (EX[1] - EN[1]) * t
    if upper:
        y = base + HU * np.sin(np.pi * t ** A_UP) ** 0.95
    else:
        y = base - HL * np.sin(np.pi * t ** A_LO) ** 1.05
    return np.stack([x, y], -1)


def eye_r0_xy(n_half=8):
    k = np.arange(n_half + 1) / n_half
    t = 0.75 * k + 0.25 * (1 - np.cos(np.pi * k)) / 2
    up = fissure(t, True)          # en .. ex
    lo = fissure(t, False)[::-1]   # ex .. en
    # loop: en, upper..., ex, lower... (without repeating en)
    loop = np.concatenate([up, lo[1:-1]])
    return loop  # 2 n_half points, index 0 = en, n_half = ex


def outward_normals(loop):
    prv = np.roll(loop, 1, 0)
    nxt = np.roll(loop, -1, 0)
    tan = nxt - prv
    n = np.stack([tan[:, 1], -tan[:, 0]], 1)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    # orient outward: away from the centroid
    c = loop.mean(0)
    s = np.sign(((loop - c) * n).sum(1))
    s[s == 0] = 1
    return n * s[:, None]


def resample_closed(loop, m):
    pts = np.vstack([loop, loop[:1]])
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    cum = np.concatenate([[0], np.cumsum(seg)])
    tt = np.linspace(0, cum[-1], m + 1)[:-1]
    x = np.interp(tt, cum, pts[:, 0])
    y = np.interp(tt, cum, pts[:, 1])
    return np.stack([x, y], 1)


def eye_rings():
    """Rings around the left eye opening: list of (name, (n,3) points, kind)."""
    r0 = eye_r0_xy(8)
    nrm = outward_normals(r0)
    # corners: use the bisector of neighbouring normals (already from the tangent)
    rings = []
    z0 = np.array([geom.zray(x, y)[2] for x, y in r0]) - 0.7
    rings.append(("eye_r0", np.column_stack([r0, z0]), "explicit"))
    offs = [1.3, 4.0, 8.5, 14.0]
    counts = [16, 16, 16, 20]
    for k, (d, m) in enumerate(zip(offs, counts), start=1):
        f = np.ones(len(r0))
        f = np.where(nrm[:, 0] < 0, 1.0 - 0.5 * np.abs(nrm[:, 0]) ** 1.5, f)   # medial
        f = np.where(nrm[:, 0] > 0, f * (1.0 - 0.42 * nrm[:, 0] ** 2), f)  # lateral
        f = np.where(nrm[:, 1] < 0, f * (1.0 - 0.3 * (-nrm[:, 1])), f)     # downward
        xy = r0 + (d * f)[:, None] * nrm
        if m != len(xy):
            # resample along the curve, keeping index 0 near the medial corner
            xy = resample_closed(xy, m)
            i0 = np.argmin(xy[:, 0])
            xy = np.roll(xy, -i0, 0)
        kind = "explicit" if k == 1 else "sdf"
        pts = np.array([geom.zray(x, y) for x, y in xy])
        if k == 1:
            pts[:, 2] -= 0.1
        rings.append((f"eye_r{k}", pts, kind))
    return rings


# ------------------------------------------------------------------ mouth
STO_Y = np.interp  # placeholder for readability


def sto_y(x):
    return np.interp(x, H._MX, H._STO)


def border_up(x):
    return np.interp(x, H._MX, H._UB)


def border_lo(x):
    return np.interp(x, H._MX, H._LB)


FRAC = np.array([0.0, 0.13, 0.26, 0.44, 0.62, 0.81])


def half_loop(xs_up, ys_up, corner, xs_lo, ys_lo):
    """top midline -> corner -> bottom midline"""
    up = np.column_stack([xs_up, ys_up])
    lo = np.column_stack([xs_lo, ys_lo])[::-1]
    return np.vstack([up, [corner], lo])


def arc(X, yc, ytop, frac, p=2.2, q=0.8):
    xs = frac * X
    ys = yc + (ytop - yc) * (1 - (xs / X) ** p) ** q
    return xs, ys


def mouth_rings():
    X_CH = 25.0
    rings = []
    # m1: contact line (sts .. ch .. sti) - explicit
    xs = FRAC * X_CH
    ys = sto_y(xs)
    fade = (1 - (xs / X_CH) ** 2) ** 0.5
    zc = np.array([geom.zray(x, y)[2] for x, y in zip(xs, ys)])
    ch = geom.zray(X_CH, sto_y(X_CH))
    ch_z = ch[2] - 0.3
    up1 = np.column_stack([xs, ys + 0.32 * fade + 0.05, zc])
    lo1 = np.column_stack([xs, ys - 0.32 * fade - 0.05, zc])
    m1 = np.vstack([up1, [[X_CH, sto_y(X_CH), ch_z]], lo1[::-1]])
    # m0: inner curl (boundary): 3.5 mm behind the contact, gap opening to 1.6 mm
    X0 = X_CH - 1.2
    xs0 = FRAC * X0
    ys0 = sto_y(xs0)
    zc0 = np.interp(xs0, xs, zc)
    depth = 3.6 * (1 - (xs0 / X0) ** 2) ** 0.5 + 0.8
    gap = 0.85 * (1 - (xs0 / X0) ** 2) ** 0.5 + 0.15
    up0 = np.column_stack([xs0, ys0 + gap, zc0 - depth])
    lo0 = np.column_stack([xs0, ys0 - gap, zc0 - depth])
    m0 = np.vstack([up0, [[X0, sto_y(X0), ch_z - 1.6]], lo0[::-1]])
    rings.append(("mouth_m0", m0, "explicit"))
    rings.append(("mouth_m1", m1, "explicit"))
    # m2: mid vermilion; m3: vermilion border (frontal layout, z from the surface)
    specs = []
    X2 = 25.8
    xs2 = FRAC * X2
    yu2 = 0.5 * (sto_y(xs2) + border_up(xs2 * 27.2 / X2))
    yl2 = 0.5 * (sto_y(xs2) + border_lo(xs2 * 27.2 / X2))
    specs.append(("mouth_m2", half_loop(xs2, yu2, (X2, sto_y(X2)), xs2, yl2)))
    X3 = 27.2
    xs3 = FRAC * X3
    xs3[2] = 6.5  # crista philtri
    specs.append(("mouth_m3", half_loop(xs3, border_up(xs3 * 25.0 / X3), (X3, sto_y(X_CH)),
                                        xs3, border_lo(xs3 * 25.0 / X3))))
    # m4..m6: skin rings
    frac7 = np.array([0.0, 0.12, 0.25, 0.39, 0.54, 0.70, 0.86])
    X4 = 30.5
    xu, yu = arc(X4, -49.0, -37.4, frac7, 2.4, 0.75)
    yu = yu + 0.8 * np.exp(-((xu - 7.5) / 3.0) ** 2)
    xl, yl = arc(X4, -49.0, -61.6, frac7, 2.2, 0.8)
    specs.append(("mouth_m4", half_loop(xu, yu, (X4, -49.3), xl, yl)))
    frac8 = np.array([0.0, 0.11, 0.22, 0.34, 0.47, 0.61, 0.75, 0.88])
    X5 = 35.5
    xu, yu = arc(X5, -48.0, -33.5, frac8, 2.2, 0.75)
    xl, yl = arc(X5, -49.0, -66.2, frac8, 2.0, 0.8)
    specs.append(("mouth_m5", half_loop(xu, yu, (X5, -49.0), xl, yl)))
    # m6: sn -> under the ala -> nasolabial fold -> chin (outermost, Delaunay boundary)
    up6 = np.array([[0.0, -29.5], [4.5, -30.8], [9.4, -30.6], [14.5, -31.0], [19.5, -32.5], [25.5, -36.5],
                    [31.0, -40.5], [36.5, -45.0]])
    corner6 = (40.5, -51.0)
    lo6 = np.array([[0.0, -74.0], [6.5, -74.0], [13.0, -73.2], [19.5, -71.5], [26.0, -68.5], [31.5, -64.0],
                    [36.5, -58.0]])
    specs.append(("mouth_m6", np.vstack([up6, [corner6], lo6[::-1]])))
    for name, xy in specs:
        pts = np.array([geom.zray(x, y) for x, y in xy])
        rings.append((name, pts, "sdf"))
    return rings


# ------------------------------------------------------------------ nostrils
NOSTRIL_C = np.array([5.5, -23.6, 95.6])


def nostril_rings():
    from sdflib import rot_matrix
    R = rot_matrix(yaw=24)
    rings = []
    virt = []
    for name, scale, lift, m in (("nostril_rim", 1.0, 0.0, 8), ("nostril_in", 0.55, 2.4, 6)):
        a = np.linspace(0, 2 * np.pi, m, endpoint=False) + np.pi  # start at the back
        loc = np.stack([2.8 * scale * np.cos(a), np.zeros(m), 5.4 * scale * np.sin(a)], 1)
        w = NOSTRIL_C + loc @ R.T
        zz = w[:, 2]
        y_under = -26.5 + 0.30 * (zz - 91.5)
        foot = w.copy()
        foot[:, 1] = y_under - 0.8
        v = foot.copy()
        if lift == 0.0:
            pts = geom.project(foot + np.array([0.0, 0.8, 0.0]))
            rings.append((name, pts, "sdf"))
        else:
            pts = foot.copy()
            pts[:, 1] = y_under + lift
            rings.append((name, pts, "explicit"))
        virt.append(v)
    c = NOSTRIL_C.copy()
    c[1] = -26.5 + 0.30 * (c[2] - 91.5) + 3.6
    foot = NOSTRIL_C.copy()
    foot[1] = -26.5 + 0.30 * (foot[2] - 91.5) - 0.8
    return rings, virt, c, foot


# ------------------------------------------------------------------ neck
def neck_rings(n=11):
    th = np.linspace(0, np.pi, n)
    levels = [(-122.0, -60.0), (-142.0, -98.0), (-163.0, -140.0), (-184.95, -184.95)]
    rings = []
    for k, (yf, yb) in enumerate(levels):
        y = yf + (yb - yf) * (1 - np.cos(th)) / 2
        cz = H.cz_at(y)
        o = np.stack([np.zeros(n), y, cz], 1)
        d = np.stack([np.sin(th), np.zeros(n), np.cos(th)], 1)
        p = geom.rays_hit(o, d, t_max=120, step=0.3)
        p[0, 0] = 0.0
        p[-1, 0] = 0.0
        rings.append((f"neck_n{k}", p, "sdf"))
    return rings


# ------------------------------------------------------------------ ear (explicit parametric)
EAR_O = np.array([69.5, 0.6, 9.2])        # on the head surface at porion level
EAR_TILT = np.radians(16.0)                # long axis leaning back
E_U = np.array([0.0, np.cos(EAR_TILT), -np.sin(EAR_TILT)])
E_B = np.array([0.0, -np.sin(EAR_TILT), -np.cos(EAR_TILT)])
E_N = np.array([1.0, 0.0, 0.0])
EAR_C = np.array([9.0, 2.1])              # (b, u) centre of the ring system (concha)

# outline of the auricle in (b, u), clockwise from the helix root (front top)
_OUT = np.array([[0.0, 14.0], [2.0, 23.0], [7.0, 30.0], [14.0, 33.5], [22.0, 32.5], [29.0, 27.5],
                 [33.5, 18.0], [34.5, 7.0], [32.0, -3.5], [27.5, -11.0], [22.0, -17.0], [18.0, -22.5],
                 [14.0, -27.5], [8.5, -30.5], [3.5, -28.0], [1.0, -20.0], [0.0, -10.0], [-1.5, 0.0],
                 [-1.0, 7.5]])
_OUT = _OUT * np.array([1.0, 1.05])
# attachment loop on the head (b, u)
_ATT = np.array([[2.5, 16.0], [8.0, 17.5], [13.5, 14.0], [16.0, 5.0], [15.5, -5.0], [12.5, -13.5],
                 [8.0, -18.5], [3.5, -17.5], [1.0, -10.0], [0.0, -1.0], [0.2, 6.0], [1.0, 12.0]]) * np.array([1.0, 1.05])


def _polar(pts, c):
    d = pts - c
    return np.arctan2(d[:, 1], d[:, 0])


def _radial_sample(poly, c, angles):
    """r(theta) of a star-shaped closed polygon around c, sampled at `angles`."""
    a = _polar(poly, c)
    r = np.linalg.norm(poly - c, axis=1)
    order = np.argsort(a)
    a, r = a[order], r[order]
    a = np.concatenate([a - 2 * np.pi, a, a + 2 * np.pi])
    r = np.concatenate([r, r, r])
    return np.interp(angles, a, r)


EAR_M = 16


def _ear_spokes(m):
    """polar angles (around EAR_C) of m outline points spaced evenly by arc length, from the top, increasing."""
    pts = np.vstack([_OUT, _OUT[:1]])
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    cum = np.concatenate([[0], np.cumsum(seg)])
    tt = np.linspace(0, cum[-1], 400, endpoint=False)
    dense = np.stack([np.interp(tt, cum, pts[:, 0]), np.interp(tt, cum, pts[:, 1])], 1)
    ang = np.unwrap(_polar(dense, EAR_C))
    # outline runs clockwise in (b, u)?  make the angle increase along the walk
    if ang[-1] < ang[0]:
        dense, ang = dense[::-1], ang[::-1]
        tt = tt[-1] - tt[::-1]
    i0 = int(np.argmax(dense[:, 1]))
    order = np.roll(np.arange(len(dense)), -i0)
    d = dense[order]
    seg2 = np.linalg.norm(np.diff(np.vstack([d, d[:1]]), axis=0), axis=1)
    cum2 = np.concatenate([[0], np.cumsum(seg2)])
    picks = [int(np.argmin(np.abs(cum2[:-1] - s))) for s in np.linspace(0, cum2[-1], m, endpoint=False)]
    th = np.unwrap(_polar(d[picks], EAR_C))
    return th


EAR_TH = None


def rim_height(th):
    """protrusion of the helix rim from the head (mm), by angle around the concha."""
    # th: pi/2 top, pi front, 0 back, -pi/2 bottom (b axis points backwards)
    back = np.cos(th)      # +1 at the back (pa)
    up = np.sin(th)
    return 12.0 + 6.0 * back - 2.5 * np.clip(up, 0, 1) - 3.0 * np.clip(-back, 0, 1)


# ring definitions: (name, s (0 attach .. 1 rim), height function, face)
def ear_point(b, u, h):
    return EAR_O + b[..., None] * E_B + u[..., None] * E_U + h[..., None] * E_N


def ear_geometry(s, th):
    """Position on the ear for ring coordinate s in [0, 3] and angle th.

    s in [0, 1]: back face from the head attachment (0) to the rim (1);
    s in [1, 3]: front face from the rim (1) to the concha centre (3).
    """
    s = np.asarray(s, float)
    th = np.asarray(th, float)
    r_out = _radial_sample(_OUT, EAR_C, th)
    r_att = _radial_sample(_ATT, EAR_C, th)
    hr = rim_height(th)
    cth, sth = np.cos(th), np.sin(th)
    # back face
    sb = np.clip(s, 0, 1)
    rb = r_att + (r_out - r_att) * sb ** 0.8
    hb = hr * sb ** 0.6 - 0.8 * np.sin(np.pi * sb) * (sb > 0)
    # front face: t = 0 rim, 1 centre
    t = np.clip((s - 1.0) / 2.0, 0, 1)
    rf = r_out * (1 - t) ** 1.0
    # height profile across the front: helix roll, scapha groove, antihelix ridge, concha bowl
    prof = np.interp(t, [0.0, 0.07, 0.21, 0.33, 0.45, 0.6, 0.75, 1.0],
                     [1.0, 1.10, 0.66, 0.80, 0.95, 0.55, 0.18, 0.06])
    # tragus: the front wall of the concha rises in front of the ear canal
    wf = np.clip((-cth - 0.55) / 0.35, 0, 1)
    prof = prof + 0.45 * wf * np.exp(-((t - 0.72) / 0.12) ** 2)
    lobe = np.interp(t, [0.0, 0.1, 0.4, 0.7, 1.0], [1.0, 1.06, 0.92, 0.55, 0.12])
    wl = np.clip((-sth - 0.45) / 0.4, 0, 1)
    prof = (1 - wl) * prof + wl * lobe
    hf = hr * prof + 2.2 * (t > 0) * (t < 0.1) * np.sin(np.pi * t / 0.1) * (1 - wl)
    front = s > 1.0
    r = np.where(front, rf, rb)
    h = np.where(front, hf, hb)
    b = EAR_C[0] + r * cth
    u = EAR_C[1] + r * sth
    return ear_point(b, u, h)


EAR_RINGS = [  # (name, s)
    ("ear_att", 0.0), ("ear_b1", 0.42), ("ear_b2", 0.82), ("ear_rim", 1.0),
    ("ear_f1", 1.14), ("ear_f2", 1.42), ("ear_f3", 1.9), ("ear_f4", 2.5),
]


def ear_rings():
    global EAR_TH
    EAR_TH = _ear_spokes(EAR_M)
    rings = []
    for name, s in EAR_RINGS:
        if name == "ear_att":
            # on the head surface: project the attachment loop onto the SDF
            p = ear_geometry(np.zeros(EAR_M), EAR_TH)
            p = geom.project(p - 3 * E_N)
            rings.append((name, p, "sdf"))
        else:
            p = ear_geometry(np.full(EAR_M, s), EAR_TH)
            rings.append((name, p, "explicit"))
    centre = ear_geometry(np.array([3.0]), np.array([0.0]))[0]
    return rings, centre
