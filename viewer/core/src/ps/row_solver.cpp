// Photometric stereo's row solver (see row_solver.hpp).
//
// Speed: every full-resolution pass works on one image row at a time with
// structure-of-arrays buffers (per lamp: B, G, R, grey), so the inner loops run
// over pixels and vectorise. The distant model multiplies by one
// pseudo-inverse per "lamps kept" pattern (computed once, at most 2^n); the
// near model forms the 3x3 normal equations per pixel from its own light
// vectors.
#include "row_solver.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdio>
#include <cstdint>
#include <vector>

#include <opencv2/core/hal/hal.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

// "No dependence between the iterations": GCC vectorises the per-pixel lane
// loops below without a runtime alias check. (Clang -- the fuzz build -- has
// no such hint that it does not turn into an error when a sanitizer keeps it
// from vectorising; it relies on the __restrict pointers.)
#if defined(__clang__)
#define VENEER_IVDEP
#else
#define VENEER_IVDEP _Pragma("GCC ivdep")
#endif

namespace veneer::ps::detail {

bool pattern_pinv(const std::vector<float>& dir, int n, uint32_t pattern, float* out) {
  double a[3][3] = {};
  for (int i = 0; i < n; ++i) {
    if (!(pattern >> i & 1u)) continue;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) a[r][c] += double(dir[i * 3 + r]) * dir[i * 3 + c];
  }
  cv::Matx33d A(&a[0][0]);
  cv::Matx31d w;
  cv::Matx33d u, vt;
  cv::SVD::compute(A, w, u, vt);
  if (w(0) <= 0 || w(2) < 1e-6 * w(0)) return false;
  cv::Matx33d inv = A.inv(cv::DECOMP_CHOLESKY);
  for (int i = 0; i < n; ++i) {
    bool kept = pattern >> i & 1u;
    for (int r = 0; r < 3; ++r) {
      double v = 0;
      if (kept)
        for (int c = 0; c < 3; ++c) v += inv(r, c) * dir[i * 3 + c];
      out[r * n + i] = static_cast<float>(v);
    }
  }
  return true;
}

namespace {

// The per-pixel normal equations A g = b of a run of `cap` pixels: the upper
// triangle of the symmetric 3x3 A and b, nine lanes of `cap` floats in `acc`
// (zeroed here), to which each sample adds weight w times its light vector e.
struct NormalEquations {
  float* __restrict a00;
  float* __restrict a01;
  float* __restrict a02;
  float* __restrict a11;
  float* __restrict a12;
  float* __restrict a22;
  float* __restrict b0;
  float* __restrict b1;
  float* __restrict b2;
  NormalEquations(std::vector<float>& acc, int cap)
      : a00(acc.data()), a01(a00 + cap), a02(a00 + 2 * cap), a11(a00 + 3 * cap), a12(a00 + 4 * cap),
        a22(a00 + 5 * cap), b0(a00 + 6 * cap), b1(a00 + 7 * cap), b2(a00 + 8 * cap) {
    std::fill(acc.begin(), acc.begin() + 9 * cap, 0.f);
  }
  // Pixel k's sample of weight w and weighted value wy = w * y under light e.
  __attribute__((always_inline)) void add(int k, float w, float wy, float ex, float ey, float ez) const {
    a00[k] += w * ex * ex;
    a01[k] += w * ex * ey;
    a02[k] += w * ex * ez;
    a11[k] += w * ey * ey;
    a12[k] += w * ey * ez;
    a22[k] += w * ez * ez;
    b0[k] += wy * ex;
    b1[k] += wy * ey;
    b2[k] += wy * ez;
  }
};

struct LoadArgs {
  const float* src;
  const float* amb;
  int step, count;
  float e0, e1, e2, satv;
  float *cb, *cg, *cr, *yy, *st, *M;
};

// `count` pixels from `src` (half floats, every `step`-th pixel) as float
// pixels side by side in `out`.
void widen_pixels(const cv::float16_t* src, int step, int count, float* out) {
  if (step == 1) {
    cv::hal::cvt16f32f(src, out, count * 3);
    return;
  }
  for (int k = 0; k < count; ++k)
    for (int c = 0; c < 3; ++c) out[k * 3 + c] = float(src[size_t(k) * step * 3 + c]);
}

// One lamp's row into structure-of-arrays form: ambient removed, divided by the
// lamp colour, grey, saturation flag; running maximum of grey.
template <int kStep, bool kAmb>
inline void load_light(const LoadArgs& a) {
  const float* __restrict src = a.src;
  const float* __restrict amb = a.amb;
  float* __restrict cb = a.cb;
  float* __restrict cg = a.cg;
  float* __restrict cr = a.cr;
  float* __restrict yy = a.yy;
  float* __restrict st = a.st;
  float* __restrict M = a.M;
  const int st3 = kStep > 0 ? kStep * 3 : a.step * 3;
  const float e0 = a.e0, e1 = a.e1, e2 = a.e2, satv = a.satv;
VENEER_IVDEP
  for (int k = 0; k < a.count; ++k) {
    const float v0 = src[k * st3], v1 = src[k * st3 + 1], v2 = src[k * st3 + 2];
    st[k] = float((v0 >= satv) | (v1 >= satv) | (v2 >= satv));
    float c0 = v0, c1 = v1, c2 = v2;
    if constexpr (kAmb) {
      c0 -= amb[k * st3];
      c1 -= amb[k * st3 + 1];
      c2 -= amb[k * st3 + 2];
    }
    c0 *= e0;
    c1 *= e1;
    c2 *= e2;
    cb[k] = c0;
    cg[k] = c1;
    cr[k] = c2;
    const float g = (c0 + c1 + c2) * (1.f / 3.f);
    yy[k] = g;
    M[k] = std::max(M[k], g);
  }
}

// Calls f(k, sh) for the pixels k < count with lamp i's shading sh = n . V_i
// (near: the pixel's own light vector, b.V) or n . l_i (distant), n the
// pixel's fitted normal (b.nx, b.ny, b.nz).
template <class F>
void for_each_shading(const Setup& s, const Scratch& b, int i, int count, F&& f) {
  const float* __restrict nx = b.nx.data();
  const float* __restrict ny = b.ny.data();
  const float* __restrict nz = b.nz.data();
  if (s.near) {
    const size_t cap = size_t(b.cap);
    const float* __restrict vx = b.V.data() + (size_t(i) * 3 + 0) * cap;
    const float* __restrict vy = b.V.data() + (size_t(i) * 3 + 1) * cap;
    const float* __restrict vz = b.V.data() + (size_t(i) * 3 + 2) * cap;
VENEER_IVDEP
    for (int k = 0; k < count; ++k) f(k, nx[k] * vx[k] + ny[k] * vy[k] + nz[k] * vz[k]);
  } else {
    const float lx = s.dir[i * 3], ly = s.dir[i * 3 + 1], lz = s.dir[i * 3 + 2];
VENEER_IVDEP
    for (int k = 0; k < count; ++k) f(k, nx[k] * lx + ny[k] * ly + nz[k] * lz);
  }
}


// Partial shadows (PsOptions::penumbra_fraction): per pixel with 5+ kept
// samples, the fits leaving out one sample each, from the normal equations
// (A - e e^T) g = b - y e, their residual over the rest being
// sum(y^2) - y^2 - g . (b - y e). The sample whose leaving out fits the rest
// best is marked in best_i (its lamp index; -1 = none) when the rest then fit
// 4x better than all together and it lies darker than the fit without it
// predicts by more than penumbra_fraction of the pixel's brightest sample; its
// pixel's K goes down by one. Returns how many pixels drop a sample.
int drop_penumbrae(const Setup& s, Scratch& b, int count, float* best_i) {
  const int n = s.n;
  const size_t cap = size_t(b.cap);
  int drops = 0;
  auto solve3 = [](const double a[6], const double r[3], double g[3]) {
    const double c00 = a[3] * a[5] - a[4] * a[4], c01 = a[2] * a[4] - a[1] * a[5], c02 = a[1] * a[4] - a[2] * a[3];
    const double c11 = a[0] * a[5] - a[2] * a[2], c12 = a[1] * a[2] - a[0] * a[4], c22 = a[0] * a[3] - a[1] * a[1];
    const double det = a[0] * c00 + a[1] * c01 + a[2] * c02;
    const double tr = (a[0] + a[3] + a[5]) / 3;
    if (!(tr > 0) || !(det > 1e-5 * tr * tr * tr)) return false;
    g[0] = (c00 * r[0] + c01 * r[1] + c02 * r[2]) / det;
    g[1] = (c01 * r[0] + c11 * r[1] + c12 * r[2]) / det;
    g[2] = (c02 * r[0] + c12 * r[1] + c22 * r[2]) / det;
    return true;
  };
  double e[kMaxNearLights][3], yv[kMaxNearLights];
  int lamp[kMaxNearLights];
  for (int k = 0; k < count; ++k) {
    if (!(b.K[k] >= 5.f) || !(b.a[k] > 0.f) || b.ok[k] == 0.f) continue;
    double a[6] = {}, r[3] = {}, syy = 0;
    int m = 0;
    for (int i = 0; i < n; ++i) {
      if (b.W[size_t(i) * cap + k] == 0.f) continue;
      double* ei = e[m];
      for (int c = 0; c < 3; ++c) ei[c] = s.near ? b.V[(size_t(i) * 3 + c) * cap + k] : s.dir[i * 3 + c];
      const double y = b.Y[size_t(i) * cap + k];
      a[0] += ei[0] * ei[0], a[1] += ei[0] * ei[1], a[2] += ei[0] * ei[2];
      a[3] += ei[1] * ei[1], a[4] += ei[1] * ei[2], a[5] += ei[2] * ei[2];
      r[0] += y * ei[0], r[1] += y * ei[1], r[2] += y * ei[2];
      syy += y * y;
      yv[m] = y;
      lamp[m++] = i;
    }
    double g[3];
    if (m < 5 || !solve3(a, r, g)) continue;
    const double all = syy - (g[0] * r[0] + g[1] * r[1] + g[2] * r[2]);
    double best = all, dark = 0;
    int pick = -1;
    for (int j = 0; j < m; ++j) {
      const double* ej = e[j];
      const double y = yv[j];
      const double aj[6] = {a[0] - ej[0] * ej[0], a[1] - ej[0] * ej[1], a[2] - ej[0] * ej[2],
                            a[3] - ej[1] * ej[1], a[4] - ej[1] * ej[2], a[5] - ej[2] * ej[2]};
      const double rj[3] = {r[0] - y * ej[0], r[1] - y * ej[1], r[2] - y * ej[2]};
      double gj[3];
      if (!solve3(aj, rj, gj)) continue;
      const double rest = syy - y * y - (gj[0] * rj[0] + gj[1] * rj[1] + gj[2] * rj[2]);
      if (rest < best) {
        best = rest;
        pick = j;
        dark = gj[0] * ej[0] + gj[1] * ej[1] + gj[2] * ej[2] - y;
      }
    }
    if (pick < 0 || !(best * 4 < all) || !(dark > s.penumbra_fraction * b.M[k])) continue;
    best_i[k] = float(lamp[pick]);
    b.K[k] -= 1.f;
    ++drops;
  }
  return drops;
}

}  // namespace

void solve_row(const Setup& s, Scratch& b, int y, int x0, int step, int count, const float* z,
               const uint8_t* mask, const RowOut& out) {
  const int n = s.n;
  const size_t cap = size_t(b.cap);
  const size_t row_off = size_t(y) * s.width * 3;
  // 1. load, normalise by lamp colour, grey, saturation.
  float* __restrict M = b.M.data();
  std::fill(M, M + count, 0.f);
  const bool half = !s.half_images.empty();
  const float* half_amb = nullptr;  // the ambient row widened once for every lamp
  if (half && s.half_ambient) {
    widen_pixels(s.half_ambient + row_off + size_t(x0) * 3, step, count, b.wide_ambient.data());
    half_amb = b.wide_ambient.data();
  }
  for (int i = 0; i < n; ++i) {
    const float* src;
    const float* amb;
    int load_step = step;
    if (half) {
      widen_pixels(s.half_images[i] + row_off + size_t(x0) * 3, step, count, b.wide.data());
      src = b.wide.data();
      amb = half_amb;
      load_step = 1;  // widened pixels lie side by side
    } else {
      src = s.images[i] + row_off + size_t(x0) * 3;
      amb = s.ambient ? s.ambient + row_off + size_t(x0) * 3 : nullptr;
    }
    LoadArgs a{src, amb, load_step, count, s.inv_e[i * 3], s.inv_e[i * 3 + 1], s.inv_e[i * 3 + 2], s.saturation,
               b.C.data() + (size_t(i) * 3 + 0) * cap, b.C.data() + (size_t(i) * 3 + 1) * cap,
               b.C.data() + (size_t(i) * 3 + 2) * cap, b.Y.data() + size_t(i) * cap, b.sat.data() + size_t(i) * cap, M};
    if (load_step == 1) {
      amb ? load_light<1, true>(a) : load_light<1, false>(a);
    } else {
      amb ? load_light<0, true>(a) : load_light<0, false>(a);
    }
  }
  // 1b. Coloured pixels are solved on their colour's part off the lamps'
  // white: c - grey(c) per sample (the colours are divided by the lamp's,
  // so the lamps are white here), measured along the pixel's colour. A dielectric's highlight is the lamp's
  // colour, so it adds only to grey and this part is its diffuse shading
  // times a constant: Lambertian, highlight-free (the SUV space of Mallick et
  // al., CVPR 2005). Grey pixels (white, stone) have no such part: they keep
  // the grey samples.
  if (s.diffuse_chroma > 0.f) {
    float* __restrict sy = b.den.data();  // per pixel: the sum of grey over the samples,
    float* __restrict c0 = b.nx.data();   // the summed off-grey colour, then its direction
    float* __restrict c1 = b.ny.data();   // (these buffers are written again before
    float* __restrict c2 = b.nz.data();   // their own use below)
    float* __restrict use = b.ok.data();
    std::fill(sy, sy + count, 0.f);
    std::fill(c0, c0 + count, 0.f);
    std::fill(c1, c1 + count, 0.f);
    std::fill(c2, c2 + count, 0.f);
    for (int i = 0; i < n; ++i) {
      const float* __restrict cb = b.C.data() + (size_t(i) * 3 + 0) * cap;
      const float* __restrict cg = b.C.data() + (size_t(i) * 3 + 1) * cap;
      const float* __restrict cr = b.C.data() + (size_t(i) * 3 + 2) * cap;
      const float* __restrict yy = b.Y.data() + size_t(i) * cap;
VENEER_IVDEP
      for (int k = 0; k < count; ++k) {
        c0[k] += cb[k] - yy[k];
        c1[k] += cg[k] - yy[k];
        c2[k] += cr[k] - yy[k];
        sy[k] += std::max(yy[k], 0.f);
      }
    }
    const float dc = s.diffuse_chroma;
VENEER_IVDEP
    for (int k = 0; k < count; ++k) {
      const float len = std::sqrt(c0[k] * c0[k] + c1[k] * c1[k] + c2[k] * c2[k]);
      const bool coloured = (len >= dc * sy[k]) & (sy[k] > 0.f);
      use[k] = coloured ? 1.f : 0.f;
      const float il = (coloured ? 1.f : 0.f) / (coloured ? len : 1.f);
      c0[k] *= il;
      c1[k] *= il;
      c2[k] *= il;
      M[k] = coloured ? 0.f : M[k];
    }
    // Each sample's off-grey part measured along the pixel's own colour
    // direction: linear in the shading, so dark samples carry no bias.
    for (int i = 0; i < n; ++i) {
      const float* __restrict cb = b.C.data() + (size_t(i) * 3 + 0) * cap;
      const float* __restrict cg = b.C.data() + (size_t(i) * 3 + 1) * cap;
      const float* __restrict cr = b.C.data() + (size_t(i) * 3 + 2) * cap;
      float* __restrict yy = b.Y.data() + size_t(i) * cap;
VENEER_IVDEP
      for (int k = 0; k < count; ++k) {
        const float g = yy[k], u = (cb[k] - g) * c0[k] + (cg[k] - g) * c1[k] + (cr[k] - g) * c2[k];
        yy[k] = use[k] != 0.f ? u : g;
        M[k] = use[k] != 0.f ? std::max(M[k], u) : M[k];
      }
    }
  }
  // 2. weights: robust drops shadowed and saturated samples; < 3 kept falls back to all.
  uint32_t* __restrict pat = b.pat.data();
  float* __restrict K = b.K.data();
  float* __restrict okv = b.ok.data();
  if (s.robust) {
    for (int i = 0; i < n; ++i) {
      const float* __restrict yy = b.Y.data() + size_t(i) * cap;
      const float* __restrict st = b.sat.data() + size_t(i) * cap;
      float* __restrict w = b.W.data() + size_t(i) * cap;
      const float sf = s.shadow_fraction;
VENEER_IVDEP
      for (int k = 0; k < count; ++k) w[k] = float((yy[k] >= sf * M[k]) & (st[k] == 0.f) & (yy[k] > 0.f));
    }
    std::fill(K, K + count, 0.f);
    for (int i = 0; i < n; ++i) {
      const float* __restrict w = b.W.data() + size_t(i) * cap;
VENEER_IVDEP
      for (int k = 0; k < count; ++k) K[k] += w[k];
    }
VENEER_IVDEP
    for (int k = 0; k < count; ++k) okv[k] = K[k] >= 3.f ? 1.f : 0.f;
    if (s.use_cache) {
      std::fill(pat, pat + count, 0u);
      for (int i = 0; i < n; ++i) {
        const float* __restrict w = b.W.data() + size_t(i) * cap;
VENEER_IVDEP
        for (int k = 0; k < count; ++k) pat[k] |= uint32_t(w[k] != 0.f) << i;
      }
    }
    // Fallback to every sample where fewer than 3 are kept.
VENEER_IVDEP
    for (int k = 0; k < count; ++k) {
      if (okv[k] == 0.f) {
        for (int i = 0; i < n; ++i) b.W[size_t(i) * cap + k] = 1.f;
        K[k] = float(n);
        pat[k] = s.full;
      }
    }
  } else {
    for (int i = 0; i < n; ++i) std::fill(b.W.begin() + size_t(i) * cap, b.W.begin() + size_t(i) * cap + count, 1.f);
    std::fill(pat, pat + count, s.full);
    std::fill(K, K + count, float(n));
    std::fill(okv, okv + count, 1.f);
  }
  float* __restrict gx = b.acc.data() + 9 * cap;
  float* __restrict gy = b.acc.data() + 10 * cap;
  float* __restrict gz = b.acc.data() + 11 * cap;
  float* __restrict nx = b.nx.data();
  float* __restrict ny = b.ny.data();
  float* __restrict nz = b.nz.data();
  float* __restrict ga = b.a.data();
  const float ms = s.min_signal;
  // 3-4 run once, or twice when outliers were dropped after the first fit.
  for (int pass = 0; pass < 2; ++pass) {
    // 3. solve g = albedo * n.
    if (!s.near) {
      if (s.use_cache || !s.robust) {
        // Full pattern for everybody (vectorised), then the other patterns pixel by pixel.
        // The second pass only re-solves the pixels that dropped an outlier.
        const float* P = s.pinv.data() + size_t(s.use_cache ? s.full : 0) * 3 * n;
        if (pass == 0) {
          std::fill(gx, gx + count, 0.f);
          std::fill(gy, gy + count, 0.f);
          std::fill(gz, gz + count, 0.f);
          for (int i = 0; i < n; ++i) {
            const float* __restrict yy = b.Y.data() + size_t(i) * cap;
            const float p0 = P[i], p1 = P[n + i], p2 = P[2 * n + i];
VENEER_IVDEP
            for (int k = 0; k < count; ++k) {
              gx[k] += p0 * yy[k];
              gy[k] += p1 * yy[k];
              gz[k] += p2 * yy[k];
            }
          }
        }
        if (s.robust) {
          const float* dropped = b.acc.data();  // best_i of the outlier step: -1 = kept all
VENEER_IVDEP
          for (int k = 0; k < count; ++k) {
            const uint32_t p = pat[k];
            if (p == s.full) continue;
            if (pass == 1 && dropped[k] < 0.f) continue;
            if (!s.pinv_ok[p]) {
              okv[k] = 0.f;
              continue;
            }
            const float* Q = s.pinv.data() + size_t(p) * 3 * n;
            float x = 0, yv = 0, zv = 0;
            for (int i = 0; i < n; ++i) {
              const float v = b.Y[size_t(i) * cap + k];
              x += Q[i] * v;
              yv += Q[n + i] * v;
              zv += Q[2 * n + i] * v;
            }
            gx[k] = x;
            gy[k] = yv;
            gz[k] = zv;
          }
        }
      } else {
        // Many lamps: per-pixel weighted normal equations with the constant directions.
        const NormalEquations eq(b.acc, cap);
        for (int i = 0; i < n; ++i) {
          const float* __restrict yy = b.Y.data() + size_t(i) * cap;
          const float* __restrict w = b.W.data() + size_t(i) * cap;
          const float lx = s.dir[i * 3], ly = s.dir[i * 3 + 1], lz = s.dir[i * 3 + 2];
VENEER_IVDEP
          for (int k = 0; k < count; ++k) eq.add(k, w[k], w[k] * yy[k], lx, ly, lz);
        }
      }
    } else {
      // Near model: per-pixel light vectors V_i = f_i * l_i from the back-projected point.
      float* __restrict px = b.px.data();
      float* __restrict py = b.py.data();
      float* __restrict pz = b.pz.data();
      const float invf = 1.f / s.f;
      const float v = (float(y) - s.cy) * invf;
VENEER_IVDEP
      for (int k = 0; k < count; ++k) pz[k] = z ? z[k] : 0.f;
VENEER_IVDEP
      for (int k = 0; k < count; ++k) {
        const float zz = pz[k];
        const float t = 1.f - zz;
        px[k] = t * (float(x0 + k * step) - s.cx) * invf;
        py[k] = -t * v;
        pz[k] = zz;
      }
      const NormalEquations eq(b.acc, cap);
      for (int i = 0; i < n; ++i) {
        const float* __restrict yy = b.Y.data() + size_t(i) * cap;
        const float* __restrict w = b.W.data() + size_t(i) * cap;
        float* __restrict vx = b.V.data() + (size_t(i) * 3 + 0) * cap;
        float* __restrict vy = b.V.data() + (size_t(i) * 3 + 1) * cap;
        float* __restrict vz = b.V.data() + (size_t(i) * 3 + 2) * cap;
        const float lx = s.pos[i * 3], ly = s.pos[i * 3 + 1], lz = s.pos[i * 3 + 2], r2 = s.pos_norm2[i];
VENEER_IVDEP
        for (int k = 0; k < count; ++k) {
          const float dx = lx - px[k], dy = ly - py[k], dz = lz - pz[k];
          const float d2 = dx * dx + dy * dy + dz * dz;
          const float inv = 1.f / std::sqrt(d2);
          const float sc = r2 * inv * inv * inv;  // falloff |L|^2/d^2 times 1/d normalisation
          const float ex = dx * sc, ey = dy * sc, ez = dz * sc;
          vx[k] = ex;
          vy[k] = ey;
          vz[k] = ez;
          eq.add(k, w[k], w[k] * yy[k], ex, ey, ez);
        }
      }
    }
    if (s.near || (s.robust && !s.use_cache)) {
      // 3x3 symmetric solve by cofactors, vectorised.
      const float* __restrict A = b.acc.data();
      const float* __restrict A1 = A + cap;
      const float* __restrict A2 = A + 2 * cap;
      const float* __restrict A3 = A + 3 * cap;
      const float* __restrict A4 = A + 4 * cap;
      const float* __restrict A5 = A + 5 * cap;
      const float* __restrict B0 = A + 6 * cap;
      const float* __restrict B1 = A + 7 * cap;
      const float* __restrict B2 = A + 8 * cap;
VENEER_IVDEP
      for (int k = 0; k < count; ++k) {
        const float a00 = A[k], a01 = A1[k], a02 = A2[k], a11 = A3[k], a12 = A4[k], a22 = A5[k];
        const float b0 = B0[k], b1 = B1[k], b2 = B2[k];
        const float c00 = a11 * a22 - a12 * a12, c01 = a02 * a12 - a01 * a22, c02 = a01 * a12 - a02 * a11;
        const float c11 = a00 * a22 - a02 * a02, c12 = a01 * a02 - a00 * a12, c22 = a00 * a11 - a01 * a01;
        const float det = a00 * c00 + a01 * c01 + a02 * c02;
        const float tr = (a00 + a11 + a22) * (1.f / 3.f);
        const bool good = (det > 1e-5f * tr * tr * tr) & (tr > 0.f);
        const float id = (good ? 1.f : 0.f) / (good ? det : 1.f);
        gx[k] = (c00 * b0 + c01 * b1 + c02 * b2) * id;
        gy[k] = (c01 * b0 + c11 * b1 + c12 * b2) * id;
        gz[k] = (c02 * b0 + c12 * b1 + c22 * b2) * id;
        okv[k] = good ? okv[k] : 0.f;
      }
    }
    // 4. normal and grey albedo.
VENEER_IVDEP
    for (int k = 0; k < count; ++k) {
      const float len = std::sqrt(gx[k] * gx[k] + gy[k] * gy[k] + gz[k] * gz[k]);
      const bool sig = (len > 0.f) & (M[k] > ms);
      const float il = (sig ? 1.f : 0.f) / (sig ? len : 1.f);
      nx[k] = gx[k] * il;
      ny[k] = gy[k] * il;
      nz[k] = gz[k] * il;
      ga[k] = sig ? len : 0.f;
      okv[k] = sig ? okv[k] : 0.f;
    }
    const bool outliers = s.outlier_fraction > 0.f, penumbrae = s.penumbra_fraction > 0.f && n <= kMaxNearLights;
    if (pass == 1 || !s.robust || !(outliers || penumbrae)) break;
    // The normal equations are rebuilt in the next pass (near, many lamps) or
    // not used (the distant model's patterns): acc's first lanes are free.
    float* __restrict best_i = b.acc.data();
    std::fill(best_i, best_i + count, -1.f);
    int drops = penumbrae ? drop_penumbrae(s, b, count, best_i) : 0;
    if (outliers) {
      // Outliers: the sample farthest from the first fit (a specular highlight,
      // a cast shadow) is dropped when it is off by more than outlier_fraction of
      // the pixel's brightest sample and 4+ samples remain; then solve again.
      float* __restrict best = b.den.data();
      float* __restrict far_i = b.acc.data() + cap;
      std::fill(best, best + count, 0.f);
      std::fill(far_i, far_i + count, -1.f);
      for (int i = 0; i < n; ++i) {
        const float* __restrict yy = b.Y.data() + size_t(i) * cap;
        const float* __restrict w = b.W.data() + size_t(i) * cap;
        for_each_shading(s, b, i, count, [&](int k, float sh) {
          const float r = std::abs(yy[k] - ga[k] * sh) * w[k];
          const bool sel = r > best[k];
          best[k] = sel ? r : best[k];
          far_i[k] = sel ? float(i) : far_i[k];
        });
      }
      const float of = s.outlier_fraction;
      for (int k = 0; k < count; ++k) {
        // Dark pixels (brightest sample < 0.2) need an absolute 0.02 of full scale: sensor noise.
        const bool drop = (best_i[k] < 0.f) & (best[k] > of * std::max(M[k], 0.2f)) & (K[k] >= 4.f) & (ga[k] > 0.f);
        best_i[k] = drop ? far_i[k] : best_i[k];
        K[k] -= drop ? 1.f : 0.f;
        drops += drop;
      }
    }
    if (drops == 0) break;
    for (int i = 0; i < n; ++i) {
      float* __restrict w = b.W.data() + size_t(i) * cap;
VENEER_IVDEP
      for (int k = 0; k < count; ++k) w[k] = best_i[k] == float(i) ? 0.f : w[k];
    }
    if (s.use_cache) {
      std::fill(pat, pat + count, 0u);
      for (int i = 0; i < n; ++i) {
        const float* __restrict w = b.W.data() + size_t(i) * cap;
        for (int k = 0; k < count; ++k) pat[k] |= uint32_t(w[k] != 0.f) << i;
      }
    }
  }
  // 5. per-channel albedo and residual over the kept samples, with shading S_i = n . V_i.
  float* __restrict den = b.den.data();
  float* __restrict numb = b.acc.data();  // reuse: 3 numerators + residual sum
  float* __restrict numg = b.acc.data() + cap;
  float* __restrict numr = b.acc.data() + 2 * cap;
  float* __restrict res = b.acc.data() + 3 * cap;
  std::fill(numb, numb + 4 * cap, 0.f);
  std::fill(den, den + count, 0.f);
  for (int i = 0; i < n; ++i) {
    const float* __restrict yy = b.Y.data() + size_t(i) * cap;
    const float* __restrict w = b.W.data() + size_t(i) * cap;
    const float* __restrict cb = b.C.data() + (size_t(i) * 3 + 0) * cap;
    const float* __restrict cg = b.C.data() + (size_t(i) * 3 + 1) * cap;
    const float* __restrict cr = b.C.data() + (size_t(i) * 3 + 2) * cap;
    // pixel k's sample of this lamp under shading sh
    auto add = [&](int k, float sh) {
      const float ws = w[k] * sh;
      numb[k] += ws * cb[k];
      numg[k] += ws * cg[k];
      numr[k] += ws * cr[k];
      den[k] += ws * sh;
      const float d = yy[k] - ga[k] * sh;
      res[k] += w[k] * d * d;
    };
    for_each_shading(s, b, i, count, add);
  }
  // 6. write.
  float* __restrict on = out.normals;
  const uint8_t* __restrict mk = mask;
  float* __restrict inside = b.px.data();  // reuse: 1 where the pixel is in the mask
  for (int k = 0; k < count; ++k) inside[k] = mk[size_t(k) * step] != 0 ? 1.f : 0.f;
VENEER_IVDEP
  for (int k = 0; k < count; ++k) {
    on[k * 3] = nx[k] * inside[k];
    on[k * 3 + 1] = ny[k] * inside[k];
    on[k * 3 + 2] = nz[k] * inside[k];
  }
  if (out.albedo) {
    float* __restrict al = out.albedo;
VENEER_IVDEP
    for (int k = 0; k < count; ++k) {
      const bool use = (inside[k] != 0.f) & (ga[k] > 0.f) & (den[k] > 0.f);
      const float id = (use ? 1.f : 0.f) / (use ? den[k] : 1.f);
      al[k * 3] = std::max(0.f, numb[k] * id);
      al[k * 3 + 1] = std::max(0.f, numg[k] * id);
      al[k * 3 + 2] = std::max(0.f, numr[k] * id);
    }
  }
  if (out.residual) {
    float* __restrict ro = out.residual;
VENEER_IVDEP
    for (int k = 0; k < count; ++k) {
      const bool use = (inside[k] != 0.f) & (ga[k] > 0.f);
      ro[k] = use ? std::sqrt(res[k] / std::max(K[k], 1.f)) / (use ? M[k] : 1.f) : 0.f;
    }
  }
  if (out.reliable) {
    uint8_t* __restrict rl = out.reliable;
    for (int k = 0; k < count; ++k) rl[k] = ((inside[k] != 0.f) & (okv[k] != 0.f)) ? 255 : 0;
  }
}

Status check_directions(const std::vector<float>& dir, int n, const std::string& what) {
  cv::Mat L(n, 3, CV_64F);
  for (int i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) L.at<double>(i, c) = dir[i * 3 + c];
  cv::Mat w;
  cv::SVD::compute(L, w, cv::SVD::NO_UV);
  const double s0 = w.at<double>(0), s2 = w.at<double>(2);
  if (!(s0 > 0) || s2 < 1e-3 * s0) {
    char buf[160];
    std::snprintf(buf, sizeof buf, "degenerate %s: they do not span 3-D (coplanar or identical; singular values %.3g %.3g %.3g)",
                  what.c_str(), s0, w.at<double>(1), s2);
    return make_error(buf);
  }
  return Status::success();
}
void solve_rows(const Setup& s, const cv::Mat& mask, const cv::Mat* zmap, int y0, int y1, PsResult& result) {
  constexpr int kChunk = 256;  // pixels per pass: the scratch rows stay in L1/L2
  tbb::parallel_for(tbb::blocked_range<int>(y0, y1, 4), [&](const tbb::blocked_range<int>& r) {
    Scratch sc;
    sc.resize(s.n, std::min(kChunk, s.width));
    for (int y = r.begin(); y < r.end(); ++y) {
      const uint8_t* mrow = mask.ptr<uint8_t>(y);
      for (int x0 = 0; x0 < s.width; x0 += kChunk) {
        const int count = std::min(kChunk, s.width - x0);
        RowOut out;
        out.normals = result.normals.ptr<float>(y) + size_t(x0) * 3;
        out.albedo = result.albedo.ptr<float>(y) + size_t(x0) * 3;
        out.residual = result.residual.ptr<float>(y) + x0;
        out.reliable = result.reliable.ptr<uint8_t>(y) + x0;
        // Stretches without object pixels are only cleared.
        if (std::find_if(mrow + x0, mrow + x0 + count, [](uint8_t v) { return v != 0; }) == mrow + x0 + count) {
          std::fill(out.normals, out.normals + size_t(count) * 3, 0.f);
          std::fill(out.albedo, out.albedo + size_t(count) * 3, 0.f);
          std::fill(out.residual, out.residual + count, 0.f);
          std::fill(out.reliable, out.reliable + count, uint8_t(0));
          continue;
        }
        solve_row(s, sc, y, x0, 1, count, zmap ? zmap->ptr<float>(y) + x0 : nullptr, mrow + x0, out);
      }
    }
  });
}
}  // namespace veneer::ps::detail
