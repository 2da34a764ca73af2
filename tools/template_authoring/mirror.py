import numpy as np
def mirror(P, F, tol=1e-9):
    n = len(P)
    mid = np.abs(P[:, 0]) < tol
    mp = np.arange(n)
    off = np.nonzero(~mid)[0]
    mp[off] = n + np.arange(len(off))
    P2 = np.vstack([P, P[off] * np.array([-1, 1, 1])])
    F2 = np.vstack([F, mp[F][:, ::-1]])
    return P2, F2, mp
