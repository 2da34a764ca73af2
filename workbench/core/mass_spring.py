"""The skin as a mass-spring system (Kähler 2003, ch. 6), integrated by projective dynamics.

Units and frame: millimetres, seconds and grams in the head frame (x to the
subject's left, x = 0 midsagittal, y up, z toward the face, Frankfort
Horizontal at y = 0).  Forces are therefore g·mm/s² (µN) and stiffnesses
g/s².

The model (digest §7.4)
-----------------------
* every skin edge is a spring; every interior edge also gets a *bending*
  spring across its two opposite vertices;
* masses are lumped: a third of each incident rest triangle's area × skin
  thickness (2 mm) × density (1100 kg/m³ = 1.1e-3 g/mm³);
* a skin node over bone gets a spring to its closest bone point, with the
  rest skin–bone distance as rest length.  Kähler adds a *mirrored* spring to
  an outside static node so that the node slides tangentially; a distance
  constraint on a sphere about the bone point has exactly that behaviour
  (tangential motion is free to first order), so one constraint stands for
  the pair.  ``tether_fraction`` (30 %) of that stiffness is instead a
  zero-length tether to the node's rest position on its bone: with only
  sliding constraints the local/global iteration converges very slowly in
  the tangential directions and "relaxed" would not come back to rest.  Which bone (cranium or mandible) is decided at initialisation:
  in the lower face a node closer to the mandible than to the cranium goes
  with the jaw (K 7.4.5, 12);  nodes in regions without bone (lips, cheeks;
  passed in as ``bone_free``) or farther than ``bone_max_mm`` from bone get
  none;
* muscle-attached nodes (chosen by :mod:`workbench.core.muscle_model`) get
  zero-length springs to targets the muscles move; their bone spring is
  scaled down by their muscle weight so the two blend;
* simulated nodes with neither bone nor muscle springs (deep cheeks, nose
  tip) get a weak pull to rest (``hold_ratio`` = 10 % of the foundation),
  Lee et al.'s restoring force ``h_i`` (digest §8.5);
* only ``simulated`` nodes move; the others are kinematic (scalp, ears,
  neck: Kähler also simulates only the face) and follow their bone rigidly.

Integrator: projective dynamics (Bouaziz et al. 2014)
-----------------------------------------------------
Explicit Euler and Kähler's leapfrog Verlet are only conditionally stable,
and full implicit Euler needs a new sparse factorisation whenever springs
rotate.  Projective dynamics is an implicit-Euler scheme whose global
matrix ``M/h² + Σ w Aᵀ A`` does not depend on the positions, so it is
factorised once (sparse LU) and every step is one *local* step (project
each spring onto its rest length, each bone node onto its sphere, each
muscle node onto its target; vectorised numpy) and one *global* step (two
triangular solves with three right-hand sides).  It is unconditionally
stable for any stiffness and time step, which is what the seeds' unitless
values need.  The local step and the two triangular solves (SuperLU's
factors) run in numba kernels when numba is installed (``cache=True``; the
arithmetic is the same as the numpy/scipy fallback, to 1e-8 mm), which is
what reaches the issue's 300 steps/s on the reference head.

:meth:`SkinSimulation.settle` runs the same iteration quasi-statically (a
0.1 s step, no velocity) with Chebyshev acceleration (Wang 2015) to reach
the static pose of an expression in a few hundred iterations.

Scaling the seeds' unitless constants
-------------------------------------
Kähler's 100 (edge modulus E) and 30 (skin–bone) only work for his mesh and
time step.  Here they become two resolution-independent physical scales:

* the bone foundation is a stiffness per unit area, ``k_b = ρ τ / T²`` with
  response time ``T = response_time_s`` (a node on its own spring has the
  period 2πT whatever its area); per node ``k_b A_i``;
* the membrane modulus is ``E = k_b λ²`` with ``λ = membrane_length_mm``,
  the distance over which a point displacement of the skin decays on the
  foundation.  Kähler's values (E = 100, bone 30 on ≈ 140 mm² nodes of
  his 1027-vertex head) give λ ≈ sqrt(100 / 0.21) ≈ 20 mm; the default is
  12 mm, tuned so that the muscle-driven regions (a few mm to a few cm
  wide) are not flattened by the membrane (a 20 mm λ halves the mouth
  corners' movement in a smile);
* edge springs follow Van Gelder: ``k_s = E Σ area(T_s) / r_s²`` (rest
  areas), so the membrane energy does not change when the mesh is refined;
  bending springs are ``bending_ratio`` of that;
* muscle springs are ``muscle_ratio × k_b A_i`` = 5 × the foundation.
  Kähler's skin-muscle springs are weaker (10 against 30 for the bone), but
  he also moves each attached skin node with its muscle every frame
  ("over-relaxation", K 7.3.5), so his skin follows the muscles closely;
  a stiffer spring gives that without the violence he reports.

Damping: implicit Euler damps on its own; on top of that velocities decay
with the time constant ``damping_time_s`` (Kähler's γ = 30 on 0.31 g
nodes is γ/m ≈ 100 /s, i.e. 10 ms), independent of the time step
(``v ← v · exp(-h / τ_d)``).

Kähler's biphasic modulus (×10 beyond 150 % stretch) is not modelled:
projective-dynamics weights are constant; stretch that large does not occur
in the expressions here.

Volume preservation: the skin layer keeps its volume, so where the skin
around a node is compressed tangentially (one-ring area ``A < A₀``) its
thickness grows by ``τ (A₀/A − 1)`` and the node's bone-sphere radius
grows by as much (clamped to [−τ/2, 2τ]): contracted regions bulge,
stretched ones thin.

Non-penetration: after each step bone-attached nodes are kept on the outer
side of the tangent plane of their bone point (cheap, exact for the
small slides the springs allow); :meth:`SkinSimulation.push_out_of_bone`
does the exact test with a :class:`~workbench.core.spatial.MeshIndex`
(signed distance) and is run by ``settle``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from workbench.core.compiled import numba as _numba
from workbench.core.mass_spring_setup import (
    BoneContact,
    edge_topology,
    kinematic_jaw_share,
    muscle_weights_per_node,
    triangle_areas,
)
from workbench.core.spatial import MeshIndex

NONE, SKULL, JAW = 0, 1, 2


# ---------------------------------------------------------------------- compiled kernels
# Plain-Python loops compiled by numba (``cache=True``: compiled once per machine and
# kept in __pycache__; the first compile takes a few seconds, see benchmarks/bench_animation.py).
def _springs_kernel(s, si, sj, rest, w, out):
    """Scatter ``w * rest * d/|d|`` of every spring (d = s_i - s_j) into ``out`` (+ at i, - at j)."""
    for k in range(si.shape[0]):
        i = si[k]
        j = sj[k]
        d0 = s[i, 0] - s[j, 0]
        d1 = s[i, 1] - s[j, 1]
        d2 = s[i, 2] - s[j, 2]
        length = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        f = w[k] * rest[k] / max(length, 1e-12)
        out[i, 0] += f * d0
        out[i, 1] += f * d1
        out[i, 2] += f * d2
        out[j, 0] -= f * d0
        out[j, 1] -= f * d1
        out[j, 2] -= f * d2


def _bone_kernel(
    s, bn, ptr, ring, faces, rest_area, anchor, bone_rest, tether, normal, bw, tw, tau, out
):
    """Bone spheres (radius grown by the volume term) and tethers of the bone nodes into ``out``."""
    for k in range(bn.shape[0]):
        v = bn[k]
        area = 0.0
        for q in range(ptr[k], ptr[k + 1]):
            f = ring[q]
            a = faces[f, 0]
            b = faces[f, 1]
            c = faces[f, 2]
            e0 = s[b, 0] - s[a, 0]
            e1 = s[b, 1] - s[a, 1]
            e2 = s[b, 2] - s[a, 2]
            g0 = s[c, 0] - s[a, 0]
            g1 = s[c, 1] - s[a, 1]
            g2 = s[c, 2] - s[a, 2]
            c0 = e1 * g2 - e2 * g1
            c1 = e2 * g0 - e0 * g2
            c2 = e0 * g1 - e1 * g0
            area += 0.5 * np.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
        area /= 3.0
        grow = tau * (rest_area[v] / max(area, 1e-9) - 1.0)
        grow = min(max(grow, -0.5 * tau), 2.0 * tau)
        u0 = s[v, 0] - anchor[k, 0]
        u1 = s[v, 1] - anchor[k, 1]
        u2 = s[v, 2] - anchor[k, 2]
        sc = (bone_rest[v] + grow) / max(np.sqrt(u0 * u0 + u1 * u1 + u2 * u2), 1e-12)
        out[v, 0] += bw[k] * (anchor[k, 0] + u0 * sc) + tw[k] * (tether[k, 0] + normal[k, 0] * grow)
        out[v, 1] += bw[k] * (anchor[k, 1] + u1 * sc) + tw[k] * (tether[k, 1] + normal[k, 1] * grow)
        out[v, 2] += bw[k] * (anchor[k, 2] + u2 * sc) + tw[k] * (tether[k, 2] + normal[k, 2] * grow)


def _lu_kernel(lp, li, lx, up, ui, ux, perm_r, perm_c, b, y, out):
    """Solve ``A x = b`` (3 columns) from SuperLU factors ``Pr A Pc = L U`` (CSC, sorted rows)."""
    n = b.shape[0]
    for i in range(n):
        r = perm_r[i]
        y[r, 0] = b[i, 0]
        y[r, 1] = b[i, 1]
        y[r, 2] = b[i, 2]
    for j in range(n):  # L: the diagonal is each column's first entry
        d = lx[lp[j]]
        y0 = y[j, 0] / d
        y1 = y[j, 1] / d
        y2 = y[j, 2] / d
        y[j, 0] = y0
        y[j, 1] = y1
        y[j, 2] = y2
        for q in range(lp[j] + 1, lp[j + 1]):
            i = li[q]
            y[i, 0] -= lx[q] * y0
            y[i, 1] -= lx[q] * y1
            y[i, 2] -= lx[q] * y2
    for j in range(n - 1, -1, -1):  # U: the diagonal is each column's last entry
        d = ux[up[j + 1] - 1]
        y0 = y[j, 0] / d
        y1 = y[j, 1] / d
        y2 = y[j, 2] / d
        y[j, 0] = y0
        y[j, 1] = y1
        y[j, 2] = y2
        for q in range(up[j], up[j + 1] - 1):
            i = ui[q]
            y[i, 0] -= ux[q] * y0
            y[i, 1] -= ux[q] * y1
            y[i, 2] -= ux[q] * y2
    for i in range(n):
        c = perm_c[i]
        out[i, 0] = y[c, 0]
        out[i, 1] = y[c, 1]
        out[i, 2] = y[c, 2]


if _numba is not None:
    _springs_jit = _numba.njit(cache=True, nogil=True)(_springs_kernel)
    _bone_jit = _numba.njit(cache=True, nogil=True)(_bone_kernel)
    _lu_jit = _numba.njit(cache=True, nogil=True)(_lu_kernel)


class _Solver:
    """Prefactorised ``A x = b`` for the free block: SuperLU, solved by numba when it is there."""

    def __init__(self, matrix: sp.csc_matrix, compiled: bool) -> None:
        self.lu = splu(
            matrix,
            permc_spec="MMD_AT_PLUS_A",
            diag_pivot_thresh=0.0,
            options={"SymmetricMode": True},
        )
        self.compiled = compiled
        if compiled:
            low = self.lu.L.tocsc()
            upp = self.lu.U.tocsc()
            low.sort_indices()
            upp.sort_indices()
            self._l = (low.indptr, low.indices, low.data)
            self._u = (upp.indptr, upp.indices, upp.data)
            self._pr = np.asarray(self.lu.perm_r, np.int64)
            self._pc = np.asarray(self.lu.perm_c, np.int64)
            self._y = np.zeros((matrix.shape[0], 3))

    def solve(self, b: np.ndarray) -> np.ndarray:
        if not self.compiled:
            return np.asarray(self.lu.solve(b))
        out = np.empty((b.shape[0], 3))
        _lu_jit(*self._l, *self._u, self._pr, self._pc, np.ascontiguousarray(b), self._y, out)
        return out


@dataclass(frozen=True)
class SkinParameters:
    """Physical parameters of the skin model (mm, s, g); see the module docstring."""

    #: skin thickness τs (Kähler: 2 mm) and density (1100 kg/m³) for the masses
    thickness_mm: float = 2.0
    density_g_per_mm3: float = 1.1e-3
    #: real-time step (10 steps per 60 Hz frame)
    time_step_s: float = 1.0 / 600.0
    #: T of the bone foundation, k_b = ρ τ / T² per mm² of skin
    response_time_s: float = 0.004
    #: λ: membrane modulus E = k_b λ²
    membrane_length_mm: float = 12.0
    #: bending springs relative to the Van Gelder edge stiffness
    bending_ratio: float = 0.05
    #: muscle springs relative to the foundation
    muscle_ratio: float = 5.0
    #: velocity decay time constant (Kähler's γ/m ≈ 100 /s)
    damping_time_s: float = 0.010
    #: no bone spring (and no jaw following) farther than this from bone
    bone_max_mm: float = 14.0
    #: skin is kept this far outside the bone's tangent plane (or its rest depth, if less)
    bone_margin_mm: float = 1.0
    #: step of the quasi-static settle
    settle_step_s: float = 0.1
    #: share of the bone stiffness that is a tether to the rest position on the bone
    tether_fraction: float = 0.3
    #: pull to rest of nodes with neither bone nor muscle springs, relative to the foundation
    hold_ratio: float = 0.1


class SkinSimulation:
    """Mass-spring skin on a triangle mesh, stepped by projective dynamics.

    Parameters
    ----------
    vertices, faces : rest skin (mm, head frame)
    cranium, mandible : MeshIndex over the bones (mandible may be None)
    simulated : (n,) bool, nodes that move (others are kinematic)
    bone_free : (n,) bool, nodes that never get a bone spring (lips, cheeks)
    lower_face : (n,) bool, where a node closer to the mandible follows the jaw
    muscle_nodes, muscle_weights : nodes with muscle springs and their weight in (0, 1]
    """

    def __init__(
        self,
        vertices: np.ndarray,
        faces: np.ndarray,
        *,
        cranium: MeshIndex,
        mandible: MeshIndex | None = None,
        simulated: np.ndarray | None = None,
        bone_free: np.ndarray | None = None,
        lower_face: np.ndarray | None = None,
        muscle_nodes: np.ndarray | None = None,
        muscle_weights: np.ndarray | None = None,
        params: SkinParameters | None = None,
        compiled: bool | None = None,
    ) -> None:
        p = params or SkinParameters()
        #: numba kernels in use (default: whenever numba imports); False: numpy/scipy only
        self.compiled = (_numba is not None) if compiled is None else bool(compiled and _numba)
        self.params = p
        x0 = np.array(vertices, dtype=np.float64).reshape(-1, 3)
        f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
        n = len(x0)
        self.rest = x0
        self.faces = f
        self.n = n
        sim = np.ones(n, bool) if simulated is None else np.asarray(simulated, bool).copy()
        free_of_bone = np.zeros(n, bool) if bone_free is None else np.asarray(bone_free, bool)
        lower = np.zeros(n, bool) if lower_face is None else np.asarray(lower_face, bool)

        area_f = self._init_masses(x0, f)
        bone = self._init_bone_attachment(x0, sim, free_of_bone, lower, cranium, mandible)

        # --- stiffness scales (see module docstring)
        k_area = p.density_g_per_mm3 * p.thickness_mm / p.response_time_s**2  # g/(s^2 mm^2)
        modulus = k_area * p.membrane_length_mm**2  # g/s^2
        self.k_area = k_area
        self.modulus = modulus
        self._init_springs(x0, f, area_f, sim)
        self._init_node_weights(sim, muscle_weights_per_node(n, muscle_nodes, muscle_weights, sim))
        self.bone_rest = np.linalg.norm(x0 - bone.points, axis=1)
        self._init_system(sim)

        self.x = x0.copy()
        self.v = np.zeros_like(x0)
        self.jaw_rotation = np.eye(3)
        self.jaw_translation = np.zeros(3)
        self._targets = x0[self.muscle_nodes].copy()
        self._kin_rest = x0[self.kinematic]
        self._kin_jaw = kinematic_jaw_share(bone, self.kinematic, p.bone_max_mm)
        self._init_local_step(x0, bone.points)
        self.steps_taken = 0

    def _init_masses(self, x0: np.ndarray, f: np.ndarray) -> np.ndarray:
        """Lumped masses (g): a third of each rest triangle's area x thickness x density.

        Sets ``_vf`` (vertex-face incidence), ``rest_area`` (mm², per vertex)
        and ``mass``; returns the rest triangle areas (mm²).
        """
        p = self.params
        n = len(x0)
        area_f = triangle_areas(x0, f)
        self._vf = sp.csr_matrix(
            (np.ones(f.size), (f.reshape(-1), np.repeat(np.arange(len(f)), 3))), shape=(n, len(f))
        )
        area_v = (self._vf @ area_f) / 3.0
        self.rest_area = np.maximum(area_v, 1e-9)
        self.mass = self.rest_area * p.thickness_mm * p.density_g_per_mm3
        return area_f

    def _init_bone_attachment(
        self,
        x0: np.ndarray,
        sim: np.ndarray,
        free_of_bone: np.ndarray,
        lower: np.ndarray,
        cranium: MeshIndex,
        mandible: MeshIndex | None,
    ) -> BoneContact:
        """Decide once, from the rest skin-bone distances (mm), which bone each node follows.

        Sets ``attachment``, ``follows``, ``guard_nodes``, ``bone_distance`` and
        the rest bone points and unit normals (head frame); returns the contact.
        """
        p = self.params
        n = len(x0)
        cl_c = cranium.closest_points(x0)
        d_c = cl_c.distances
        bone_pt = cl_c.points.copy()
        bone_n = cranium.pseudo_normals(cl_c.face_ids, cl_c.barycentric)
        attach = np.full(n, SKULL, np.int8)
        if mandible is not None:
            cl_m = mandible.closest_points(x0)
            jaw = lower & (cl_m.distances < d_c)
            attach[jaw] = JAW
            bone_pt[jaw] = cl_m.points[jaw]
            bone_n[jaw] = mandible.pseudo_normals(cl_m.face_ids[jaw], cl_m.barycentric[jaw])
            d_b = np.where(jaw, cl_m.distances, d_c)
        else:
            d_b = d_c
        #: which bone each node follows (kinematic nodes too): SKULL or JAW
        # (far from the mandible, e.g. the lower neck, a node stays with the skull)
        nearer_jaw = attach == JAW
        self.follows = np.where((attach == JAW) & (d_b <= p.bone_max_mm), JAW, SKULL).astype(
            np.int8
        )
        #: nodes kept outside the tangent plane of their nearest bone point
        self.guard_nodes = np.nonzero(sim & (d_b <= 2.0 * p.bone_max_mm))[0]
        self._guard_jaw = nearer_jaw[self.guard_nodes]
        springy = sim & ~free_of_bone & (d_b <= p.bone_max_mm)
        attach[~springy] = NONE
        #: bone spring of each node: NONE, SKULL or JAW
        self.attachment = attach
        self.bone_distance = d_b
        self._bone_pt0 = bone_pt
        self._bone_n0 = bone_n / np.maximum(np.linalg.norm(bone_n, axis=1, keepdims=True), 1e-12)
        return BoneContact(bone_pt, d_b, nearer_jaw)

    def _init_springs(self, x0: np.ndarray, f: np.ndarray, area_f: np.ndarray, sim: np.ndarray):
        """Edge and bending springs: rest lengths (mm) and Van Gelder stiffnesses (g/s²).

        Springs between two kinematic nodes do nothing and are dropped.  Sets
        ``spring_i``, ``spring_j``, ``spring_rest``, ``spring_w`` (edge springs
        first) and the counts ``n_edge_springs``, ``n_bend_springs``.
        """
        p = self.params
        modulus = self.modulus
        edges, bend, bend_edge, edge_face = edge_topology(f, len(x0))
        e_area = np.bincount(edge_face[:, 0], weights=area_f[edge_face[:, 1]], minlength=len(edges))
        r_e = np.linalg.norm(x0[edges[:, 0]] - x0[edges[:, 1]], axis=1)
        r_b = np.linalg.norm(x0[bend[:, 0]] - x0[bend[:, 1]], axis=1)
        # bending springs: the two triangles of the interior edge they cross
        k_e = modulus * e_area / np.maximum(r_e, 1e-9) ** 2
        b_area = e_area[bend_edge]
        k_b = p.bending_ratio * modulus * b_area / np.maximum(r_b, 1e-9) ** 2
        # springs between two kinematic nodes do nothing: drop them
        keep_e = sim[edges[:, 0]] | sim[edges[:, 1]]
        keep_b = sim[bend[:, 0]] | sim[bend[:, 1]]
        self.spring_i = np.r_[edges[keep_e, 0], bend[keep_b, 0]]
        self.spring_j = np.r_[edges[keep_e, 1], bend[keep_b, 1]]
        self.spring_rest = np.r_[r_e[keep_e], r_b[keep_b]]
        self.spring_w = np.r_[k_e[keep_e], k_b[keep_b]]
        self.n_edge_springs = int(keep_e.sum())
        self.n_bend_springs = int(keep_b.sum())

    def _init_node_weights(self, sim: np.ndarray, mw: np.ndarray) -> None:
        """Per-node weights (g/s²) of the bone, tether, muscle and hold terms, and their nodes.

        ``mw`` is the muscle weight per node (0 on kinematic nodes): the bone
        spring is scaled by ``1 - mw`` so the bone and muscle springs blend.
        """
        p = self.params
        k_area, attach = self.k_area, self.attachment
        self.muscle_weight = mw
        bone_total = np.where(attach != NONE, k_area * self.rest_area * (1.0 - mw), 0.0)
        self.bone_w = (1.0 - p.tether_fraction) * bone_total
        self.tether_w = p.tether_fraction * bone_total
        self.muscle_w = p.muscle_ratio * k_area * self.rest_area * mw
        self.bone_nodes = np.nonzero(self.bone_w > 0)[0]
        self.muscle_nodes = np.nonzero(self.muscle_w > 0)[0]
        # nodes with neither bone nor full muscle springs: a weak pull to rest (Lee's h_i, L 8),
        # or sliding cheeks would converge very slowly and drift
        self.hold_w = np.where(
            sim & (attach == NONE), p.hold_ratio * k_area * self.rest_area * (1.0 - mw), 0.0
        )
        self.hold_nodes = np.nonzero(self.hold_w > 0)[0]

    def _init_system(self, sim: np.ndarray) -> None:
        """Global matrix ``M/h² + Σ w AᵀA``, split into free / kinematic blocks, and its LU.

        ``A`` is the spring incidence (one row per spring, +1 at i, -1 at j);
        factorised once for the real-time step ``params.time_step_s``.
        """
        n = self.n
        m = len(self.spring_i)
        rows = np.arange(m)
        a_mat = sp.csr_matrix(
            (
                np.r_[np.ones(m), -np.ones(m)],
                (np.r_[rows, rows], np.r_[self.spring_i, self.spring_j]),
            ),
            shape=(m, n),
        )
        w_springs = sp.diags(self.spring_w)
        lap = (a_mat.T @ w_springs @ a_mat).tocsr()
        self.free = np.nonzero(sim)[0]
        self.kinematic = np.nonzero(~sim)[0]
        self._stiff = (
            lap + sp.diags(self.bone_w + self.tether_w + self.muscle_w + self.hold_w)
        ).tocsc()
        self._a_t_w = (
            a_mat.T @ w_springs
        ).tocsr()  # n x m: scatter of w * projected spring vectors
        self._a_t_w_free = self._a_t_w[self.free]
        self._l_fk = self._stiff[self.free][:, self.kinematic].tocsr()
        self._lu, self._inertia = self._factor(self.params.time_step_s)
        self._settle_solver: tuple[Any, np.ndarray] | None = None

    def _init_local_step(self, x0: np.ndarray, bone_pt: np.ndarray) -> None:
        """Gathered per-term arrays the local step reads (anchors and normals in the head frame,
        mm; weights in g/s²; positions of the nodes in the free block)."""
        n = self.n
        self._bone_jaw = self.attachment[self.bone_nodes] == JAW
        self._bone_anchor = bone_pt[self.bone_nodes].copy()
        self._bone_normal = self._bone_n0[self.bone_nodes].copy()
        bone_face_ids = np.unique(self._vf[self.bone_nodes].indices)
        self._bone_faces = self.faces[bone_face_ids]
        self._face_of_bone = self._vf[self.bone_nodes][:, bone_face_ids].tocsr()
        ring = self._vf[self.bone_nodes].tocsr()  # one-ring faces of each bone node, for the kernel
        self._ring_ptr = ring.indptr.astype(np.int64)
        self._ring_faces = ring.indices.astype(np.int64)
        free_pos = np.full(n, -1, np.int64)
        free_pos[self.free] = np.arange(len(self.free))
        self._bone_free_pos = free_pos[self.bone_nodes]
        self._muscle_free_pos = free_pos[self.muscle_nodes]
        self._bone_wv = self.bone_w[self.bone_nodes, None]
        self._tether_wv = self.tether_w[self.bone_nodes, None]
        self._tether_rest = x0[self.bone_nodes].copy()
        self._hold_free_pos = free_pos[self.hold_nodes]
        self._hold_wv = self.hold_w[self.hold_nodes, None]
        self._hold_jaw = self.follows[self.hold_nodes] == JAW
        self._hold_rest = x0[self.hold_nodes].copy()
        self._muscle_wv = self.muscle_w[self.muscle_nodes, None]
        # nodes already closer to their bone than the margin keep their rest depth
        g = self.guard_nodes
        self._guard_anchor = bone_pt[g].copy()
        self._guard_normal = self._bone_n0[g].copy()
        depth0 = np.einsum("ij,ij->i", x0[g] - bone_pt[g], self._bone_n0[g])
        self._margin = np.minimum(self.params.bone_margin_mm, np.maximum(depth0, 0.0))

    def _factor(self, h: float) -> tuple[Any, np.ndarray]:
        """LU of the free block of ``M/h² + Σ w AᵀA`` and the inertia weights ``m/h²``."""
        inertia = self.mass / h**2
        system = (self._stiff + sp.diags(inertia)).tocsc()
        free = self.free
        return _Solver(system[free][:, free].tocsc(), self.compiled), inertia[free, None]

    # ------------------------------------------------------------------ control
    def set_jaw(self, rotation: np.ndarray, translation: np.ndarray) -> None:
        """Rigid jaw transform ``x -> R x + t`` (mm) applied to jaw-attached anchors and nodes."""
        self.jaw_rotation = np.asarray(rotation, float).reshape(3, 3)
        self.jaw_translation = np.asarray(translation, float).reshape(3)
        r, t = self.jaw_rotation, self.jaw_translation
        anchors = self._bone_pt0[self.bone_nodes].copy()
        normals = self._bone_n0[self.bone_nodes].copy()
        j = self._bone_jaw
        anchors[j] = anchors[j] @ r.T + t
        normals[j] = normals[j] @ r.T
        self._bone_anchor = anchors
        self._bone_normal = normals
        g = self.guard_nodes
        ga = self._bone_pt0[g].copy()
        gn = self._bone_n0[g].copy()
        gj = self._guard_jaw
        ga[gj] = ga[gj] @ r.T + t
        gn[gj] = gn[gj] @ r.T
        self._guard_anchor = ga
        self._guard_normal = gn
        tether = self.rest[self.bone_nodes].copy()
        tether[j] = tether[j] @ r.T + t
        self._tether_rest = tether
        hold = self.rest[self.hold_nodes].copy()
        hold[self._hold_jaw] = hold[self._hold_jaw] @ r.T + t
        self._hold_rest = hold
        kin = self._kin_rest.copy()
        kin += self._kin_jaw * (kin @ r.T + t - kin)
        self.x[self.kinematic] = kin

    def set_muscle_targets(self, targets: np.ndarray) -> None:
        """Target positions ``(len(muscle_nodes), 3)`` (mm) of the muscle-attached nodes."""
        self._targets = np.asarray(targets, float).reshape(len(self.muscle_nodes), 3)

    # ------------------------------------------------------------------ stepping
    def step(self, n: int = 1) -> None:
        """Advance ``n`` time steps of ``params.time_step_s`` seconds."""
        p = self.params
        self._run(
            n, self._lu, self._inertia, p.time_step_s, np.exp(-p.time_step_s / p.damping_time_s)
        )

    def _run(self, n: int, lu: Any, inertia: np.ndarray, h: float, decay: float) -> None:
        kin_rhs = self._l_fk @ self.x[self.kinematic] if len(self.kinematic) else 0.0
        for _ in range(int(n)):
            new = self._iterate(self.x + h * self.v, lu, inertia, kin_rhs)
            self.v = (new - self.x) * (decay / h)
            self.x = new
            self.steps_taken += 1

    def _iterate(self, s: np.ndarray, lu: Any, inertia: np.ndarray, kin_rhs: Any) -> np.ndarray:
        """One local/global iteration from the predicted positions ``s``; returns new positions."""
        if self.compiled:
            return self._iterate_compiled(s, lu, inertia, kin_rhs)
        tau = self.params.thickness_mm
        free = self.free
        # local step: springs onto their rest length
        d = s[self.spring_i] - s[self.spring_j]
        length = np.sqrt(np.einsum("ij,ij->i", d, d))
        proj = d * (self.spring_rest / np.maximum(length, 1e-12))[:, None]
        rhs = inertia * s[free] + self._a_t_w_free @ proj - kin_rhs
        # bone nodes onto spheres about their anchors, radius grown where the skin is compressed
        bn = self.bone_nodes
        if len(bn):
            area = (self._face_of_bone @ triangle_areas(s, self._bone_faces)) / 3.0
            grow = np.clip(
                tau * (self.rest_area[bn] / np.maximum(area, 1e-9) - 1.0), -tau / 2, 2 * tau
            )
            u = s[bn] - self._bone_anchor
            ul = np.sqrt(np.einsum("ij,ij->i", u, u))
            scale = (self.bone_rest[bn] + grow) / np.maximum(ul, 1e-12)
            rhs[self._bone_free_pos] += self._bone_wv * (self._bone_anchor + u * scale[:, None])
            # tether to the rest position on the bone, lifted by the same volume-preserving growth
            rhs[self._bone_free_pos] += self._tether_wv * (
                self._tether_rest + self._bone_normal * grow[:, None]
            )
        if len(self.muscle_nodes):
            rhs[self._muscle_free_pos] += self._muscle_wv * self._targets
        if len(self.hold_nodes):
            rhs[self._hold_free_pos] += self._hold_wv * self._hold_rest
        new = s.copy()
        new[self.kinematic] = self.x[self.kinematic]
        new[free] = lu.solve(rhs)
        self._keep_above_bone(new)
        return new

    def _iterate_compiled(
        self, s: np.ndarray, lu: Any, inertia: np.ndarray, kin_rhs: Any
    ) -> np.ndarray:
        """:meth:`_iterate` with the local step and the solve in numba kernels (same arithmetic)."""
        s = np.ascontiguousarray(s)
        full = np.zeros_like(s)
        _springs_jit(s, self.spring_i, self.spring_j, self.spring_rest, self.spring_w, full)
        if len(self.bone_nodes):
            _bone_jit(
                s,
                self.bone_nodes,
                self._ring_ptr,
                self._ring_faces,
                self.faces,
                self.rest_area,
                self._bone_anchor,
                self.bone_rest,
                self._tether_rest,
                self._bone_normal,
                self._bone_wv[:, 0],
                self._tether_wv[:, 0],
                self.params.thickness_mm,
                full,
            )
        if len(self.muscle_nodes):
            full[self.muscle_nodes] += self._muscle_wv * self._targets
        if len(self.hold_nodes):
            full[self.hold_nodes] += self._hold_wv * self._hold_rest
        free = self.free
        rhs = inertia * s[free] + full[free] - kin_rhs
        new = s.copy()
        new[self.kinematic] = self.x[self.kinematic]
        new[free] = lu.solve(rhs)
        self._keep_above_bone(new)
        return new

    def _keep_above_bone(self, x: np.ndarray) -> None:
        """Keep nodes near bone ``bone_margin_mm`` outside their bone point's tangent plane."""
        g = self.guard_nodes
        if not len(g):
            return
        depth = np.einsum("ij,ij->i", x[g] - self._guard_anchor, self._guard_normal)
        short = self._margin - depth
        inside = short > 0
        if np.any(inside):
            x[g[inside]] += self._guard_normal[inside] * short[inside, None]

    def settle(self, tol_mm: float = 1e-3, max_steps: int = 3000) -> int:
        """Quasi-static solve: iterate until no node moves more than ``tol_mm`` per iteration.

        The same local/global iteration with a long step (``settle_step_s``)
        and no velocity carried over, accelerated by Chebyshev semi-iteration
        (Wang 2015, "A Chebyshev semi-iterative approach for accelerating
        projective and position-based dynamics") with the spectral radius
        estimated from the first plain iterations; a growing update restarts
        the acceleration.  Returns the iterations taken.
        """
        if self._settle_solver is None:
            self._settle_solver = self._factor(self.params.settle_step_s)
        lu, inertia = self._settle_solver
        kin_rhs = self._l_fk @ self.x[self.kinematic] if len(self.kinematic) else 0.0
        self.v[:] = 0.0
        prev = self.x.copy()
        x = self.x.copy()
        history: list[float] = []
        rho = 0.0
        omega = 1.0
        k_accel = 0
        done = 0
        last = np.inf
        while done < max_steps:
            xh = self._iterate(x, lu, inertia, kin_rhs)
            done += 1
            move = float(np.max(np.abs(xh - x)))
            if move < tol_mm:
                x = xh
                break
            if rho == 0.0:
                history.append(move)
                if len(history) == 12:
                    rho = min(0.995, (history[-1] / max(history[1], 1e-30)) ** (1 / 10))
                nxt = xh
            else:
                if move > 1.5 * last:  # diverging: restart the acceleration
                    k_accel = 0
                k_accel += 1
                omega = (
                    1.0
                    if k_accel == 1
                    else (2 / (2 - rho**2) if k_accel == 2 else 4 / (4 - rho**2 * omega))
                )
                nxt = omega * (xh - prev) + prev
                nxt[self.kinematic] = x[self.kinematic]
            last = move
            prev, x = x, nxt
        self.x = x
        self._keep_above_bone(self.x)
        self.v[:] = 0.0
        self.steps_taken += done
        return done

    def push_out_of_bone(self, bones: list[tuple[MeshIndex, np.ndarray | None]]) -> int:
        """Exact non-penetration: move simulated nodes found inside a bone to its surface + margin.

        ``bones`` is a list of (index over the rest bone, 4x4 transform or None);
        the query is done in the bone's rest frame.  Returns how many nodes moved.
        """
        moved = 0
        free = self.free
        for index, transform in bones:
            pts = self.x[free]
            if transform is not None:
                r, t = transform[:3, :3], transform[:3, 3]
                local = (pts - t) @ r
            else:
                r, t, local = np.eye(3), np.zeros(3), pts
            sd = index.signed_distance(local)
            bad = sd < 0.0
            if not np.any(bad):
                continue
            cl = index.closest_points(local[bad])
            nrm = index.pseudo_normals(cl.face_ids, cl.barycentric)
            fixed = cl.points + nrm * self.params.bone_margin_mm
            self.x[free[bad]] = fixed @ r.T + t
            moved += int(bad.sum())
        return moved

    def reset(self) -> None:
        """Back to the rest shape, at rest."""
        self.x = self.rest.copy()
        self.v[:] = 0.0
        self.set_jaw(self.jaw_rotation, self.jaw_translation)
