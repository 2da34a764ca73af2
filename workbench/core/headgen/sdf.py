"""Signed-distance modelling: primitives, smooth booleans, grid evaluation, meshing.

Units and frame
---------------
Millimetres, in the frame the caller builds in (the head frame for the
reference head: x to the subject's left, y up, z forward).  Distances are
negative inside a solid.  Most primitives return a *pseudo*-distance (exact
on the surface, within a few per cent near it), which is all that marching
cubes and the polynomial smooth blends need.

Evaluation
----------
A :class:`Grid` holds a float32 field sampled at the nodes ``origin + h·ijk``
(axis order x, y, z).  Every boolean is applied only inside the primitive's
bounding box grown by the blend radius: outside that box the primitive is
farther than the blend radius, so the blended result equals the old value on
and near the surface.  With ``half=True`` only ``x >= 0`` is stored and the
field is mirrored at the end (:meth:`Grid.full`), which halves the work and
makes the model exactly symmetric about ``x = 0``; a primitive added with
``bilateral=True`` stands for itself and its mirror image.

Smooth booleans are the polynomial smooth minimum / maximum of Quilez
(https://iquilezles.org/articles/smin/): blend radius ``k`` mm, exact
``min`` / ``max`` where the two distances differ by more than ``k``.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy import ndimage
from scipy.interpolate import CubicSpline
from scipy.spatial import cKDTree

from workbench.core.isosurface import (
    _compact,
    decimate,
    face_component_labels,
    keep_largest_component,
    taubin_smooth,
)
from workbench.core.mesh import Mesh, validate
from workbench.core.threads import worker_count

BIG = np.float32(60.0)  # "far outside" value of an empty grid, mm


# ------------------------------------------------------------------ blends
def smin(a: np.ndarray, b: np.ndarray, k: float) -> np.ndarray:
    """Polynomial smooth minimum (union) with blend radius ``k`` mm."""
    if k <= 0:
        return np.minimum(a, b)
    h = np.clip(0.5 + 0.5 * (b - a) / k, 0.0, 1.0)
    return b + (a - b) * h - k * h * (1.0 - h)


def smax(a: np.ndarray, b: np.ndarray, k: float) -> np.ndarray:
    """Polynomial smooth maximum (intersection); ``smax(a, -b, k)`` subtracts b."""
    return -smin(-a, -b, k)


def _frame(rotation: np.ndarray | None) -> np.ndarray:
    return np.eye(3) if rotation is None else np.asarray(rotation, float)


def rotation_to(
    axis: np.ndarray, up: np.ndarray | tuple[float, float, float] = (0.0, 1.0, 0.0)
) -> np.ndarray:
    """Rows (e1, e2, e3) of an orthonormal frame with e3 along ``axis`` and e2 near ``up``."""
    e3 = np.asarray(axis, float) / np.linalg.norm(axis)
    e1 = np.cross(np.asarray(up, float), e3)
    e1 /= np.linalg.norm(e1)
    return np.stack([e1, np.cross(e3, e1), e3])


# ------------------------------------------------------------------ primitives
class Primitive:
    """A solid with a bounding box ``lo``, ``hi`` (mm) and a distance ``__call__(x, y, z)``.

    ``x, y, z`` are arrays that broadcast against each other (a grid block is
    passed as ``(nx,1,1)``, ``(1,ny,1)``, ``(1,1,nz)``).
    """

    lo: np.ndarray
    hi: np.ndarray

    def __call__(self, x, y, z) -> np.ndarray:  # pragma: no cover - interface
        raise NotImplementedError


class Function(Primitive):
    """Any distance function ``fn(x, y, z)`` with explicit bounds."""

    def __init__(self, fn: Callable, lo, hi):
        self.fn, self.lo, self.hi = fn, np.asarray(lo, float), np.asarray(hi, float)

    def __call__(self, x, y, z):
        return self.fn(x, y, z)


class Ellipsoid(Primitive):
    """Ellipsoid, semi-axes ``radii`` along the rows of ``rotation`` (default x, y, z).

    Distance: Quilez's bound ``k0 (k0 - 1) / k1`` (exact on the surface).
    """

    def __init__(self, centre, radii, rotation=None):
        self.c = np.asarray(centre, float)
        self.r = np.asarray(radii, float)
        self.R = _frame(rotation)
        ext = np.sqrt(((self.R * self.r[:, None]) ** 2).sum(axis=0))
        self.lo, self.hi = self.c - ext, self.c + ext

    def __call__(self, x, y, z):
        px, py, pz = x - self.c[0], y - self.c[1], z - self.c[2]
        q = [self.R[i, 0] * px + self.R[i, 1] * py + self.R[i, 2] * pz for i in range(3)]
        k0 = np.sqrt(sum((q[i] / self.r[i]) ** 2 for i in range(3)))
        k1 = np.sqrt(sum((q[i] / self.r[i] ** 2) ** 2 for i in range(3)))
        return k0 * (k0 - 1.0) / np.maximum(k1, 1e-9)


class SuperEllipsoid(Primitive):
    """Axis-aligned solid with superelliptic (exponent ``p``) x-y sections and elliptic z profile.

    ``((|x/a|^p + |y/b|^p)^(2/p) + (z/c)^2)^(1/2) = 1``; ``p = 2`` is an
    ellipsoid, larger ``p`` flattens the top and sides (a cranial vault seen
    from the front).  Distance: first-order ``(Q - 1) / |grad Q|``.
    """

    def __init__(self, centre, radii, p: float = 2.0):
        self.c, self.r, self.p = np.asarray(centre, float), np.asarray(radii, float), float(p)
        self.lo, self.hi = self.c - self.r, self.c + self.r

    def __call__(self, x, y, z):
        a, b, c = self.r
        A = np.abs(x - self.c[0]) / a + 1e-9
        B = np.abs(y - self.c[1]) / b + 1e-9
        C = np.abs(z - self.c[2]) / c
        q = (A**self.p + B**self.p) ** (1.0 / self.p)
        Q = np.sqrt(q * q + C * C)
        f = q ** (2.0 - self.p) / Q
        grad = np.sqrt(
            (f * A ** (self.p - 1.0) / a) ** 2
            + (f * B ** (self.p - 1.0) / b) ** 2
            + (C / (Q * c)) ** 2
        )
        return (Q - 1.0) / np.maximum(grad, 1e-9)


class RoundCone(Primitive):
    """Capsule from ``a`` (radius ``ra``) to ``b`` (radius ``rb``), radius linear in between."""

    def __init__(self, a, b, ra, rb=None):
        self.a, self.b = np.asarray(a, float), np.asarray(b, float)
        self.ra, self.rb = float(ra), float(ra if rb is None else rb)
        r = max(self.ra, self.rb)
        self.lo = np.minimum(self.a, self.b) - r
        self.hi = np.maximum(self.a, self.b) + r

    def __call__(self, x, y, z):
        ab = self.b - self.a
        px, py, pz = x - self.a[0], y - self.a[1], z - self.a[2]
        t = np.clip((px * ab[0] + py * ab[1] + pz * ab[2]) / (ab @ ab), 0.0, 1.0)
        d = np.sqrt((px - t * ab[0]) ** 2 + (py - t * ab[1]) ** 2 + (pz - t * ab[2]) ** 2)
        return d - (self.ra + (self.rb - self.ra) * t)


class Box(Primitive):
    """Box of half sizes ``half`` along the rows of ``rotation``, edges rounded by ``round_mm``."""

    def __init__(self, centre, half, rotation=None, round_mm=0.0):
        self.c, self.h = np.asarray(centre, float), np.asarray(half, float)
        self.R, self.rr = _frame(rotation), float(round_mm)
        ext = np.abs(self.R * self.h[:, None]).sum(axis=0) + self.rr
        self.lo, self.hi = self.c - ext, self.c + ext

    def __call__(self, x, y, z):
        px, py, pz = x - self.c[0], y - self.c[1], z - self.c[2]
        q = [
            np.abs(self.R[i, 0] * px + self.R[i, 1] * py + self.R[i, 2] * pz) - self.h[i]
            for i in range(3)
        ]
        out = np.sqrt(sum(np.maximum(qi, 0.0) ** 2 for qi in q))
        return out + np.minimum(np.maximum(np.maximum(q[0], q[1]), q[2]), 0.0) - self.rr


def resample(points, values=None, step: float = 0.5, closed: bool = False):
    """Cubic spline through control ``points`` (k, 3), resampled every ~``step`` mm.

    ``values`` (k, m) are interpolated with the same parameter (chord length).
    Returns ``(samples (n, 3), tangents (n, 3), values (n, m) or None)``.
    """
    p = np.asarray(points, float)
    vals = None if values is None else np.asarray(values, float).reshape(len(p), -1)
    if closed:
        p = np.vstack([p, p[:1]])
        vals = None if vals is None else np.vstack([vals, vals[:1]])
    t = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
    bc = "periodic" if closed else "not-a-knot"
    if len(p) < 4 and not closed:
        bc = "natural"
    spline = CubicSpline(t, p, bc_type=bc)
    n = max(int(np.ceil(t[-1] / step)), 2)
    s = np.linspace(0.0, t[-1], n, endpoint=not closed)
    tang = spline(s, 1)
    tang /= np.linalg.norm(tang, axis=1, keepdims=True)
    out = None
    if vals is not None:
        out = (
            CubicSpline(t, vals, bc_type=bc)(s)
            if len(p) >= 4 or closed
            else np.stack([np.interp(s, t, vals[:, j]) for j in range(vals.shape[1])], axis=1)
        )
    return spline(s), tang, out


def superellipse_distance(u, v, a, b, p: float = 2.0):
    """Approximate signed distance to ``|u/a|^p + |v/b|^p = 1`` (exact on the curve)."""
    if p == 2.0:
        k0 = np.sqrt((u / a) ** 2 + (v / b) ** 2)
        k1 = np.sqrt((u / a**2) ** 2 + (v / b**2) ** 2)
        return k0 * (k0 - 1.0) / np.maximum(k1, 1e-9)
    um, vm = np.abs(u / a) + 1e-9, np.abs(v / b) + 1e-9
    q = (um**p + vm**p) ** (1.0 / p)
    grad = q ** (1.0 - p) * np.hypot(um ** (p - 1.0) / a, vm ** (p - 1.0) / b)
    return (q - 1.0) / np.maximum(grad, 1e-6)


class Sweep(Primitive):
    """Elliptic cross-section swept along a curve (dense samples from :func:`resample`).

    Parameters
    ----------
    samples, tangents : (n, 3)
        Curve points (about 0.5 mm apart) and unit tangents.
    radii : (n, 2)
        Semi-axes of the section: ``a`` along ``side = tangent x up``, ``b``
        along ``tangent x side`` (roughly ``up``).
    up : (3,) or (n, 3)
        Reference "up" direction of the section.
    closed : bool
        Closed loop (no end caps); open curves end in flat caps (taper the
        radii for rounded ends).
    exponent : float
        Section shape: 2 = ellipse, larger = rounded rectangle (superellipse).
    """

    def __init__(
        self, samples, tangents, radii, up=(0.0, 1.0, 0.0), closed=False, exponent: float = 2.0
    ):
        self.p = float(exponent)
        self.c, self.t = np.asarray(samples, float), np.asarray(tangents, float)
        self.r = np.maximum(np.asarray(radii, float).reshape(-1, 2), 0.05)
        up = np.broadcast_to(np.asarray(up, float), self.c.shape)
        side = np.cross(self.t, up)
        self.n = side / np.linalg.norm(side, axis=1, keepdims=True)
        self.b = np.cross(self.t, self.n)
        self.closed = closed
        self.tree = cKDTree(self.c)
        rmax = float(self.r.max())
        self.lo, self.hi = self.c.min(axis=0) - rmax, self.c.max(axis=0) + rmax

    def __call__(self, x, y, z):
        shape = np.broadcast_shapes(np.shape(x), np.shape(y), np.shape(z))
        p = np.stack(
            [
                np.broadcast_to(x, shape).ravel(),
                np.broadcast_to(y, shape).ravel(),
                np.broadcast_to(z, shape).ravel(),
            ],
            axis=1,
        )
        _, k = self.tree.query(p, workers=worker_count())
        d = p - self.c[k]
        u = np.einsum("ij,ij->i", d, self.n[k])
        v = np.einsum("ij,ij->i", d, self.b[k])
        a, b = self.r[k, 0], self.r[k, 1]
        dist = superellipse_distance(u, v, a, b, self.p)
        if not self.closed:
            s = np.einsum("ij,ij->i", d, self.t[k])
            end = np.where(k == 0, -s, np.where(k == len(self.c) - 1, s, -1e9))
            out = np.sqrt(np.maximum(dist, 0) ** 2 + np.maximum(end, 0) ** 2)
            dist = np.minimum(np.maximum(dist, end), 0.0) + out
        return dist.reshape(shape)


class Profile2D:
    """Signed distance to a closed 2-D polygon ``(k, 2)`` (mm), from a 0.2 mm raster.

    Negative inside.  Points outside the raster get the raster edge value plus
    their distance to the raster box (a bound, good enough far from the shape).
    """

    def __init__(self, polygon, pixel: float = 0.2, margin: float = 12.0):
        from skimage.draw import polygon as fill

        poly = np.asarray(polygon, float)
        self.lo = poly.min(axis=0) - margin
        self.px = pixel
        size = np.ceil((poly.max(axis=0) + margin - self.lo) / pixel).astype(int) + 1
        ij = (poly - self.lo) / pixel
        mask = np.zeros(size, bool)
        rr, cc = fill(ij[:, 0], ij[:, 1], shape=mask.shape)
        mask[rr, cc] = True
        outside = ndimage.distance_transform_edt(~mask)
        inside = ndimage.distance_transform_edt(mask)
        self.sdf = ((outside - inside) * pixel + np.where(mask, 0.5, -0.5) * pixel).astype(
            np.float32
        )
        self.size = size

    def __call__(self, u, v):
        iu, iv = (u - self.lo[0]) / self.px, (v - self.lo[1]) / self.px
        cu = np.clip(iu, 0, self.size[0] - 1)
        cv = np.clip(iv, 0, self.size[1] - 1)
        val = ndimage.map_coordinates(
            self.sdf, [cu.ravel(), cv.ravel()], order=1, mode="nearest"
        ).reshape(cu.shape)
        return val + np.hypot(iu - cu, iv - cv) * self.px


class Extrusion(Primitive):
    """A :class:`Profile2D` in the plane ``(e1, e2)`` through ``origin``, extruded along ``e3``.

    ``depth = (front, back)``: extent along ``+e3`` and ``-e3`` (mm).  The
    profile is scaled by ``taper`` (1 at ``+front`` -> ``taper`` at ``-back``);
    edges are rounded by ``round_mm``.
    """

    def __init__(self, profile: Profile2D, origin, rotation, depth, taper=1.0, round_mm=0.0):
        self.p, self.o, self.R = profile, np.asarray(origin, float), np.asarray(rotation, float)
        self.front, self.back = float(depth[0]), float(depth[1])
        self.taper, self.rr = float(taper), float(round_mm)
        corners = np.array(
            [
                [a, b]
                for a in (profile.lo[0], profile.lo[0] + profile.size[0] * profile.px)
                for b in (profile.lo[1], profile.lo[1] + profile.size[1] * profile.px)
            ]
        )
        pts = [
            self.o + c[0] * self.R[0] + c[1] * self.R[1] + w * self.R[2]
            for c in corners
            for w in (self.front, -self.back)
        ]
        self.lo, self.hi = np.min(pts, axis=0), np.max(pts, axis=0)

    def __call__(self, x, y, z):
        px, py, pz = x - self.o[0], y - self.o[1], z - self.o[2]
        u, v, w = (self.R[i, 0] * px + self.R[i, 1] * py + self.R[i, 2] * pz for i in range(3))
        u, v, w = np.broadcast_arrays(u, v, w)
        frac = np.clip((self.front - w) / max(self.front + self.back, 1e-9), 0.0, 1.0)
        s = 1.0 + (self.taper - 1.0) * frac
        d2 = self.p(u / s, v / s) * s
        dw = np.maximum(w - self.front, -self.back - w)
        out = np.sqrt(np.maximum(d2, 0) ** 2 + np.maximum(dw, 0) ** 2)
        return np.minimum(np.maximum(d2, dw), 0.0) + out - self.rr


# ------------------------------------------------------------------ grid
class Grid:
    """A float32 distance field on nodes ``origin + h * (i, j, k)``, x-y-z axis order.

    With ``half=True`` only ``x >= 0`` is stored (``lo[0]`` is ignored) and
    :meth:`full` returns the mirrored field.
    """

    def __init__(self, lo, hi, h: float, half: bool = False):
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        if half:
            lo = np.array([0.0, lo[1], lo[2]])
        self.h, self.half = float(h), half
        self.origin = np.floor(lo / h) * h
        self.shape = tuple(int(n) for n in np.ceil((hi - self.origin) / h).astype(int) + 1)
        self.field = np.full(self.shape, BIG, np.float32)

    def _block(self, lo, hi):
        i0 = np.clip(np.floor((np.asarray(lo) - self.origin) / self.h).astype(int), 0, self.shape)
        i1 = np.clip(
            np.ceil((np.asarray(hi) - self.origin) / self.h).astype(int) + 1, 0, self.shape
        )
        if np.any(i1 <= i0):
            return None
        sl = tuple(slice(a, b) for a, b in zip(i0, i1, strict=False))
        ax = [
            (self.origin[d] + self.h * np.arange(i0[d], i1[d])).astype(np.float32) for d in range(3)
        ]
        return sl, ax[0][:, None, None], ax[1][None, :, None], ax[2][None, None, :]

    def _apply(self, prim: Primitive, k: float, bilateral: bool, combine, everywhere=False):
        lo, hi = prim.lo - k - self.h, prim.hi + k + self.h
        if bilateral:
            lo = np.minimum(lo, [-hi[0], lo[1], lo[2]])
            hi = np.maximum(hi, [-prim.lo[0] + k + self.h, hi[1], hi[2]])
        if everywhere:
            lo, hi = self.origin, self.origin + self.h * np.array(self.shape)
        block = self._block(lo, hi)
        if block is None:
            return
        sl, x, y, z = block
        d = prim(x, y, z)
        if bilateral:
            d = np.minimum(d, prim(-x, y, z))
        d = np.broadcast_to(d, self.field[sl].shape)
        self.field[sl] = combine(self.field[sl], d.astype(np.float32), k)

    def union(self, prim: Primitive, k: float = 0.0, bilateral: bool = False) -> Grid:
        self._apply(prim, k, bilateral, smin)
        return self

    def subtract(self, prim: Primitive, k: float = 0.0, bilateral: bool = False) -> Grid:
        self._apply(prim, k, bilateral, lambda a, d, kk: smax(a, -d, kk))
        return self

    def intersect(self, prim: Primitive, k: float = 0.0, bilateral: bool = False) -> Grid:
        self._apply(prim, k, bilateral, smax, everywhere=True)
        return self

    def full(self) -> tuple[np.ndarray, np.ndarray]:
        """``(field, origin)``: the whole (mirrored, if half) field and its origin (mm)."""
        if not self.half:
            return self.field, self.origin
        f = np.concatenate([self.field[:0:-1], self.field], axis=0)
        origin = self.origin - np.array([self.h * (self.shape[0] - 1), 0.0, 0.0])
        return f, origin

    def sample(self, points) -> np.ndarray:
        """Trilinear field value at ``points`` (k, 3) mm (mirrored for ``x < 0`` if half)."""
        p = np.asarray(points, float).reshape(-1, 3).copy()
        if self.half:
            p[:, 0] = np.abs(p[:, 0])
        idx = ((p - self.origin) / self.h).T
        return ndimage.map_coordinates(self.field, idx, order=1, mode="nearest")


# ------------------------------------------------------------------ meshing
def _closed_manifold(v: np.ndarray, faces: np.ndarray) -> bool:
    r = validate(Mesh(v, faces))
    return r.is_watertight and r.is_clean and r.inconsistent_orientation_edges == 0


def _decimate_closed(v: np.ndarray, faces: np.ndarray, target: int):
    """Quadric decimation that keeps a closed manifold (retries a few nearby targets)."""
    for factor in (1.0, 1.04, 0.97, 1.09, 0.93, 1.15, 1.25, 1.4):
        dv, df = decimate(v, faces, int(target * factor))
        if _closed_manifold(dv, df):
            return dv, df
    return v, faces  # give up decimating rather than return a broken surface


def _decimate_pieces(v: np.ndarray, faces: np.ndarray, target: int):
    labels = face_component_labels(faces, len(v))
    parts_v, parts_f, offset = [], [], 0
    for lab in range(int(labels.max()) + 1):
        pv, pf = _compact(v, faces[labels == lab])
        pv, pf = _decimate_closed(pv, pf, max(int(target * len(pf) / len(faces)), 40))
        parts_v.append(pv)
        parts_f.append(pf + offset)
        offset += len(pv)
    return np.concatenate(parts_v), np.concatenate(parts_f)


def mesh_from_field(
    field: np.ndarray,
    origin,
    h: float,
    *,
    smooth: int = 6,
    target: int | None = None,
    keep_all: bool = False,
    blur: float = 0.0,
) -> Mesh:
    """Zero level set of ``field`` (negative inside) as a closed, outward mesh in mm.

    Marching cubes (scikit-image, Lewiner) -> largest component -> Taubin
    smoothing (``smooth`` iterations) -> quadric decimation to about
    ``target`` triangles -> largest component (``keep_all``: every component
    but specks, for sets of separate solids such as teeth).  ``blur`` (voxels)
    low-pass filters the field first: near-cusps where blended solids meet
    would otherwise let the decimation pinch two sheets together.  The field must be positive
    on its outer faces so that the surface closes.
    """
    from skimage.measure import marching_cubes

    f = np.asarray(field, np.float32)
    if blur > 0:  # soften creases where smooth booleans meet at sharp angles (voxels)
        f = ndimage.gaussian_filter(f, blur, mode="nearest")
    edge = np.concatenate([f[[0, -1]].ravel(), f[:, [0, -1]].ravel(), f[:, :, [0, -1]].ravel()])
    if edge.min() <= 0:
        raise ValueError("the solid touches the border of its grid; enlarge the grid")
    v, faces, _, _ = marching_cubes(-f, 0.0, spacing=(h, h, h), allow_degenerate=False)
    v = v.astype(np.float64) + np.asarray(origin, float)
    faces = faces.astype(np.int64)
    if keep_all:  # drop specks (pieces under 2 % of the largest)
        labels = face_component_labels(faces, len(v))
        sizes = np.bincount(labels)
        v, faces = _compact(v, faces[sizes[labels] >= 0.02 * sizes.max()])
    else:
        v, faces, _ = keep_largest_component(v, faces)
    if smooth:
        v = taubin_smooth(v, faces, smooth)
    if target is not None and target < len(faces):
        if keep_all:  # decimate each piece on its own so that pieces never fuse
            v, faces = _decimate_pieces(v, faces, target)
        else:
            v, faces = _decimate_closed(v, faces, target)
            v, faces, _ = keep_largest_component(v, faces)
    mesh = Mesh(v, faces)
    if mesh.volume < 0:
        mesh = Mesh(v, faces[:, ::-1])
    return mesh
