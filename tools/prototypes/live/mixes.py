#!/usr/bin/python3
"""Mixes of Lambert on normals with a basis fit of what Lambert leaves (see models.py)."""
import os, sys
import numpy as np
from models import load, ps, ptm, hsh, linear, fit_basis, score, MODELS


def lamb_plus(basis, ridge_basis, ridge_lamb=1e-6):
    """per pixel: a max(0, n.l) + sum c_k b_k(l), a and c by least squares with a ridge on the basis' terms"""
    def f(D, L, k, N, rho):
        keep = [i for i in range(len(L)) if i != k]
        h, w = D.shape[1:]
        S = np.maximum(0, np.einsum('hwc,lc->lhw', N, L)).reshape(len(L), -1)  # lamps x pixels
        B = basis(L)  # lamps x t
        t = B.shape[1]
        I = D[keep].reshape(len(keep), -1)
        # per-pixel design [S_l, B_l]
        X = np.concatenate([S[keep].T[:, :, None], np.broadcast_to(B[keep], (S.shape[1],) + B[keep].shape)], 2)
        A = np.einsum('pli,plj->pij', X, X)
        tr = np.trace(A, axis1=1, axis2=2)[:, None] / (t + 1)
        reg = np.concatenate([[ridge_lamb], np.full(t, ridge_basis)])
        A += tr[:, :, None] * np.diag(reg)[None]
        b = np.einsum('pli,lp->pi', X, I)
        C = np.linalg.solve(A, b[..., None])[..., 0]
        x = np.concatenate([S[k][:, None], np.broadcast_to(B[k], (S.shape[1], t))], 1)
        return np.maximum((C * x).sum(1), 0).reshape(h, w)
    return f


def geo(f1, f2, a=0.5):
    def f(D, L, k, N, rho):
        p, q = f1(D, L, k, N, rho), f2(D, L, k, N, rho)
        return np.exp(a * np.log(np.maximum(p, 1e-6)) + (1 - a) * np.log(np.maximum(q, 1e-6)))
    return f


M2 = {
    'lambert': MODELS['lambert'],
    'ptm(6)': MODELS['ptm(6)'],
    'lamb+const': lamb_plus(lambda L: np.ones((len(L), 1)), 1e-3),
    'lamb+lin r.01': lamb_plus(linear, 1e-2),
    'lamb+lin r.1': lamb_plus(linear, 1e-1),
    'lamb+ptm r.01': lamb_plus(ptm, 1e-2),
    'lamb+ptm r.1': lamb_plus(ptm, 1e-1),
    'lamb+ptm r1': lamb_plus(ptm, 1.0),
    'lamb+hsh2 r.1': lamb_plus(lambda L: hsh(L, 2), 1e-1),
    'geo(lamb,ptm)': geo(MODELS['lambert'], MODELS['ptm(6)']),
}

if __name__ == '__main__':
    rows = {m: [] for m in M2}; cols = []
    for s in sys.argv[1:]:
        D, L, mask = load(s)
        for k in range(len(L)):
            keep = [i for i in range(len(L)) if i != k]
            N, rho = ps(D[keep], L[keep])
            cols.append('%s/%d' % (os.path.basename(s.rstrip('/')), k))
            for m, f in M2.items():
                rows[m].append(score(f(D, L, k, N, rho), D, k, mask))
    print('%-14s %s  mean' % ('model', ' '.join('%8s' % c for c in cols)))
    for m, v in rows.items():
        print('%-14s %s  %.4f' % (m, ' '.join('%8.4f' % x for x in v), np.mean(v)))
