import sys, os, json
import numpy as np, cv2
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__))); sys.path.insert(0, os.environ.get('LOOK_PY_DIR', '../shared/tools'))
import proto as P, look as LK
dst, src, ndst, nsrc, tdir, ref = sys.argv[1:7]
D, dl, _ = P.load_set(dst); S, sl, _ = P.load_set(src)
nd, md = P.normals(ndst); ns, ms = P.normals(nsrc)
mp = LK.read_pfm(os.path.join(tdir, 'map.pfm'))
ok = mp[..., 0] >= 0
xi = np.clip(np.rint(mp[..., 0]).astype(int), 0, S.shape[2] - 1); yi = np.clip(np.rint(mp[..., 1]).astype(int), 0, S.shape[1] - 1)
Sw = S[:, yi, xi]  # L,H,W,3
nsw = ns[yi, xi]
Dmed = np.median(D, 0); Smedw = np.median(S, 0)[yi, xi]
shd = np.stack([np.maximum((nd * l).sum(-1), 0) for l in dl])  # L,H,W
shs = np.stack([np.maximum((nsw * l).sum(-1), 0) for l in sl])
def finish(name, R):
    R = np.where(ok[None, ..., None], R, D)
    med = np.median(R, 0)
    out = os.path.join(os.environ.get('LOOK_OUT', 'look-out'), os.path.basename(tdir) + '-' + name)
    P.write_out(out, R, med, tdir)
    r = LK.look(out, ref, src)
    print(name, 'shading %.4f texture %.3f' % (r['shading_mean'], r['texture_corr']))
finish('copy', Sw)
eps = 1e-3
finish('A-dstratio', Smedw[None] * D / np.maximum(Dmed[None], eps))
for e in (0.05, 0.1, 0.2):
    ratio = np.clip((shd + e) / (shs + e), 0.25, 4)
    finish('B-lambert%.2f' % e, Sw * ratio[..., None])
alb = Smedw / np.maximum(np.median(shs, 0), 0.05)[..., None]
finish('C-model', alb[None] * shd[..., None])
