import sys, numpy as np, cv2
# crop.py out.png mask.png scale img...  crops all to mask bbox (+8px), tonemaps jointly, upscales
m = cv2.imread(sys.argv[2], 0) > 127
ys, xs = np.nonzero(m); y0, y1, x0, x1 = max(ys.min()-8,0), ys.max()+9, max(xs.min()-8,0), xs.max()+9
sc = float(sys.argv[3]); ims = []
for p in sys.argv[4:]:
    im = cv2.imread(p, cv2.IMREAD_UNCHANGED).astype(np.float32); im /= 65535.0 if im.max() > 255 else 255.0
    ims.append(im[y0:y1, x0:x1])
s = max(np.percentile(np.concatenate([i.ravel() for i in ims]), 99.5), 1e-6)
out = [cv2.resize(np.clip((np.clip(i / s, 0, 1) ** (1 / 2.2)) * 255, 0, 255).astype(np.uint8), None, fx=sc, fy=sc, interpolation=cv2.INTER_NEAREST) for i in ims]
out = [cv2.copyMakeBorder(o, 0, 0, 0, 4, cv2.BORDER_CONSTANT, value=(255,255,255)) for o in out]
cv2.imwrite(sys.argv[1], np.hstack(out))
