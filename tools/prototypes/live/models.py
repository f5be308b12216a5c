#!/usr/bin/python3
"""Issue 40, item 2: which relightable model predicts a lamp the rig never
captured. Per real set (DiLiGenT layout) and lamp K: fit each model to the
other lamps' photos (grey), predict lamp K, and measure as livelook.py's
score does: |log(P_K / Dm) - log(D_K / Dm)| less the median difference, over
the mask where D_K is lit (> 5 % of the pixel's brightest). Prototype, not
product code: numpy + opencv (Debian's python3-numpy, python3-opencv).

  models.py SET [SET ...]      prints a table: model x (set, lamp) and the mean
"""
import os, sys
import numpy as np
import cv2


def load(s):
    names = open(os.path.join(s, 'filenames.txt')).read().split()
    D = np.stack([cv2.imread(os.path.join(s, n), cv2.IMREAD_UNCHANGED).astype(np.float64).mean(2) for n in names])
    D /= 255.0
    L = np.loadtxt(os.path.join(s, 'light_directions.txt'))
    mask = cv2.imread(os.path.join(s, 'mask.png'), cv2.IMREAD_GRAYSCALE) > 127
    return D, L, mask


def ps(D, L):
    """Lambert photometric stereo with the darkest/brightest samples of each pixel left out."""
    n, h, w = D.shape
    I = D.reshape(n, -1)
    G = np.linalg.lstsq(L, I, rcond=None)[0]
    # one reweighted pass: drop shadows (below 0.3 of the fit) and highlights (above 2x)
    pred = L @ G
    wgt = ((I > 0.3 * pred) & (I < 2 * pred + 0.02)).astype(np.float64)
    for p in range(I.shape[1]):
        pass
    # solve per pixel with weights (vectorised normal equations)
    A = np.einsum('li,lj,lp->pij', L, L, wgt) + 1e-6 * np.eye(3)
    b = np.einsum('li,lp->pi', L, wgt * I)
    G = np.linalg.solve(A, b[..., None])[..., 0].T
    rho = np.linalg.norm(G, axis=0)
    N = G / np.maximum(rho, 1e-9)
    return N.T.reshape(h, w, 3), rho.reshape(h, w)


def hsh(L, order):
    l = L / np.linalg.norm(L, axis=1, keepdims=True)
    phi = np.arctan2(l[:, 1], l[:, 0])
    th = np.arccos(np.clip(l[:, 2], 0, 1))
    c, s = np.cos(phi), np.sin(phi)
    ct = np.cos(th)
    x = 2 * ct - 1   # shifted hemisphere
    sq = np.sqrt(np.maximum(ct - ct * ct, 0))
    pi = np.pi
    b = [1 / np.sqrt(2 * pi) * np.ones_like(phi)]
    if order > 1:  # in the order RTI files use (the numbers do not depend on it)
        b += [np.sqrt(6 / pi) * c * sq, np.sqrt(3 / (2 * pi)) * (-1 + 2 * ct), np.sqrt(6 / pi) * s * sq]
    if order > 2:
        b += [np.sqrt(30 / pi) * np.cos(2 * phi) * (-ct + ct * ct),
              np.sqrt(30 / pi) * c * sq * (-1 + 2 * ct),
              np.sqrt(5 / (2 * pi)) * (1 - 6 * ct + 6 * ct * ct),
              np.sqrt(30 / pi) * s * sq * (-1 + 2 * ct),
              np.sqrt(30 / pi) * np.sin(2 * phi) * (-ct + ct * ct)]
    return np.stack(b, 1)


def ptm(L):
    u, v = L[:, 0], L[:, 1]
    return np.stack([u * u, v * v, u * v, u, v, np.ones_like(u)], 1)


def linear(L):
    return np.concatenate([L, np.ones((len(L), 1))], 1)


def fit_basis(B, I, ridge):
    A = B.T @ B
    A += ridge * np.trace(A) / len(A) * np.eye(len(A))
    return np.linalg.solve(A, B.T @ I)


def predict_basis(basis, ridge):
    def f(D, L, k, N, rho):
        keep = [i for i in range(len(L)) if i != k]
        B = basis(L[keep]); C = fit_basis(B, D[keep].reshape(len(keep), -1), ridge)
        return (basis(L[k:k + 1]) @ C).reshape(D.shape[1:])
    return f


def lambert(D, L, k, N, rho):
    return rho * np.maximum(0, N @ L[k])


def ratio_model(kernel_deg, base='lambert', fill=1.0):
    """Lambert on normals (or a basis fit) times the per-pixel ratio of the
    photos to it, interpolated over the lamps' directions by a Gaussian kernel."""
    def f(D, L, k, N, rho):
        keep = [i for i in range(len(L)) if i != k]
        if base == 'lambert':
            M = np.stack([rho * np.maximum(0, N @ L[i]) for i in range(len(L))])
        else:
            B = base(L[keep]); C = fit_basis(B, D[keep].reshape(len(keep), -1), 1e-3)
            M = (base(L) @ C).reshape(D.shape)
        e = 0.02
        R = (D[keep] + e) / (M[keep] + e)
        ang = np.arccos(np.clip(L[keep] @ L[k], -1, 1))
        w = np.exp(-0.5 * (ang / np.radians(kernel_deg)) ** 2)
        w /= w.sum()
        r = np.tensordot(w, np.log(R), 1)
        return np.maximum((M[k] + e) * np.exp(r) - e, 0)
    return f


def nadaraya(kernel_deg):
    def f(D, L, k, N, rho):
        keep = [i for i in range(len(L)) if i != k]
        ang = np.arccos(np.clip(L[keep] @ L[k], -1, 1))
        w = np.exp(-0.5 * (ang / np.radians(kernel_deg)) ** 2); w /= w.sum()
        return np.tensordot(w, D[keep], 1)
    return f


def rbf(kernel_deg, ridge=1e-3):
    """radial basis over the captured lamps' directions: Gaussian kernels at each kept lamp plus a linear term"""
    def f(D, L, k, N, rho):
        keep = [i for i in range(len(L)) if i != k]
        Lk = L[keep]
        s = np.radians(kernel_deg)
        def basis(X):
            ang = np.arccos(np.clip(X @ Lk.T, -1, 1))
            return np.concatenate([np.exp(-0.5 * (ang / s) ** 2), linear(X)], 1)
        B = basis(Lk)
        C = fit_basis(B, D[keep].reshape(len(keep), -1), ridge)
        return (basis(L[k:k + 1]) @ C).reshape(D.shape[1:])
    return f


def score(P, D, k, mask):
    keep = [i for i in range(len(D)) if i != k]
    Dm = np.median(D[keep], 0)
    lit = mask & (D[k] > 0.05 * D.max(0)) & (P > 1e-6) & (Dm > 1e-6)
    a = np.log(P[lit] / Dm[lit]); b = np.log(D[k][lit] / Dm[lit])
    d = np.abs((a - np.median(a)) - (b - np.median(b)))
    return d.mean()


MODELS = {
    'lambert': lambert,
    'linear(4)': predict_basis(linear, 1e-3),
    'ptm(6)': predict_basis(ptm, 1e-3),
    'hsh2(4)': predict_basis(lambda L: hsh(L, 2), 1e-3),
    'hsh3(9)': predict_basis(lambda L: hsh(L, 3), 1e-3),
    'hsh3 r.05': predict_basis(lambda L: hsh(L, 3), 5e-2),
    'rbf10+lin': rbf(10),
    'rbf20+lin': rbf(20),
    'nw10': nadaraya(10),
    'lamb*ratio10': ratio_model(10),
    'lamb*ratio20': ratio_model(20),
    'lamb*ratio40': ratio_model(40),
    'ptm*ratio10': ratio_model(10, ptm),
    'ptm*ratio20': ratio_model(20, ptm),
    'hsh2*ratio15': ratio_model(15, lambda L: hsh(L, 2)),
}

if __name__ == '__main__':
    sets = sys.argv[1:]
    lamps = [int(x) for x in os.environ.get('LAMPS', '').split(',') if x] or None
    rows = {m: [] for m in MODELS}
    cols = []
    for s in sets:
        D, L, mask = load(s)
        for k in (lamps or range(len(L))):
            keep = [i for i in range(len(L)) if i != k]
            N, rho = ps(D[keep], L[keep])
            cols.append('%s/%d' % (os.path.basename(s.rstrip('/')), k))
            for m, f in MODELS.items():
                rows[m].append(score(f(D, L, k, N, rho), D, k, mask))
    print('%-14s %s  mean' % ('model', ' '.join('%8s' % c for c in cols)))
    for m, v in rows.items():
        print('%-14s %s  %.4f' % (m, ' '.join('%8.4f' % x for x in v), np.mean(v)))
