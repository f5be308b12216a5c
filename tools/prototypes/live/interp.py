#!/usr/bin/python3
"""A basis fit times its residual ratio interpolated exactly through the
captured lamps (Gaussian radial basis over the lamps' directions, in log):
exact at a captured lamp, the basis alone far from all of them."""
import os, sys
import numpy as np
from models import load, ps, ptm, hsh, fit_basis, score, MODELS


def rbf_weights(Lk, l, sigma_deg, lam):
    s = np.radians(sigma_deg)
    K = np.exp(-0.5 * (np.arccos(np.clip(Lk @ Lk.T, -1, 1)) / s) ** 2)
    k = np.exp(-0.5 * (np.arccos(np.clip(Lk @ l, -1, 1)) / s) ** 2)
    return np.linalg.solve(K + lam * np.eye(len(Lk)), k)


def base_times_rbf(base, sigma_deg, lam=1e-3, ridge=1e-3, e=0.02):
    def f(D, L, k, N, rho):
        keep = [i for i in range(len(L)) if i != k]
        if base == 'lambert':
            M = np.stack([rho * np.maximum(0, N @ L[i]) for i in range(len(L))])
        else:
            B = base(L[keep]); C = fit_basis(B, D[keep].reshape(len(keep), -1), ridge)
            M = (base(L) @ C).reshape(D.shape)
        r = np.log((D[keep] + e) / (np.maximum(M[keep], 0) + e))
        w = rbf_weights(L[keep], L[k], sigma_deg, lam)
        return np.maximum((np.maximum(M[k], 0) + e) * np.exp(np.tensordot(w, r, 1)) - e, 0)
    return f


M3 = {
    'ptm(6)': MODELS['ptm(6)'],
    'ptm*rbf8': base_times_rbf(ptm, 8),
    'ptm*rbf12': base_times_rbf(ptm, 12),
    'ptm*rbf12 l.1': base_times_rbf(ptm, 12, 0.1),
    'ptm*rbf20': base_times_rbf(ptm, 20),
    'ptm*rbf20 l.1': base_times_rbf(ptm, 20, 0.1),
    'hsh2*rbf12': base_times_rbf(lambda L: hsh(L, 2), 12),
    'hsh3r.05*rbf12': base_times_rbf(lambda L: hsh(L, 3), 12, 1e-3, 5e-2),
    'lamb*rbf12': base_times_rbf('lambert', 12),
    'lamb*rbf8': base_times_rbf('lambert', 8),
}

if __name__ == '__main__':
    rows = {m: [] for m in M3}; cols = []
    for s in sys.argv[1:]:
        D, L, mask = load(s)
        for k in range(len(L)):
            keep = [i for i in range(len(L)) if i != k]
            N, rho = ps(D[keep], L[keep])
            cols.append('%s/%d' % (os.path.basename(s.rstrip('/')), k))
            for m, f in M3.items():
                rows[m].append(score(f(D, L, k, N, rho), D, k, mask))
    print('%-14s %s  mean' % ('model', ' '.join('%8s' % c for c in cols)))
    for m, v in rows.items():
        print('%-14s %s  %.4f' % (m, ' '.join('%8.4f' % x for x in v), np.mean(v)))
