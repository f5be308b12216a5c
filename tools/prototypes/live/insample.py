#!/usr/bin/python3
"""The models at a captured lamp (fitted on all lamps, predicting one of them):
what the live look at a captured lamp inherits against the still look, which
uses that lamp's photo exactly. Also leave-one-out with a narrow exact
correction (a Gaussian radial basis of sigma degrees through the lamps' residual ratios)."""
import os, sys
import numpy as np
from models import load, ps, ptm, hsh, fit_basis, score, MODELS, ratio_model
from interp import base_times_rbf


def insample(f):
    def g(D, L, k, N, rho):
        # fit on all lamps: pass k = -1 as "none left out" by duplicating the set
        D2 = np.concatenate([D, D[k:k + 1]]); L2 = np.concatenate([L, L[k:k + 1]])
        return f(D2, L2, len(L), N, rho)
    return g


M = {
    'ptm(6)': MODELS['ptm(6)'],
    'hsh3 r.05': MODELS['hsh3 r.05'],
    'ptm*ratio10': MODELS['ptm*ratio10'],
    'ptm*rbf3': base_times_rbf(ptm, 3),
    'ptm*rbf4': base_times_rbf(ptm, 4),
    'ptm*rbf5': base_times_rbf(ptm, 5),
    'hsh3r.05*rbf4': base_times_rbf(lambda L: hsh(L, 3), 4, 1e-3, 5e-2),
}

if __name__ == '__main__':
    for label, wrap in (('leave-one-out', lambda f: f), ('in-sample', insample)):
        rows = {m: [] for m in M}; cols = []
        for s in sys.argv[1:]:
            D, L, mask = load(s)
            N, rho = ps(D, L)
            for k in range(len(L)):
                cols.append('%s/%d' % (os.path.basename(s.rstrip('/')), k))
                for m, f in M.items():
                    P = wrap(f)(D, L, k, N, rho)
                    rows[m].append(score(P, D, k, mask))
        print(label)
        print('%-14s %s  mean' % ('model', ' '.join('%8s' % c for c in cols)))
        for m, v in rows.items():
            print('%-14s %s  %.4f' % (m, ' '.join('%8.4f' % x for x in v), np.mean(v)))
