"""Fit control positions so that the Loop-subdivided surface lies on the design SDF."""
from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
from scipy import sparse
from scipy.sparse.linalg import spsolve

import geom

_spec = importlib.util.spec_from_file_location("subdiv", str(Path(__file__).resolve().parents[2] / "workbench" / "core" / "headgen" / "subdivision.py"))
subdiv = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(subdiv)


def fine_classes(sub, kinds_sdf):
    """bool per fine vertex: True if it should lie on the SDF (all its control parents are sdf)."""
    S = sub.matrix.tocsr()
    bad = (~kinds_sdf).astype(float)
    contrib = S.multiply(S > 0) @ bad
    return np.asarray(contrib).ravel() < 1e-9


def fit(P, F, kinds_sdf, creases=None, corners=None, iters=3, lam=0.02, extra_targets=None,
        midline=None, verbose=True):
    n = len(P)
    sub = subdiv.loop_subdivide(F, n, 1, creases, corners)
    S = sub.matrix.tocsr()
    on_sdf = fine_classes(sub, kinds_sdf)
    C = P.copy()
    T0 = S @ P
    for it in range(iters):
        Fp = S @ C
        T = T0.copy()
        T[on_sdf] = geom.project(Fp[on_sdf])
        if extra_targets is not None:
            mask, fn = extra_targets
            T[mask] = fn(Fp, mask)
        w = np.where(on_sdf, 1.0, 0.6)
        if extra_targets is not None:
            w[extra_targets[0]] = 1.0
        W = sparse.diags(w)
        A = (S.T @ W @ S + lam * sparse.identity(n)).tocsc()
        rhs = S.T @ (w[:, None] * T) + lam * C
        C = np.column_stack([spsolve(A, rhs[:, k]) for k in range(3)])
        if midline is not None:
            C[midline, 0] = 0.0
        if verbose:
            err = np.linalg.norm(S @ C - T, axis=1)
            print(f"fit iter {it}: rms {np.sqrt((err[on_sdf] ** 2).mean()):.3f} max {err[on_sdf].max():.3f}")
    return C, sub
