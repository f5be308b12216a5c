#!/usr/bin/python3
"""The chosen model: a smooth basis fit (HSH order 3, ridge 0.05 of the
normal equations' mean diagonal) plus its residual at the captured lamps
interpolated additively by a narrow Gaussian radial basis (sigma degrees) over
the lamps' directions, so the model is exact at a captured lamp and the
smooth fit alone far from all of them."""
import os, sys
import numpy as np
from models import load, ps, ptm, hsh, fit_basis, score, MODELS
from interp import rbf_weights


def basis_plus_rbf(base, ridge, sigma_deg, lam=1e-3):
    def f(D, L, k, N, rho, keep=None):
        keep = keep if keep is not None else [i for i in range(len(L)) if i != k]
        I = D[keep].reshape(len(keep), -1)
        C = fit_basis(base(L[keep]), I, ridge)
        res = I - base(L[keep]) @ C
        w = rbf_weights(L[keep], L[k], sigma_deg, lam)
        return np.maximum(base(L[k:k + 1]) @ C + w @ res, 0).reshape(D.shape[1:])
    return f


M = {
    'hsh3 r.05': MODELS['hsh3 r.05'],
    'ptm(6)': MODELS['ptm(6)'],
    'hsh3r.05+rbf2': basis_plus_rbf(lambda L: hsh(L, 3), 5e-2, 2),
    'hsh3r.05+rbf3': basis_plus_rbf(lambda L: hsh(L, 3), 5e-2, 3),
    'hsh3r.05+rbf5': basis_plus_rbf(lambda L: hsh(L, 3), 5e-2, 5),
    'hsh3r.05+rbf8': basis_plus_rbf(lambda L: hsh(L, 3), 5e-2, 8),
    'hsh3r.05+rbf12': basis_plus_rbf(lambda L: hsh(L, 3), 5e-2, 12),
    'ptm+rbf3': basis_plus_rbf(ptm, 1e-3, 3),
    'hsh2r.01+rbf3': basis_plus_rbf(lambda L: hsh(L, 2), 1e-2, 3),
}

if __name__ == '__main__':
    rows = {m: [] for m in M}; ins = {m: [] for m in M}; cols = []
    for s in sys.argv[1:]:
        D, L, mask = load(s)
        for k in range(len(L)):
            cols.append('%s/%d' % (os.path.basename(s.rstrip('/')), k))
            for m, f in M.items():
                rows[m].append(score(f(D, L, k, None, None), D, k, mask))
                if 'rbf' not in m:
                    continue
                ins[m].append(score(f(D, L, k, None, None, keep=list(range(len(L)))), D, k, mask))
    print('%-14s %s  mean  in-sample-max' % ('model', ' '.join('%8s' % c for c in cols)))
    for m, v in rows.items():
        print('%-14s %s  %.4f  %s' % (m, ' '.join('%8.4f' % x for x in v), np.mean(v),
                                      '%.4f' % max(ins[m]) if ins[m] else '-'))
