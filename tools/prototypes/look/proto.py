import json, os, sys, glob
import numpy as np, cv2
sys.path.insert(0, os.environ.get('LOOK_PY_DIR', '../shared/tools'))
import look as LK

def load_set(folder):
    if os.path.exists(os.path.join(folder, 'filenames.txt')):
        names = open(os.path.join(folder, 'filenames.txt')).read().split()
        dirs = np.loadtxt(os.path.join(folder, 'light_directions.txt'))
        pos = None
        amb = None
    else:
        j = json.load(open(os.path.join(folder, 'set.json')))
        names = [e['file'] for e in j['images']]
        dirs = np.array([l['direction'] for l in j['lights']])
        pos = np.array([l['position_m'] for l in j['lights']])
        amb = os.path.join(folder, 'ambient.png') if os.path.exists(os.path.join(folder, 'ambient.png')) else None
    ims = []
    for n in names:
        im = cv2.imread(os.path.join(folder, n), cv2.IMREAD_UNCHANGED).astype(np.float32)
        im /= 65535.0 if im.max() > 255 else 255.0
        ims.append(im)
    ims = np.stack(ims)
    if amb:
        a = cv2.imread(amb, cv2.IMREAD_UNCHANGED).astype(np.float32) / 65535.0
        ims = np.maximum(ims - a, 0)
    return ims, dirs, pos

def read_pfm3(p):
    return LK.read_pfm(p)

def normals(nd):
    n = read_pfm3(os.path.join(nd, 'normals.pfm'))  # stored x,y,z in R,G,B; read_pfm returns file order
    m = cv2.imread(os.path.join(nd, 'mask.png'), 0) > 127
    return n, m

def write_out(out, R, med, mp_dir):
    os.makedirs(out, exist_ok=True)
    for l in range(len(R)):
        cv2.imwrite(os.path.join(out, 'result_light_%02d.png' % l), np.clip(R[l] * 65535, 0, 65535).astype(np.uint16))
    cv2.imwrite(os.path.join(out, 'result_median.png'), np.clip(med * 65535, 0, 65535).astype(np.uint16))
    os.system('cp %s/map.pfm %s/' % (mp_dir, out))
