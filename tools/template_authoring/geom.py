"""Surface queries on the SDF head (authoring)."""
from __future__ import annotations

import numpy as np

import headsdf as H
import sdflib as S

F = H.head
CENTER = np.array([0.0, 20.0, 5.0])  # chart centre (star-shaped head w.r.t. this point)


def ray_hit(origin, direction, t_max=260.0, step=0.5, f=None):
    """First surface crossing of f along origin + t*dir, t in (0, t_max] (scalar)."""
    f = f or F
    o = np.asarray(origin, float)
    d = np.asarray(direction, float)
    d = d / np.linalg.norm(d)
    ts = np.arange(0.0, t_max, step)
    vals = f(o + ts[:, None] * d)
    inside = vals < 0
    idx = np.nonzero(inside[:-1] != inside[1:])[0]
    if len(idx) == 0:
        return None
    i = idx[0]
    lo, hi = ts[i], ts[i + 1]
    lo_in = inside[i]
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        if (f(o + mid * d) < 0) == lo_in:
            lo = mid
        else:
            hi = mid
    return o + 0.5 * (lo + hi) * d


def zray(x, y, z0=140.0):
    """Surface point hit by a ray travelling in -z at (x, y)."""
    p = ray_hit((x, y, z0), (0, 0, -1), t_max=250)
    return p


def xray(y, z, x0=0.0):
    """Surface point reached travelling in +x from (x0, y, z) (first exit)."""
    return ray_hit((x0, y, z), (1, 0, 0), t_max=150)


def yray_down(x, z, y0=0.0):
    return ray_hit((x, y0, z), (0, -1, 0), t_max=200)


def center_ray(direction):
    return ray_hit(CENTER, direction, t_max=320)


def project(p, f=None):
    return S.project(f or F, np.atleast_2d(np.asarray(p, float)), iters=30)


def normal(p, f=None):
    g = S.grad(f or F, np.atleast_2d(np.asarray(p, float)))
    return g / np.linalg.norm(g, axis=-1, keepdims=True)


def midline_profile(n=4000):
    """Sagittal outline (x = 0) as points ordered by angle around CENTER (front = angle 0, up positive)."""
    ang = np.linspace(-np.pi * 0.62, np.pi * 1.45, n)
    pts = []
    for a in ang:
        d = np.array([0.0, np.sin(a), np.cos(a)])
        p = center_ray(d)
        pts.append(p if p is not None else [np.nan] * 3)
    pts = np.array(pts)
    return ang, pts


def arc_point(pts, i0, length):
    """Point at arc length `length` (mm, signed along index order) from pts[i0]."""
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    target = cum[i0] + length
    j = int(np.clip(np.searchsorted(cum, target), 1, len(pts) - 1))
    t = (target - cum[j - 1]) / max(seg[j - 1], 1e-9)
    return pts[j - 1] + t * (pts[j] - pts[j - 1]), j


def chart(p):
    """Stereographic chart of the direction from CENTER (half x >= 0 -> unit disk)."""
    d = np.asarray(p, float) - CENTER
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    return np.stack([d[..., 2], d[..., 1]], -1) / (1.0 + d[..., 0:1])


def rays_hit(origins, dirs, t_max=260.0, step=0.6, f=None, last=False):
    """Vectorised first (or last) inside->outside crossing along each ray. Returns (n,3), NaN if none."""
    f = f or F
    o = np.atleast_2d(np.asarray(origins, float))
    d = np.atleast_2d(np.asarray(dirs, float))
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    n = max(len(o), len(d))
    o = np.broadcast_to(o, (n, 3))
    ts = np.arange(0.0, t_max, step)
    out = np.full(n, np.nan)
    chunk = max(1, 400000 // len(ts))
    for s in range(0, n, chunk):
        oo = o[s:s + chunk]
        dd = d[s:s + chunk]
        P = oo[:, None, :] + ts[None, :, None] * dd[:, None, :]
        v = f(P)
        inside = v < 0
        cross = inside[:, :-1] & ~inside[:, 1:]
        has = cross.any(1)
        if last:
            k = cross.shape[1] - 1 - np.argmax(cross[:, ::-1], axis=1)
        else:
            k = np.argmax(cross, axis=1)
        lo = ts[k]
        hi = ts[np.minimum(k + 1, len(ts) - 1)]
        for _ in range(30):
            mid = 0.5 * (lo + hi)
            ins = f(oo + mid[:, None] * dd) < 0
            lo = np.where(ins, mid, lo)
            hi = np.where(ins, hi, mid)
        out[s:s + chunk] = np.where(has, 0.5 * (lo + hi), np.nan)
    return o + out[:, None] * d


def midline_profile_fast(n=3000):
    ang = np.linspace(-np.pi * 0.62, np.pi * 1.45, n)
    dirs = np.stack([np.zeros(n), np.sin(ang), np.cos(ang)], 1)
    pts = rays_hit(CENTER, dirs, t_max=320)
    pts[:, 0] = 0.0
    return ang, pts
