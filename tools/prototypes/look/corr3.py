import sys, os
import numpy as np, cv2
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__))); sys.path.insert(0, os.environ.get('LOOK_PY_DIR', '../shared/tools'))
import proto as P, look as LK
from corr import masked_blur, lobe
from corr2 import albedo, fit_spec

def run(dst, src, ndst, nsrc, tdir, ref, sigma=8.0, spec=True, dspec=True, tag='', floor=0.02):
    D, dl, _ = P.load_set(dst); S, sl, _ = P.load_set(src)
    nd, md = P.normals(ndst); ns, ms = P.normals(nsrc)
    mp = LK.read_pfm(os.path.join(tdir, 'map.pfm'))
    ok = mp[..., 0] >= 0
    xi = np.clip(np.rint(mp[..., 0]).astype(int), 0, S.shape[2] - 1); yi = np.clip(np.rint(mp[..., 1]).astype(int), 0, S.shape[1] - 1)
    rd, cd = albedo(D, nd, md, dl); kd, ad = fit_spec(D, nd, md, dl, rd, cd)
    rs, cs = albedo(S, ns, ms, sl); ks, as_ = fit_spec(S, ns, ms, sl, rs, cs)
    specS = np.stack([ks * lobe(ns, d, as_) for d in sl])
    specD = np.stack([kd * lobe(nd, d, ad) for d in dl]) if dspec else 0 * D[..., 0]
    Sd = np.maximum(S - specS[..., None], 0); Dd = np.maximum(D - specD[..., None], 0)
    Sdm = np.median(Sd, 0).mean(-1); Ddm = np.median(Dd, 0).mean(-1)
    Ms = masked_blur(Sdm / np.maximum(rs.mean(-1), 1e-3), ms, sigma)
    Md = masked_blur(Ddm / np.maximum(rd.mean(-1), 1e-3), md, sigma)
    T = np.median(Sd, 0)[yi, xi] * (Md / np.maximum(Ms[yi, xi], floor))[..., None]
    fl = floor * np.percentile(Ddm[md], 90)
    R = T[None] * (Dd.mean(-1) / np.maximum(Ddm, fl)[None])[..., None]
    if spec:
        vis = np.clip(Dd.mean(-1) / np.maximum(rd.mean(-1) * cd, 1e-3), 0, 1)
        R = R + (vis * np.stack([ks[yi, xi] * lobe(nd, d, as_) for d in dl]))[..., None]
    R = np.where((ok & md)[None, ..., None], R, D)
    out = os.path.join(os.environ.get('LOOK_OUT', 'look-out'), os.path.basename(tdir) + '-c3' + tag)
    P.write_out(out, R, np.median(R, 0), tdir)
    r = LK.look(out, ref, src)
    print(os.path.basename(out), 'shading %.4f texture %.3f' % (r['shading_mean'], r['texture_corr']))
    return r
