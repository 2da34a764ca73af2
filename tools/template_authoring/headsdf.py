"""Signed-distance design of the male reference head (authoring only).

Head frame, mm: x to the subject's left, y up, z forward; FH = y 0; origin between porions.
"""
from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicSpline, PchipInterpolator

from sdflib import (capsule, ellipsoid, length, mirror_x, polyline_tube, rot_matrix, smax, smin, sphere, ssub)

EYE_C = np.array([32.5, 13.0, 59.5])
EYE_R = 12.0


def spline(ys, vs):
    f = CubicSpline(np.asarray(ys, float), np.asarray(vs, float), bc_type="natural")
    lo, hi = ys[0], ys[-1]
    return lambda y: f(np.clip(y, lo, hi))


def bump(u):
    """smooth compact bump (1 - r^2)^2 for r = |u| < 1."""
    r2 = np.minimum((u * u).sum(-1), 1.0)
    return (1.0 - r2) ** 2


def seg_dist(ax, y, a, b):
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    ab = b - a
    t = np.clip(((ax - a[0]) * ab[0] + (y - a[1]) * ab[1]) / ab.dot(ab), 0, 1)
    return np.hypot(ax - (a[0] + t * ab[0]), y - (a[1] + t * ab[1])), t


def smoothstep(e0, e1, x):
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3 - 2 * t)


# ------------------------------------------------------------------ face loft profiles
LOFT_Y = [-107, -102, -96, -90, -82, -74, -66, -58, -50, -42, -34, -26, -18, -9, 0, 12, 24, 34, 44, 54, 66]
LOFT_F = [60, 73.5, 81.0, 85.0, 87.0, 85.5, 83.0, 86.5, 88.5, 90.5, 91.3, 91.0, 87.5, 85.0, 82.5, 80.0, 85.0, 91.5, 94.0, 86.0, 70.0]
LOFT_W = [18, 30, 38, 44.5, 50.0, 53.0, 55.0, 56.5, 58.0, 60.0, 62.0, 64.0, 66.0, 67.5, 68.0, 66.5, 64.5, 63.0, 61.5, 60.0, 56.0]
LOFT_N = [1.8, 1.8, 1.8, 1.8, 1.8, 1.75, 1.72, 1.72, 1.72, 1.75, 1.8, 1.9, 2.1, 2.2, 2.05, 1.85, 2.05, 2.25, 2.35, 2.4, 2.4]
LOFT_C = 14.0
_W = spline(LOFT_Y, LOFT_W)
_F = spline(LOFT_Y, LOFT_F)
_N = spline(LOFT_Y, LOFT_N)

# mouth layout (x >= 0 half): stomion line and vermilion borders
_MX = [0.0, 3.0, 6.5, 10.0, 15.0, 20.0, 25.0]
_STO = [-49.7, -49.6, -49.3, -49.1, -49.05, -49.25, -49.7]
_UB = [-41.6, -41.1, -40.4, -41.3, -43.4, -46.2, -49.6]
_LB = [-57.6, -57.5, -57.3, -56.9, -55.7, -53.4, -49.6]


_UPK = ([-0.06, 0.0, 0.25, 0.55, 0.85, 1.0, 1.15, 1.45, 1.6], [0.2, 0.45, 0.86, 1.0, 0.93, 0.82, 0.38, 0.0, 0.0])
_LOK = ([-0.06, 0.0, 0.3, 0.5, 0.8, 1.0, 1.25, 1.6, 1.8], [0.2, 0.5, 0.95, 1.0, 0.86, 0.62, 0.22, 0.0, 0.0])
_upf = PchipInterpolator(*_UPK)
_lof = PchipInterpolator(*_LOK)


def lip_disp(ax, y):
    t = np.clip(ax / 25.5, 0, 1)
    ys = np.interp(ax, _MX, _STO)
    ub = np.interp(ax, _MX, _UB)
    lb = np.interp(ax, _MX, _LB)
    fade = np.where(ax < 25.5, (1.0 - t ** 2) ** 0.55, 0.0)
    hu = np.maximum(ub - ys, 0.8)
    hl = np.maximum(ys - lb, 0.8)
    su = np.clip((y - ys) / hu, -0.06, 1.6)
    sl = np.clip((ys - y) / hl, -0.06, 1.8)
    du = np.where((y - ys) / hu > -0.06, _upf(su), 0.0)
    dl = np.where((ys - y) / hl > -0.06, _lof(sl), 0.0)
    d = fade * (5.9 * du + 8.6 * dl)
    # stomion groove
    d -= 1.3 * fade * np.exp(-((y - ys) / 0.7) ** 2)
    # commissure tucked in, modiolus bulge lateral of it
    d -= 1.6 * bump(np.stack([(ax - 25.5) / 3.5, (y + 49.7) / 3.0], -1))
    d += 1.0 * bump(np.stack([(ax - 30.0) / 6.0, (y + 50.5) / 7.0], -1))
    # philtrum columns and dimple
    dcol, tcol = seg_dist(ax, y, (3.8, -29.0), (6.3, -40.6))
    d += 0.6 * np.exp(-(dcol / 1.8) ** 2) * smoothstep(0.0, 0.25, tcol)
    d -= 0.5 * np.exp(-(ax / 2.2) ** 2) * smoothstep(-29.0, -33.0, y) * smoothstep(-42.0, -38.0, y)
    return d


def face_disp(x, y):
    """z displacement (mm) of the face loft front."""
    ax = np.abs(x)
    d = np.zeros_like(x)
    # eye socket: broad shallow hollow + upper-lid sulcus under the brow
    d -= 2.4 * bump(np.stack([(ax - 31.0) / 20.0, (y - 15.0) / 15.0], -1))
    d -= 0.9 * bump(np.stack([(ax - 33.0) / 14.0, (y - 23.5) / 6.5], -1))
    # medial canthal hollow (skin wraps toward the globe beside the nose)
    d -= 4.0 * bump(np.stack([(ax - 18.0) / 7.0, (y - 12.5) / 7.0], -1))
    # lower lid / tear trough
    d -= 1.2 * bump(np.stack([(ax - 27.0) / 12.0, (y - 3.5) / 5.0], -1))
    # brow ridge along the upper orbital rim, fading laterally
    yb = 35.0 - 2.5 * np.clip(ax / 45.0, 0, 1) ** 2
    d += 2.3 * bump(np.stack([ax / 50.0, (y - yb) / 11.0], -1)) ** 0.7
    # glabella: broad and gentle
    d += 1.2 * bump(np.stack([ax / 26.0, (y - 40.0) / 13.0], -1))
    # cheekbone prominence
    d += 3.5 * bump(np.stack([(ax - 42.0) / 21.0, (y + 11.0) / 19.0], -1))
    # nasolabial groove from the alar crease to beside the mouth corner
    dist, t = seg_dist(ax, y, (16.5, -22.0), (30.5, -57.0))
    w = np.sin(np.pi * (0.12 + 0.8 * t)) ** 0.7
    d -= 1.2 * w * np.exp(-(dist / 3.0) ** 2)
    # cheek fullness lateral of the groove and over the buccal hollow
    d += 1.5 * bump(np.stack([(ax - 31.0) / 12.0, (y + 36.0) / 14.0], -1))
    d += 2.0 * bump(np.stack([(ax - 42.0) / 17.0, (y + 34.0) / 17.0], -1))
    # mentolabial sulcus and chin
    d -= 1.6 * bump(np.stack([ax / 22.0, (y + 66.5) / 6.0], -1))
    d += 1.5 * bump(np.stack([ax / 16.0, (y + 84.0) / 12.0], -1))
    d += lip_disp(ax, y)
    return d


def face_loft(p):
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    W = _W(y)
    zf = _F(y)
    n = _N(y)
    zz = z - face_disp(x, y)
    F = np.maximum(zf - LOFT_C, 5.0)
    B = 60.0
    zr = zz - LOFT_C
    s = (np.abs(x) / W) ** n + (np.maximum(zr, 0) / F) ** n + (np.maximum(-zr, 0) / B) ** n
    f = (s ** (1.0 / n) - 1.0) * np.minimum(W, F) * 0.9
    f = np.where(np.isnan(f), 50.0, f)
    f = smax(f, -(y + 106.5), 2.5)
    f = smax(f, y - 72.0, 12.0)
    return f


def nose(p):
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    ys = [-18, -13, -6, 2, 10, 18, 24, 29, 34]
    zd = [103.0, 103.5, 100.6, 97.0, 93.5, 90.1, 87.9, 87.3, 85.0]
    bw = [13.0, 12.5, 11.8, 11.0, 10.3, 9.8, 9.6, 9.6, 10.0]
    dep = [21.0, 21.0, 21.0, 21.0, 20.0, 18.0, 16.0, 14.0, 11.0]
    rh = [4.5, 4.2, 3.2, 2.6, 2.4, 2.6, 3.0, 3.4, 4.0]
    pw = 1.45
    z_d = np.interp(y, ys, zd)
    b = np.interp(y, ys, bw)
    dp = np.interp(y, ys, dep)
    rho = np.interp(y, ys, rh)
    r = np.sqrt(x * x + rho * rho)
    prof = dp * (r ** pw - rho ** pw) / b ** pw
    slope = dp * pw * r ** (pw - 1) / b ** pw * np.abs(x) / r
    g = (z - z_d + prof) / np.sqrt(1 + slope * slope)
    sl = 0.30
    y_under = -26.5 + sl * (z - 91.5)
    g2 = (y_under - y) / np.sqrt(1 + sl ** 2)
    body = smax(g, g2, 2.5)
    # lower nose mass (lobule + alae), a flattened rounded block
    q = mirror_x(p)
    base = ellipsoid(p, (0.0, -19.0, 93.0), (17.0, 8.0, 11.5))
    base = smax(base, g2, 2.0)
    body = smin(body, base, 4.0)
    tip = ellipsoid(p, (0.0, -14.2, 101.5), (7.6, 7.0, 6.5))
    body = smin(body, tip, 4.0)
    # alar groove separating the ala from the lobule
    groove = capsule(q, (10.8, -12.0, 98.5), (14.8, -17.0, 96.0), 1.8)
    groove = smin(groove, capsule(q, (14.8, -17.0, 96.0), (16.5, -24.0, 91.0), 1.6), 1.5)
    body = ssub(body, groove, 2.2)
    body = smax(body, 66.0 - z, 3.0)
    body = smax(body, y - 33.0, 5.0)
    nostril = ellipsoid(q, (5.5, -23.6, 95.6), (2.8, 2.4, 5.4), rot_matrix(yaw=24))
    body = ssub(body, nostril, 1.2)
    return body


def cranium(p):
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    q = mirror_x(p)
    taper = 1.0 - 0.13 * np.clip((z - 0.0) / 90.0, 0, 1.2)
    cx, cy, cz = 0.0, 47.0, -4.0
    ax_ = 76.0
    ay = np.where(y > cy, 81.0, 66.0)
    az = np.where(z > cz, 92.0, 93.0)
    e = 2.2
    u = (np.abs(x / taper) / ax_) ** e + (np.abs(y - cy) / ay) ** e + (np.abs(z - cz) / az) ** e
    cran = (u ** (1.0 / e) - 1.0) * 72.0
    occ = ellipsoid(p, (0.0, 32.0, -58.0), (50.0, 42.0, 40.0))
    cran = smin(cran, occ, 10.0)
    fore = ellipsoid(p, (0.0, 62.0, 40.0), (55.0, 42.0, 50.0))
    cran = smin(cran, fore, 10.0)
    zcut = np.interp(y, [0.0, 20.0, 40.0, 60.0], [55.0, 62.0, 80.0, 110.0])
    cran = smax(cran, z - zcut, 8.0)
    # keep the skull base high at the back: the neck fills below
    cran = smax(cran, -(y + 18.0) - 0.25 * np.maximum(z, 0), 10.0)
    return cran


def neck(p):
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    cz = -10.0 + 0.12 * (y + 100.0)
    rx = np.interp(y, [-185, -160, -130, -100, -60], [70.0, 61.0, 57.0, 56.0, 57.0])
    rzf = np.interp(y, [-185, -140, -100], [54.0, 54.0, 52.0])
    rzb = np.interp(y, [-185, -160, -130, -100, -60, -20], [68.0, 62.0, 59.0, 61.0, 66.0, 70.0])
    rz = np.where(z > cz, rzf, rzb)
    u = np.sqrt((x / rx) ** 2 + ((z - cz) / rz) ** 2)
    d = (u - 1.0) * np.minimum(rx, rz)
    d = smax(d, y + 20.0, 10.0)
    # larynx prominence
    lar = ellipsoid(p, (0.0, -128.0, cz_at(-128.0) + 50.0), (9.0, 14.0, 6.0))
    d = smin(d, lar, 6.0)
    q = mirror_x(p)
    scm = capsule(q, (50.0, -45.0, -22.0), (14.0, -192.0, 40.0), 9.0)
    d = smin(d, scm, 12.0)
    return d


def cz_at(y):
    return -10.0 + 0.12 * (y + 100.0)


def lid_crease(q):
    """thin tube along the upper-lid (supratarsal) fold, ~6.5 mm above the margin"""
    t = np.linspace(0.08, 0.92, 9)
    en, ex = np.array([16.35, 10.5]), np.array([44.4, 12.5])
    x = en[0] + (ex[0] - en[0]) * t
    yb = en[1] + (ex[1] - en[1]) * t + 5.9 * np.sin(np.pi * t ** 0.94) ** 0.95
    y = yb + 5.2 * np.sin(np.pi * t) ** 0.5
    r = EYE_R + 2.6
    dx, dy = x - EYE_C[0], y - EYE_C[1]
    z = EYE_C[2] + np.sqrt(np.maximum(r * r - dx * dx - dy * dy, 4.0))
    pts = np.stack([x, y, z], 1)
    rad = 0.55 + 0.5 * np.sin(np.pi * t)
    return polyline_tube(q, pts, rad)


def head(p):
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    q = mirror_x(p)
    cr = cranium(p)
    nk = neck(p)
    d = smin(cr, nk, 30.0)
    kf = np.interp(y, [-110, -80, -40, 0], [5.0, 6.0, 10.0, 10.0])
    d = smin(d, face_loft(p), kf)
    # temples: slight hollow behind the lateral orbital rim
    temple = ellipsoid(q, (73.0, 30.0, 45.0), (9.0, 17.0, 18.0))
    d = ssub(d, temple, 8.0)
    # globe + lids
    lid = sphere(q, EYE_C, EYE_R + 1.2)
    d = smin(d, lid, 5.0)
    d = ssub(d, lid_crease(q), 1.2)
    kn = np.interp(y, [10.0, 30.0], [3.0, 5.0])
    d = smin(d, nose(p), kn)
    d = smax(d, -(y + 185.0), 0.5)
    return d
