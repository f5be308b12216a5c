import sys, os, json
import numpy as np, cv2
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__))); sys.path.insert(0, os.environ.get('LOOK_PY_DIR', '../shared/tools'))
import proto as P, look as LK

def masked_blur(a, m, s):
    if s <= 0: return a
    w = cv2.GaussianBlur(m.astype(np.float32), (0, 0), s)
    if a.ndim == 3:
        b = np.stack([cv2.GaussianBlur((a[..., c] * m).astype(np.float32), (0, 0), s) for c in range(a.shape[2])], -1)
        return b / np.maximum(w, 1e-6)[..., None]
    return cv2.GaussianBlur((a * m).astype(np.float32), (0, 0), s) / np.maximum(w, 1e-6)

def coarse_normals(n, m, s):
    if s <= 0: return n
    b = masked_blur(n, m, s)
    return b / np.maximum(np.linalg.norm(b, axis=-1, keepdims=True), 1e-6)

def fit(I, n, m, dirs, alphas=(4, 8, 16, 32, 64, 128), lam=0.05):
    """per pixel diffuse albedo rho (H,W,3), spec k (H,W), global alpha"""
    L = len(I)
    c = np.stack([np.maximum((n * d).sum(-1), 0) for d in dirs])  # L,H,W
    g = I.mean(-1)
    ratio = np.where(c[..., None] > 0.1, I / np.maximum(c, 1e-3)[..., None], np.nan)
    rho = np.nanmedian(ratio, 0)
    rho = np.where(np.isfinite(rho), rho, 0)
    res = g - rho.mean(-1)[None] * c
    best = None
    v = np.array([0, 0, 1.0])
    for a in alphas:
        s = np.stack([np.maximum((n * ((d + v) / np.linalg.norm(d + v))).sum(-1), 0) ** a for d in dirs]) * (c > 0)
        k = np.maximum((np.maximum(res, 0) * s).sum(0) / ((s * s).sum(0) + lam), 0)
        err = (((res - k[None] * s) ** 2).sum(0) * m).sum()
        if best is None or err < best[0]: best = (err, a, k)
    _, a, k = best
    k = masked_blur(k, m, 2.0) * m
    return rho, k, a

def lobe(n, d, a):
    v = np.array([0, 0, 1.0]); h = (d + v) / np.linalg.norm(d + v)
    return np.maximum((n * h).sum(-1), 0) ** a * ((n * d).sum(-1) > 0)

def run(dst, src, ndst, nsrc, tdir, ref, sigma=0.0, spec=True, tag='', dspec=None, lam=0.05):
    if dspec is None: dspec = spec
    D, dl, _ = P.load_set(dst); S, sl, _ = P.load_set(src)
    nd, md = P.normals(ndst); ns, ms = P.normals(nsrc)
    mp = LK.read_pfm(os.path.join(tdir, 'map.pfm'))
    ok = mp[..., 0] >= 0
    xi = np.clip(np.rint(mp[..., 0]).astype(int), 0, S.shape[2] - 1); yi = np.clip(np.rint(mp[..., 1]).astype(int), 0, S.shape[1] - 1)
    rd, kd, ad = fit(D, nd, md, dl, lam=lam); rs, ks, as_ = fit(S, ns, ms, sl, lam=lam)
    print('alpha dst', ad, 'k med', np.median(kd[md]), ' src', as_, np.median(ks[ms]))
    specd = np.stack([kd * lobe(nd, d, ad) for d in dl]) if dspec else 0 * D[..., 0]
    Ddiff = np.maximum(D - specd[..., None], 1e-4)
    Dr = Ddiff / np.maximum(np.median(Ddiff, 0), 1e-4)
    # texture: source diffuse median, coarse shading moved from source normals to destination normals
    specs = np.stack([ks * lobe(ns, d, as_) for d in sl]) if spec else 0 * S[..., 0]
    Sdiff_med = np.median(np.maximum(S - specs[..., None], 0), 0)
    cd = coarse_normals(nd, md, sigma); cs = coarse_normals(ns, ms, sigma)
    shm = lambda n, dirs: np.median(np.stack([np.maximum((n * d).sum(-1), 0) for d in dirs]), 0)
    shd = shm(cd, dl); shs = shm(cs, sl)[yi, xi]
    tex = Sdiff_med[yi, xi] * np.clip((shd + 0.05) / (shs + 0.05), 0.2, 5)[..., None]
    R = Dr * tex[None]
    if spec:
        R = R + np.stack([ks[yi, xi] * lobe(nd, d, as_) for d in dl])[..., None]
    R = np.where(ok[None, ..., None], R, D)
    out = os.path.join(os.environ.get('LOOK_OUT', 'look-out'), os.path.basename(tdir) + '-corr' + tag)
    P.write_out(out, R, np.median(R, 0), tdir)
    r = LK.look(out, ref, src)
    print(os.path.basename(out), 'shading %.4f texture %.3f' % (r['shading_mean'], r['texture_corr']))

if __name__ == '__main__':
    a = sys.argv[1:]
    for sigma in (4,):
        for spec, dspec in ((False, False), (True, False), (True, True)):
            run(*a[:6], sigma=sigma, spec=spec, dspec=dspec, tag='-s%g%s%s' % (sigma, '-spec' if spec else '', '-dspec' if dspec else ''))
