"""Linear and sphincter muscles as fibre polygons driving skin nodes (Kähler 2003, ch. 7).

Units and frame: millimetres in the head frame (x to the subject's left,
x = 0 midsagittal, y up, z toward the face, Frankfort Horizontal at y = 0).

A muscle arrives as its grid rows evaluated below the skin
(:class:`MuscleSpec`).  Rows of unequal length are resampled by arc length
to the longest row (K 7.4.2).  Then

* a **linear** muscle's fibres are the grid *columns*: one polygon per
  column from row 0 (the fixed, bone end) to the last row (the free end),
  one segment per cell (K 7.4.4);
* a **sphincter**'s fibres are its *rows* (open rings, outermost first;
  digest §9.2: no facial muscle is a closed ring).

Contraction ``c ∈ [0, 1]`` per muscle (K 7.3.1):

* linear: each control point slides *along the original polygon* to the arc
  parameter ``t̃_i = max((1 − c) t_i, 0.01)``, the fixed end staying put.
  ⚠ Two typos of the source are fixed: the interpolation uses index
  ``k_i + 1`` (the source prints ``p_{k_{i+1}}``), and the clamp is not
  applied to ``i = 0`` (literally it would move the fixed end to t = 0.01);
* sphincter: ``q_i = p*_i + (1 − c)(p_i − p*_i)``.  ⚠ The source's centre
  ``p* = (1 − a) a_0 + a a_1`` lies between two axis points that are both
  below the skin, so it can only pull lips in; MEDUSA describes the two
  parameters as contraction "shrinking orthogonal to the axis" and
  protrusion "movement along the axis in either direction".  We take that
  reading: the centre is each point's projection ``p⊥`` on the axis
  (the source's outer-fibre rule), and protrusion ``a ∈ [−1, 1]`` shifts it
  by ``a · |a_1 − a_0|`` outward along the axis, graded across the fibres as
  in the source (0 on the outermost fibre, full on the innermost).

Bulging (K 7.3.4): ``b = 1 + ν (1 − L_q / L_p)`` with ν = 5, where the
length ratio is ``1 − c`` for both kinds.  ⚠ The source's ``b`` turns
negative beyond 120 % length and its "125 % → thinning by 1/4" does not
follow from the formula; we clamp ``b`` to [0.1, 3].  The thickening moves
the skin above the muscle outward by ``(b − 1) ×`` half the muscle height
(2 mm: the grids lie 4 mm = τs + (τm_min + τm_max)/4 below the skin).  On
a linear muscle the bulge follows the source's quadratic profile, zero at
both ends and one in the middle, here evaluated continuously as
``4 t (1 − t)`` because the reference muscles have only one or two
segments (the source's discrete profile needs three).

Jaw (K 7.3.1): jaw-attached muscles are contracted in the rest pose and then
moved rigidly with the jaw (rotation commutes with sliding along the
polygon).

Skin attachment (K 7.4.6): each muscle sheet is sampled bilinearly; a skin
node within the radius of influence of a sample is attached with weight
``φ`` (1 up to ``inner_mm``, cosine falloff to 0 at ``outer_mm``; the source
gives no radius).  Kähler's closed-lip fix weights the distance by
``n_s · n_d`` (skin normal · direction from the sheet to the node); ⚠ the
source does not say multiply or divide; we *divide* (clamped at 0.5) so a
sheet directly below the node (``n_s · n_d ≈ 1``) is preferred.  All of this
is folded into two constant sparse matrices, so a muscle update is a few
vectorised operations on the 24 muscles' control points and two sparse
products (well under a spring step).

Interweaving: where sheets overlap their displacements add, which stands in
for Kähler's constraint groups and inter-muscle spring mesh (K 7.2.3,
7.3.2), not implemented here.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

BULGE_NU = 5.0
BULGE_RANGE = (0.1, 3.0)
HALF_HEIGHT_MM = 2.0
MIN_ARC = 0.01


@dataclass(frozen=True)
class MuscleSpec:
    """One muscle as evaluated grid rows (mm, head frame).

    ``rows`` run from the fixed end to the free end (linear) or from the
    outer to the inner ring (sphincter); ``axis`` is the sphincter's two axis
    points (outer first), ``attachment`` "skull" or "jaw".
    """

    code: str
    kind: str
    attachment: str
    rows: tuple[np.ndarray, ...]
    axis: np.ndarray | None = None


def _resample(row: np.ndarray, n: int) -> np.ndarray:
    """``n`` points evenly spaced by arc length along the polyline ``row``."""
    row = np.asarray(row, float).reshape(-1, 3)
    if len(row) == n:
        return row.copy()
    seg = np.linalg.norm(np.diff(row, axis=0), axis=1)
    s = np.r_[0.0, np.cumsum(seg)]
    if s[-1] <= 0:
        return np.repeat(row[:1], n, axis=0)
    u = np.linspace(0.0, s[-1], n)
    return np.stack([np.interp(u, s, row[:, k]) for k in range(3)], axis=1)


def _arc_params(poly: np.ndarray) -> np.ndarray:
    seg = np.linalg.norm(np.diff(poly, axis=0), axis=1)
    s = np.r_[0.0, np.cumsum(seg)]
    return s / s[-1] if s[-1] > 0 else np.linspace(0.0, 1.0, len(poly))


def _sheet_grids(specs: Sequence[MuscleSpec]) -> tuple[list[np.ndarray], list[int]]:
    """Each muscle's rows resampled to its longest row: ``(rows, cols, 3)`` grids (mm).

    Also returns the index of each grid's first control point in the
    concatenation of all grids (row-major).
    """
    grids: list[np.ndarray] = []
    base = 0
    bases = []
    for s in specs:
        width = max(len(r) for r in s.rows)
        g = np.stack([_resample(r, width) for r in s.rows])
        grids.append(g)
        bases.append(base)
        base += g.shape[0] * g.shape[1]
    return grids, bases


def _sheet_samples(
    g: np.ndarray, base: int, linear: bool, bw: np.ndarray, uu: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Bilinear samples of one muscle sheet ``g`` (mm), cell by cell.

    ``bw`` are the bilinear weights of the samples in a cell (corner order
    (r, c), (r, c+1), (r+1, c), (r+1, c+1)) and ``uu`` their parameter across
    the rows.  Returns the sample positions, their four corner control-point
    ids (``base`` added), the weights and the bulge profile (``4 t (1 - t)``
    along a linear muscle, 1 on a sphincter).
    """
    rows, cols = g.shape[:2]
    pos, cps, prof = [], [], []
    for r in range(rows - 1):
        for c in range(max(cols - 1, 1)):
            c1 = min(c + 1, cols - 1)
            corner = np.array(
                [r * cols + c, r * cols + c1, (r + 1) * cols + c, (r + 1) * cols + c1]
            )
            pos.append(bw @ g.reshape(-1, 3)[corner])
            cps.append(np.broadcast_to(base + corner, bw.shape))
            t = (r + uu) / (rows - 1)
            prof.append(4.0 * t * (1.0 - t) if linear else np.ones_like(t))
    return (
        np.concatenate(pos),
        np.concatenate(cps),
        np.tile(bw, (len(pos), 1)),
        np.concatenate(prof),
    )


def _sheet_influence(
    samples: np.ndarray,
    x: np.ndarray,
    nrm: np.ndarray,
    allowed: np.ndarray | None,
    inner_mm: float,
    outer_mm: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Skin nodes a sheet's samples reach, their nearest sample and weight ``φ``.

    ``φ`` is 1 up to ``inner_mm`` and falls off as a squared cosine to 0 at
    ``outer_mm`` (mm), the distance divided by ``n_s · n_d`` (clamped at 0.5)
    so a sheet directly below a node is preferred; ``allowed`` (optional
    ``(n,)`` bool) limits the nodes.  Weights below 1e-3 are dropped.
    """
    dist, near = cKDTree(samples).query(x, k=1, distance_upper_bound=outer_mm)
    ok = np.isfinite(dist)
    if allowed is not None:
        ok &= allowed
    vid = np.nonzero(ok)[0]
    near = near[vid]
    nd = x[vid] - samples[near]
    nd /= np.maximum(np.linalg.norm(nd, axis=1, keepdims=True), 1e-12)
    cos = np.clip(np.einsum("ij,ij->i", nrm[vid], nd), 0.5, 1.0)
    d_eff = dist[vid] / cos
    phi = np.where(
        d_eff <= inner_mm,
        1.0,
        np.cos(0.5 * np.pi * np.clip((d_eff - inner_mm) / (outer_mm - inner_mm), 0, 1)) ** 2,
    )
    keep = phi > 1e-3
    return vid[keep], near[keep], phi[keep]


class MuscleRig:
    """The muscles of a head and their linear map to skin-node targets.

    Parameters
    ----------
    specs : the muscles
    skin_vertices, skin_normals : rest skin (mm) and unit vertex normals
    candidates : optional ``{code: (n,) bool}`` — skin nodes a muscle may attach to
    inner_mm, outer_mm : radius of influence (distance from the sheet)
    samples_per_cell : bilinear samples per cell side
    """

    def __init__(
        self,
        specs: Sequence[MuscleSpec],
        skin_vertices: np.ndarray,
        skin_normals: np.ndarray,
        *,
        candidates: Mapping[str, np.ndarray] | None = None,
        inner_mm: float = 5.0,
        outer_mm: float = 12.0,
        samples_per_cell: int = 7,
    ) -> None:
        self.codes = tuple(s.code for s in specs)
        self.index = {c: i for i, c in enumerate(self.codes)}
        self.kinds = tuple(s.kind for s in specs)
        self.on_jaw = np.array([s.attachment == "jaw" for s in specs], bool)
        x = np.asarray(skin_vertices, float)
        nrm = np.asarray(skin_normals, float)
        grids, bases = _sheet_grids(specs)
        self.grids = grids
        self.rest_points = (
            np.concatenate([g.reshape(-1, 3) for g in grids]) if grids else np.zeros((0, 3))
        )
        self.point_muscle = (
            np.concatenate(
                [np.full(g.shape[0] * g.shape[1], m) for m, g in enumerate(grids)]
            ).astype(np.int64)
            if grids
            else np.zeros(0, np.int64)
        )
        self._init_linear_fibres(specs, bases)
        self._init_sphincters(specs, bases)
        self._init_skin_attachment(
            specs, bases, x, nrm, candidates, inner_mm, outer_mm, samples_per_cell
        )

    def _init_linear_fibres(self, specs: Sequence[MuscleSpec], bases: list[int]) -> None:
        """Fibres of the linear muscles (grid columns, fixed end first), padded to one array.

        Per fibre: control-point ids ``_lf_idx`` (padded with the last id), arc
        parameters ``_lf_t`` in [0, 1], validity mask, segment count, muscle
        and rest points (mm).
        """
        fib_idx: list[np.ndarray] = []
        fib_mus: list[int] = []
        for m, (s, g) in enumerate(zip(specs, self.grids, strict=True)):
            if s.kind != "linear":
                continue
            rows, cols = g.shape[:2]
            for c in range(cols):
                fib_idx.append(bases[m] + np.arange(rows) * cols + c)
                fib_mus.append(m)
        width = max((len(f) for f in fib_idx), default=2)
        nf = len(fib_idx)
        self._lf_idx = np.zeros((nf, width), np.int64)
        self._lf_t = np.ones((nf, width))
        self._lf_valid = np.zeros((nf, width), bool)
        self._lf_nseg = np.zeros(nf, np.int64)
        for k, idx in enumerate(fib_idx):
            L = len(idx)
            self._lf_idx[k, :L] = idx
            self._lf_idx[k, L:] = idx[-1]
            self._lf_t[k, :L] = _arc_params(self.rest_points[idx])
            self._lf_valid[k, :L] = True
            self._lf_nseg[k] = L - 1
        self._lf_muscle = np.asarray(fib_mus, np.int64)
        self._lf_pts = self.rest_points[self._lf_idx]

    def _init_sphincters(self, specs: Sequence[MuscleSpec], bases: list[int]) -> None:
        """Sphincter control points: ring level (0 outermost .. 1 innermost) and axis geometry.

        Stores each point's projection on its muscle's axis (mm), its offset
        from that projection and the outward axis vector per unit protrusion
        (``|a_1 - a_0|`` long, from ``a_1`` toward ``a_0``, the end nearer the skin).
        """
        sph_pts: list[np.ndarray] = []
        sph_level: list[np.ndarray] = []
        sph_mus: list[np.ndarray] = []
        axes = np.zeros((len(specs), 2, 3))
        for m, (s, g) in enumerate(zip(specs, self.grids, strict=True)):
            if s.kind != "sphincter":
                continue
            if s.axis is None:
                raise ValueError(f"muscle {s.code}: a sphincter needs an axis")
            axes[m] = np.asarray(s.axis, float).reshape(2, 3)
            rows, cols = g.shape[:2]
            lev = np.repeat(np.arange(rows) / max(rows - 1, 1), cols)
            sph_pts.append(bases[m] + np.arange(rows * cols))
            sph_level.append(lev)
            sph_mus.append(np.full(rows * cols, m))
        self._sp_idx = np.concatenate(sph_pts) if sph_pts else np.zeros(0, np.int64)
        self._sp_level = np.concatenate(sph_level) if sph_level else np.zeros(0)
        self._sp_muscle = (
            np.concatenate(sph_mus).astype(np.int64) if sph_mus else np.zeros(0, np.int64)
        )
        a0 = axes[self._sp_muscle, 0]
        a1 = axes[self._sp_muscle, 1]
        ax = a1 - a0
        ax_len = np.linalg.norm(ax, axis=1)
        ax_u = ax / np.maximum(ax_len, 1e-12)[:, None]
        p = self.rest_points[self._sp_idx]
        self._sp_perp = a0 + np.einsum("ij,ij->i", p - a0, ax_u)[:, None] * ax_u
        # outward along the axis (a_0 is the outer end, nearer the skin), |a_1 - a_0| per unit protrusion
        self._sp_out = -ax_u * ax_len[:, None]
        self._sp_rel = p - self._sp_perp

    def _init_skin_attachment(
        self,
        specs: Sequence[MuscleSpec],
        bases: list[int],
        x: np.ndarray,
        nrm: np.ndarray,
        candidates: Mapping[str, np.ndarray] | None,
        inner_mm: float,
        outer_mm: float,
        samples_per_cell: int,
    ) -> None:
        """Attach skin nodes to the sheets (K 7.4.6) and fold the result into two sparse maps.

        ``_w_disp`` maps control-point displacements (mm) to node
        displacements, ``_w_bulge`` per-muscle bulge heights (mm) to node
        offsets along the rest normals; both are normalised by the node
        weights ``min(1, Σφ)``.
        """
        tree_rows: list[np.ndarray] = []
        tree_cols: list[np.ndarray] = []
        tree_vals: list[np.ndarray] = []
        bulge_rows: list[np.ndarray] = []
        bulge_cols: list[np.ndarray] = []
        bulge_vals: list[np.ndarray] = []
        phi_sum = np.zeros(len(x))
        uv = np.linspace(0.0, 1.0, samples_per_cell)
        grid_u, grid_v = np.meshgrid(uv, uv, indexing="ij")
        uu, vv = grid_u.ravel(), grid_v.ravel()
        bw = np.stack([(1 - uu) * (1 - vv), (1 - uu) * vv, uu * (1 - vv), uu * vv], axis=1)
        for m, (s, g) in enumerate(zip(specs, self.grids, strict=True)):
            samples, sample_cp, sample_w, sample_prof = _sheet_samples(
                g, bases[m], s.kind == "linear", bw, uu
            )
            allowed = None
            if candidates is not None and s.code in candidates:
                allowed = np.asarray(candidates[s.code], bool)
            vid, near, phi = _sheet_influence(samples, x, nrm, allowed, inner_mm, outer_mm)
            phi_sum[vid] += phi
            tree_rows.append(np.repeat(vid, 4))
            tree_cols.append(sample_cp[near].ravel())
            tree_vals.append((phi[:, None] * sample_w[near]).ravel())
            bulge_rows.append(vid)
            bulge_cols.append(np.full(len(vid), m))
            bulge_vals.append(phi * sample_prof[near])
        attached = np.nonzero(phi_sum > 0)[0]
        #: skin nodes with a muscle spring, and their weight min(1, Σφ)
        self.nodes = attached
        self.weights = np.minimum(1.0, phi_sum[attached])
        local = np.full(len(x), -1, np.int64)
        local[attached] = np.arange(len(attached))
        scale = 1.0 / np.maximum(self.weights, 1e-9)
        r_all = local[np.concatenate(tree_rows)] if tree_rows else np.zeros(0, np.int64)
        v_all = np.concatenate(tree_vals) if tree_vals else np.zeros(0)
        self._w_disp = sp.csr_matrix(
            (v_all * scale[r_all], (r_all, np.concatenate(tree_cols) if tree_cols else r_all)),
            shape=(len(attached), len(self.rest_points)),
        )
        rb = local[np.concatenate(bulge_rows)] if bulge_rows else np.zeros(0, np.int64)
        vb = np.concatenate(bulge_vals) if bulge_vals else np.zeros(0)
        self._w_bulge = sp.csr_matrix(
            (vb * scale[rb], (rb, np.concatenate(bulge_cols) if bulge_cols else rb)),
            shape=(len(attached), len(specs)),
        )
        self._rest_nodes = x[attached]
        self._normals = nrm[attached]
        #: per-muscle skin influence (node ids) for inspection
        self.influence = {
            self.codes[m]: np.asarray(r) for m, r in zip(range(len(specs)), bulge_rows, strict=True)
        }

    # ------------------------------------------------------------------
    def control_points(
        self,
        contraction: np.ndarray,
        protrusion: np.ndarray | None = None,
        jaw: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> np.ndarray:
        """Deformed control points ``(p, 3)`` (mm) for contractions ``(m,)`` in [0, 1]."""
        c = np.clip(np.asarray(contraction, float), 0.0, 1.0)
        q = self.rest_points.copy()
        if len(self._lf_idx):
            cf = c[self._lf_muscle]
            t = self._lf_t
            tt = np.maximum((1.0 - cf)[:, None] * t, MIN_ARC)
            tt[:, 0] = 0.0
            k = (t[:, None, :-1] < tt[:, :, None]).sum(axis=2) - 1
            k = np.clip(k, 0, (self._lf_nseg - 1)[:, None])
            ta = np.take_along_axis(t, k, axis=1)
            tb = np.take_along_axis(t, k + 1, axis=1)
            pa = np.take_along_axis(self._lf_pts, k[:, :, None], axis=1)
            pb = np.take_along_axis(self._lf_pts, (k + 1)[:, :, None], axis=1)
            frac = (tt - ta) / np.maximum(tb - ta, 1e-12)
            new = pa + (pb - pa) * frac[:, :, None]
            new[:, 0] = self._lf_pts[:, 0]
            v = self._lf_valid
            q[self._lf_idx[v]] = new[v]
        if len(self._sp_idx):
            cs = c[self._sp_muscle]
            centre = self._sp_perp
            if protrusion is not None:
                a = np.clip(np.asarray(protrusion, float), -1.0, 1.0)[self._sp_muscle]
                centre = centre + self._sp_out * (a * self._sp_level)[:, None]
            q[self._sp_idx] = centre + (1.0 - cs)[:, None] * self._sp_rel
        if jaw is not None and np.any(self.on_jaw):
            r, tr = jaw
            sel = self.on_jaw[self.point_muscle]
            q[sel] = q[sel] @ np.asarray(r).T + np.asarray(tr)
        return q

    def bulge(self, contraction: np.ndarray) -> np.ndarray:
        """Per-muscle bulge factor ``b`` (K 7.3.4, clamped)."""
        ratio = np.maximum(1.0 - np.clip(np.asarray(contraction, float), 0, 1), MIN_ARC)
        return np.clip(1.0 + BULGE_NU * (1.0 - ratio), *BULGE_RANGE)

    def targets(
        self,
        contraction: np.ndarray,
        protrusion: np.ndarray | None = None,
        jaw: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> np.ndarray:
        """Targets ``(len(nodes), 3)`` (mm) of the attached skin nodes."""
        q = self.control_points(contraction, protrusion, jaw)
        disp = self._w_disp @ (q - self.rest_points)
        out = self._w_bulge @ ((self.bulge(contraction) - 1.0) * HALF_HEIGHT_MM)
        return self._rest_nodes + disp + out[:, None] * self._normals

    def vector(self, values: Mapping[str, float]) -> np.ndarray:
        """``(m,)`` array from ``{code: value}`` (missing codes are 0)."""
        out = np.zeros(len(self.codes))
        for code, val in values.items():
            out[self.index[code]] = float(val)
        return out
