"""Tiny vectorised SDF toolkit (numpy) for authoring the head shape."""
from __future__ import annotations

import numpy as np


def length(v):
    return np.sqrt(np.einsum("...i,...i->...", v, v))


def sphere(p, c, r):
    return length(p - np.asarray(c, float)) - r


def rot_matrix(yaw=0.0, pitch=0.0, roll=0.0):
    """degrees. yaw about y, pitch about x, roll about z.  returns R (world<-local)."""
    a, b, c = np.radians([yaw, pitch, roll])
    ry = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    rx = np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])
    rz = np.array([[np.cos(c), -np.sin(c), 0], [np.sin(c), np.cos(c), 0], [0, 0, 1]])
    return ry @ rx @ rz


def to_local(p, c, rot=None):
    q = p - np.asarray(c, float)
    if rot is not None:
        q = q @ np.asarray(rot)  # local = R^T q  ->  q @ R
    return q


def ellipsoid(p, c, r, rot=None):
    """IQ's bound approximation of the ellipsoid distance."""
    q = to_local(p, c, rot)
    r = np.asarray(r, float)
    k0 = length(q / r)
    k1 = length(q / (r * r))
    with np.errstate(invalid="ignore", divide="ignore"):
        d = k0 * (k0 - 1.0) / np.maximum(k1, 1e-12)
    return d


def superellipsoid(p, c, r, e=2.5, rot=None):
    q = np.abs(to_local(p, c, rot)) / np.asarray(r, float)
    k = (q ** e).sum(-1) ** (1.0 / e)
    return (k - 1.0) * np.min(r)


def capsule(p, a, b, r):
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    pa = p - a
    ba = b - a
    h = np.clip(np.einsum("...i,i->...", pa, ba) / ba.dot(ba), 0.0, 1.0)
    return length(pa - h[..., None] * ba) - r


def round_cone(p, a, b, r1, r2):
    """capsule with radius varying linearly from r1 (at a) to r2 (at b) (approximate)."""
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    pa = p - a
    ba = b - a
    h = np.clip(np.einsum("...i,i->...", pa, ba) / ba.dot(ba), 0.0, 1.0)
    return length(pa - h[..., None] * ba) - (r1 + (r2 - r1) * h)


def polyline_tube(p, pts, radii):
    """union of round cones along a polyline."""
    d = None
    for i in range(len(pts) - 1):
        di = round_cone(p, pts[i], pts[i + 1], radii[i], radii[i + 1])
        d = di if d is None else np.minimum(d, di)
    return d


def smin(a, b, k):
    if np.isscalar(k) and k <= 0:
        return np.minimum(a, b)
    h = np.clip(0.5 + 0.5 * (b - a) / k, 0.0, 1.0)
    return b + (a - b) * h - k * h * (1.0 - h)


def smax(a, b, k):
    return -smin(-a, -b, k)


def ssub(a, b, k):
    """a minus b (smooth)."""
    return smax(a, -b, k)


def mirror_x(p):
    q = p.copy()
    q[..., 0] = np.abs(q[..., 0])
    return q


def grad(f, p, h=0.05):
    g = np.zeros_like(p)
    for i in range(3):
        e = np.zeros(3)
        e[i] = h
        g[..., i] = (f(p + e) - f(p - e)) / (2 * h)
    return g


def project(f, p, iters=12, tol=1e-4):
    """closest-point style projection onto f = 0 (Newton steps along the gradient)."""
    p = np.array(p, float)
    for _ in range(iters):
        d = f(p)
        g = grad(f, p)
        gn2 = np.maximum((g * g).sum(-1), 1e-8)
        step = (d / gn2)[..., None] * g
        p = p - np.clip(step, -5, 5)
        if np.abs(d).max() < tol:
            break
    return p


def raycast(f, origin, dirs, t0=5.0, t1=400.0, steps=400):
    """first exit of the ray origin + t*dir from the inside (f<0) region. dirs (n,3) unit."""
    origin = np.asarray(origin, float)
    ts = np.linspace(t0, t1, steps)
    n = len(dirs)
    tout = np.full(n, np.nan)
    prev_in = None
    prev_t = None
    for t in ts:
        pts = origin + dirs * t
        d = f(pts)
        inside = d < 0
        if prev_in is not None:
            crossing = prev_in & ~inside & np.isnan(tout)
            if crossing.any():
                tout[crossing] = t
        prev_in = inside
        prev_t = t
    # refine by bisection between t - dt and t
    dt = ts[1] - ts[0]
    lo = tout - dt
    hi = tout.copy()
    ok = ~np.isnan(tout)
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        d = f(origin + dirs * mid[:, None])
        inside = d < 0
        lo = np.where(inside & ok, mid, lo)
        hi = np.where(~inside & ok, mid, hi)
    return np.where(ok, 0.5 * (lo + hi), np.nan)
