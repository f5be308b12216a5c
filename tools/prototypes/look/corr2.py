import sys, os, json
import numpy as np, cv2
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__))); sys.path.insert(0, os.environ.get('LOOK_PY_DIR', '../shared/tools'))
import proto as P, look as LK
from corr import masked_blur, coarse_normals, lobe

def albedo(I, n, m, dirs, tau=0.15):
    c = np.stack([np.maximum((n * d).sum(-1), 0) for d in dirs])
    r = np.where(c[..., None] > tau, I / np.maximum(c, 1e-3)[..., None], np.nan)
    with np.errstate(all='ignore'):
        rho = np.nanmedian(r, 0)
    bad = ~np.isfinite(rho).all(-1)
    rho[bad] = 0
    return rho, c

def fit_spec(I, n, m, dirs, rho, c, alphas=(4, 8, 16, 32, 64, 128), lam=0.05):
    g = I.mean(-1); res = np.maximum(g - rho.mean(-1)[None] * c, 0)
    best = None
    for a in alphas:
        s = np.stack([lobe(n, d, a) for d in dirs])
        k = (res * s).sum(0) / ((s * s).sum(0) + lam)
        err = (((res - k[None] * s) ** 2).sum(0) * m).sum()
        if best is None or err < best[0]: best = (err, a, k)
    _, a, k = best
    return masked_blur(k, m, 2.0) * m, a

def run(dst, src, ndst, nsrc, tdir, ref, sigma=8.0, spec=True, dspec=True, tag='', shadow_spec=True, dsigma=0):
    D, dl, _ = P.load_set(dst); S, sl, _ = P.load_set(src)
    nd, md = P.normals(ndst); ns, ms = P.normals(nsrc)
    mp = LK.read_pfm(os.path.join(tdir, 'map.pfm'))
    ok = mp[..., 0] >= 0
    xi = np.clip(np.rint(mp[..., 0]).astype(int), 0, S.shape[2] - 1); yi = np.clip(np.rint(mp[..., 1]).astype(int), 0, S.shape[1] - 1)
    rd, cd = albedo(D, nd, md, dl)
    kd, ad = fit_spec(D, nd, md, dl, rd, cd)
    rs0, cs0 = albedo(S, ns, ms, sl)
    ks, as_ = fit_spec(S, ns, ms, sl, rs0, cs0)
    specS = np.stack([ks * lobe(ns, d, as_) for d in sl])
    Sd = np.maximum(S - specS[..., None], 0)
    rs, _ = albedo(Sd, coarse_normals(ns, ms, sigma), ms, sl)   # relief of the source kept as texture
    print('alpha dst %d k %.4f  src %d k %.4f' % (ad, np.median(kd[md]), as_, np.median(ks[ms])))
    specD = np.stack([kd * lobe(nd, d, ad) for d in dl]) if dspec else 0 * D[..., 0]
    Dd = np.maximum(D - specD[..., None], 0)
    rdc, _ = albedo(Dd, coarse_normals(nd, md, dsigma), md, dl) if dsigma else (rd, None)
    gd = np.maximum(rdc.mean(-1), 1e-3)
    shade = Dd.mean(-1) / gd[None]         # L,H,W : E c_l v_l at p (destination's own)
    R = shade[..., None] * rs[yi, xi][None]
    if spec:
        vis = np.clip(shade / np.maximum(cd, 1e-3), 0, 1) if shadow_spec else 1
        R = R + (vis * np.stack([ks[yi, xi] * lobe(nd, d, as_) for d in dl]))[..., None]
    R = np.where((ok & md)[None, ..., None], R, D)
    out = os.path.join(os.environ.get('LOOK_OUT', 'look-out'), os.path.basename(tdir) + '-c2' + tag)
    P.write_out(out, R, np.median(R, 0), tdir)
    r = LK.look(out, ref, src)
    print(os.path.basename(out), 'shading %.4f texture %.3f' % (r['shading_mean'], r['texture_corr']))
    return r
