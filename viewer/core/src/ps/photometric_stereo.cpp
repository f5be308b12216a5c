// Photometric stereo (see photometric_stereo.hpp).
//
// Speed: every full-resolution pass works on one image row at a time with
// structure-of-arrays buffers (per lamp: B, G, R, grey), so the inner loops run
// over pixels and vectorise. The distant model multiplies by one
// pseudo-inverse per "lamps kept" pattern (computed once, at most 2^n); the
// near model forms the 3x3 normal equations per pixel from its own light
// vectors. The near model's depth refinement runs on a sub-sampled grid; the
// full-resolution image is read exactly once.
#include "veneer/ps/photometric_stereo.hpp"

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstdint>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include "depth.hpp"
#include "veneer/io/big_buffers.hpp"
#include "veneer/util/log.hpp"

// "No dependence between the iterations": GCC vectorises the per-pixel lane
// loops below without a runtime alias check. (Clang -- the fuzz build -- has
// no such hint that it does not turn into an error when a sanitizer keeps it
// from vectorising; it relies on the __restrict pointers.)
#if defined(__clang__)
#define VENEER_IVDEP
#else
#define VENEER_IVDEP _Pragma("GCC ivdep")
#endif


namespace veneer::ps {

const char* light_model_name(LightModel m) {
  switch (m) {
    case LightModel::automatic: return "automatic";
    case LightModel::distant: return "distant";
    case LightModel::near: return "near";
  }
  return "automatic";
}

Expected<LightModel> parse_light_model(const std::string& s) {
  if (s == "automatic" || s == "auto") return LightModel::automatic;
  if (s == "distant") return LightModel::distant;
  if (s == "near") return LightModel::near;
  return make_error("unknown light model '" + s + "' (automatic, distant, near)");
}

Status PsOptions::check() const {
  if (!(shadow_fraction >= 0.f && shadow_fraction < 1.f))
    return make_error("shadow_fraction must be in [0, 1), got " + std::to_string(shadow_fraction));
  if (!(saturation > 0.f && saturation <= 1.f))
    return make_error("saturation must be in (0, 1], got " + std::to_string(saturation));
  if (!(min_signal >= 0.f)) return make_error("min_signal must be >= 0, got " + std::to_string(min_signal));
  if (!(outlier_fraction >= 0.f && outlier_fraction < 1.f))
    return make_error("outlier_fraction must be in [0, 1), got " + std::to_string(outlier_fraction));
  if (!(diffuse_chroma >= 0.f && diffuse_chroma <= 2.f))
    return make_error("diffuse_chroma must be in [0, 2], got " + std::to_string(diffuse_chroma));
  if (refine_iterations < 1 || refine_iterations > 10)
    return make_error("refine_iterations must be in 1..10, got " + std::to_string(refine_iterations));
  if (!(refine_max_deg > 0 && refine_max_deg <= 45))
    return make_error("refine_max_deg must be in (0, 45], got " + std::to_string(refine_max_deg));
  if (near_iterations < 0 || near_iterations > 5)
    return make_error("near_iterations must be in 0..5, got " + std::to_string(near_iterations));
  if (threads < 0) return make_error("threads must be >= 0, got " + std::to_string(threads));
  return Status::success();
}

namespace {

constexpr int kMaxPatternLights = 12;  // cache every pattern up to 2^12 (distant model)
constexpr int kMaxNearLights = 32;

struct Setup {
  int n = 0;
  int width = 0, height = 0;
  bool near = false;
  bool robust = true;
  float shadow_fraction = 0.1f, saturation = 0.98f, min_signal = 1e-3f, outlier_fraction = 0.0f;
  float diffuse_chroma = 0.0f;   // see PsOptions::diffuse_chroma
  std::vector<float> dir;        // n*3 distant directions
  std::vector<float> pos;        // n*3 lamp positions (near)
  std::vector<float> pos_norm2;  // n: |position|^2 (intensity reference distance)
  std::vector<float> inv_e;      // n*3 BGR 1/intensity
  float f = 1, cx = 0, cy = 0;   // intrinsics (near)
  // Distant model: pseudo-inverse (3 x n, zero columns for dropped lamps) per pattern.
  bool use_cache = false;
  std::vector<float> pinv;       // (1 << n) * 3 * n, or only the full pattern when !use_cache
  std::vector<uint8_t> pinv_ok;
  uint32_t full = 0;
  std::vector<const float*> images;  // n, continuous CV_32FC3
  const float* ambient = nullptr;
};

// Pseudo-inverse of the rows of `dir` selected by `pattern`: (L^T L)^-1 L^T,
// in double. False when the kept directions do not span 3-D.
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

// Per-task scratch: structure-of-arrays rows.
struct Scratch {
  int cap = 0, n = 0;
  std::vector<float> C;    // n*3*cap normalised B,G,R
  std::vector<float> Y;    // n*cap grey
  std::vector<float> W;    // n*cap weights (0/1)
  std::vector<float> V;    // n*3*cap light vectors (near)
  std::vector<float> acc;  // 12*cap: A00 A01 A02 A11 A12 A22 b0 b1 b2 gx gy gz
  std::vector<float> M, K, a, nx, ny, nz, ok, den, px, py, pz;
  std::vector<uint32_t> pat;
  std::vector<float> sat;  // n*cap: 1 where a channel is saturated
  void resize(int n_, int cap_) {
    n = n_;
    cap = cap_;
    C.assign(size_t(n) * 3 * cap, 0.f);
    Y.assign(size_t(n) * cap, 0.f);
    W.assign(size_t(n) * cap, 0.f);
    V.assign(size_t(n) * 3 * cap, 0.f);
    acc.assign(size_t(12) * cap, 0.f);
    for (auto* v : {&M, &K, &a, &nx, &ny, &nz, &ok, &den, &px, &py, &pz}) v->assign(cap, 0.f);
    pat.assign(cap, 0);
    sat.assign(size_t(n) * cap, 0.f);
  }
};

// Output pointers for one row of `count` pixels.
struct RowOut {
  float* normals = nullptr;   // count*3
  float* albedo = nullptr;    // count*3 (may be null)
  float* residual = nullptr;  // count (may be null)
  uint8_t* reliable = nullptr;  // count (may be null)
};

struct LoadArgs {
  const float* src;
  const float* amb;
  int step, count;
  float e0, e1, e2, satv;
  float *cb, *cg, *cr, *yy, *st, *M;
};

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

// Solves `count` pixels of row y: x = x0 + k*step. `z` gives each pixel's
// surface z (rig frame) for the near model (null = 0). `mask`: the row's mask
// from x0, sampled with the same step.
void solve_row(const Setup& s, Scratch& b, int y, int x0, int step, int count, const float* z,
               const uint8_t* mask, const RowOut& out) {
  const int n = s.n;
  const size_t cap = size_t(b.cap);
  const size_t row_off = size_t(y) * s.width * 3;
  // 1. load, normalise by lamp colour, grey, saturation.
  float* __restrict M = b.M.data();
  std::fill(M, M + count, 0.f);
  for (int i = 0; i < n; ++i) {
    const float* src = s.images[i] + row_off + size_t(x0) * 3;
    const float* amb = s.ambient ? s.ambient + row_off + size_t(x0) * 3 : nullptr;
    LoadArgs a{src, amb, step, count, s.inv_e[i * 3], s.inv_e[i * 3 + 1], s.inv_e[i * 3 + 2], s.saturation,
               b.C.data() + (size_t(i) * 3 + 0) * cap, b.C.data() + (size_t(i) * 3 + 1) * cap,
               b.C.data() + (size_t(i) * 3 + 2) * cap, b.Y.data() + size_t(i) * cap, b.sat.data() + size_t(i) * cap, M};
    if (step == 1) {
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
        std::fill(b.acc.begin(), b.acc.begin() + 9 * cap, 0.f);
        float* __restrict a00 = b.acc.data();
        float* __restrict a01 = a00 + cap;
        float* __restrict a02 = a00 + 2 * cap;
        float* __restrict a11 = a00 + 3 * cap;
        float* __restrict a12 = a00 + 4 * cap;
        float* __restrict a22 = a00 + 5 * cap;
        float* __restrict b0 = a00 + 6 * cap;
        float* __restrict b1 = a00 + 7 * cap;
        float* __restrict b2 = a00 + 8 * cap;
        for (int i = 0; i < n; ++i) {
          const float* __restrict yy = b.Y.data() + size_t(i) * cap;
          const float* __restrict w = b.W.data() + size_t(i) * cap;
          const float lx = s.dir[i * 3], ly = s.dir[i * 3 + 1], lz = s.dir[i * 3 + 2];
VENEER_IVDEP
          for (int k = 0; k < count; ++k) {
            const float wk = w[k], wy = wk * yy[k];
            a00[k] += wk * lx * lx;
            a01[k] += wk * lx * ly;
            a02[k] += wk * lx * lz;
            a11[k] += wk * ly * ly;
            a12[k] += wk * ly * lz;
            a22[k] += wk * lz * lz;
            b0[k] += wy * lx;
            b1[k] += wy * ly;
            b2[k] += wy * lz;
          }
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
      std::fill(b.acc.begin(), b.acc.begin() + 9 * cap, 0.f);
      float* __restrict a00 = b.acc.data();
      float* __restrict a01 = a00 + cap;
      float* __restrict a02 = a00 + 2 * cap;
      float* __restrict a11 = a00 + 3 * cap;
      float* __restrict a12 = a00 + 4 * cap;
      float* __restrict a22 = a00 + 5 * cap;
      float* __restrict b0 = a00 + 6 * cap;
      float* __restrict b1 = a00 + 7 * cap;
      float* __restrict b2 = a00 + 8 * cap;
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
          const float wk = w[k], wy = wk * yy[k];
          a00[k] += wk * ex * ex;
          a01[k] += wk * ex * ey;
          a02[k] += wk * ex * ez;
          a11[k] += wk * ey * ey;
          a12[k] += wk * ey * ez;
          a22[k] += wk * ez * ez;
          b0[k] += wy * ex;
          b1[k] += wy * ey;
          b2[k] += wy * ez;
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
    if (pass == 1 || !s.robust || !(s.outlier_fraction > 0.f)) break;
    // Outliers: the sample farthest from the first fit (a specular highlight,
    // a cast shadow) is dropped when it is off by more than outlier_fraction of
    // the pixel's brightest sample and 4+ samples remain; then solve again.
    float* __restrict best = b.den.data();
    float* __restrict best_i = b.acc.data();  // the normal equations are rebuilt in the next pass
    std::fill(best, best + count, 0.f);
    std::fill(best_i, best_i + count, -1.f);
    for (int i = 0; i < n; ++i) {
      const float* __restrict yy = b.Y.data() + size_t(i) * cap;
      const float* __restrict w = b.W.data() + size_t(i) * cap;
      const float* __restrict vx = b.V.data() + (size_t(i) * 3 + 0) * cap;
      const float* __restrict vy = b.V.data() + (size_t(i) * 3 + 1) * cap;
      const float* __restrict vz = b.V.data() + (size_t(i) * 3 + 2) * cap;
      const float lx = s.dir[i * 3], ly = s.dir[i * 3 + 1], lz = s.dir[i * 3 + 2];
      const bool near = s.near;
VENEER_IVDEP
      for (int k = 0; k < count; ++k) {
        const float sh = near ? nx[k] * vx[k] + ny[k] * vy[k] + nz[k] * vz[k] : nx[k] * lx + ny[k] * ly + nz[k] * lz;
        const float r = std::abs(yy[k] - ga[k] * sh) * w[k];
        const bool sel = r > best[k];
        best[k] = sel ? r : best[k];
        best_i[k] = sel ? float(i) : best_i[k];
      }
    }
    int drops = 0;
    const float of = s.outlier_fraction;
    for (int k = 0; k < count; ++k) {
      // Dark pixels (brightest sample < 0.2) need an absolute 0.02 of full scale: sensor noise.
      const bool drop = (best[k] > of * std::max(M[k], 0.2f)) & (K[k] >= 4.f) & (ga[k] > 0.f);
      best_i[k] = drop ? best_i[k] : -1.f;
      K[k] -= drop ? 1.f : 0.f;
      drops += drop;
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
    if (s.near) {
      const float* __restrict vx = b.V.data() + (size_t(i) * 3 + 0) * cap;
      const float* __restrict vy = b.V.data() + (size_t(i) * 3 + 1) * cap;
      const float* __restrict vz = b.V.data() + (size_t(i) * 3 + 2) * cap;
VENEER_IVDEP
      for (int k = 0; k < count; ++k) {
        const float sh = nx[k] * vx[k] + ny[k] * vy[k] + nz[k] * vz[k];
        const float ws = w[k] * sh;
        numb[k] += ws * cb[k];
        numg[k] += ws * cg[k];
        numr[k] += ws * cr[k];
        den[k] += ws * sh;
        const float d = yy[k] - ga[k] * sh;
        res[k] += w[k] * d * d;
      }
    } else {
      const float lx = s.dir[i * 3], ly = s.dir[i * 3 + 1], lz = s.dir[i * 3 + 2];
VENEER_IVDEP
      for (int k = 0; k < count; ++k) {
        const float sh = nx[k] * lx + ny[k] * ly + nz[k] * lz;
        const float ws = w[k] * sh;
        numb[k] += ws * cb[k];
        numg[k] += ws * cg[k];
        numr[k] += ws * cr[k];
        den[k] += ws * sh;
        const float d = yy[k] - ga[k] * sh;
        res[k] += w[k] * d * d;
      }
    }
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

template <class F>
void run_parallel(int threads, F&& f) {
  if (threads > 0) {
    tbb::task_arena arena(threads);
    arena.execute(f);
  } else {
    f();
  }
}

// Solves every row in [y0, y1) (step 1) in parallel, writing into `result`.
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

// Pixels that kept fewer than 3 lit samples (cast shadows on most lamps) have
// no normal of their own: the plain fit over shadowed samples errs by tens of
// degrees. They take the mean normal of their already-known 8-neighbours,
// nearest reliable pixels first (a breadth-first diffusion inside the mask),
// which follows a limb or a leg's curvature from where it is lit.
void fill_from_neighbours(cv::Mat& normals, const cv::Mat& mask, const cv::Mat& reliable) {
  const int W = normals.cols, H = normals.rows;
  cv::Mat known(normals.size(), CV_8UC1, cv::Scalar(0));
  std::vector<cv::Point> front, next;
  for (int y = 0; y < H; ++y) {
    const uint8_t* m = mask.ptr<uint8_t>(y);
    const uint8_t* r = reliable.ptr<uint8_t>(y);
    uint8_t* k = known.ptr<uint8_t>(y);
    for (int x = 0; x < W; ++x) k[x] = (m[x] && r[x]) ? 1 : 0;
  }
  // First ring: unknown pixels with a known neighbour.
  auto ring_of = [&](const std::vector<cv::Point>* from, std::vector<cv::Point>& out) {
    out.clear();
    auto consider = [&](int x, int y) {
      if (x < 0 || y < 0 || x >= W || y >= H) return;
      if (!mask.at<uint8_t>(y, x) || known.at<uint8_t>(y, x)) return;
      known.at<uint8_t>(y, x) = 2;  // queued
      out.push_back({x, y});
    };
    if (!from) {
      for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x)
          if (known.at<uint8_t>(y, x) == 1)
            for (int dy = -1; dy <= 1; ++dy)
              for (int dx = -1; dx <= 1; ++dx) consider(x + dx, y + dy);
    } else {
      for (const cv::Point& p : *from)
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) consider(p.x + dx, p.y + dy);
    }
  };
  ring_of(nullptr, front);
  while (!front.empty()) {
    std::vector<cv::Vec3f> value(front.size());
    for (size_t i = 0; i < front.size(); ++i) {
      const cv::Point p = front[i];
      cv::Vec3f sum(0, 0, 0);
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const int x = p.x + dx, y = p.y + dy;
          if (x < 0 || y < 0 || x >= W || y >= H || known.at<uint8_t>(y, x) != 1) continue;
          sum += normals.at<cv::Vec3f>(y, x);
        }
      const float len = static_cast<float>(cv::norm(sum));
      value[i] = len > 0 ? sum / len : normals.at<cv::Vec3f>(p);
    }
    for (size_t i = 0; i < front.size(); ++i) {
      normals.at<cv::Vec3f>(front[i]) = value[i];
      known.at<uint8_t>(front[i]) = 1;
    }
    ring_of(&front, next);
    front.swap(next);
  }
}

}  // namespace

Expected<PsResult> photometric_stereo(const ImageSet& set, const cv::Mat& mask, const PsOptions& options,
                                      const Progress& progress) {
  PsResult result;
  if (Status st = photometric_stereo_into(set, mask, options, progress, result); !st) return st.error();
  return result;
}

namespace {

Status solve_once(const ImageSet& set, const cv::Mat& mask_in, const PsOptions& options, const Progress& progress,
                  PsResult& result);

// The linear map C taking the solved normals to integrable ones, up to the
// bas-relief family, from the integrability condition written on them: with
// rows c1, c2, c3 of C, w1 = c3 x c1 and w2 = c3 x c2 satisfy, at every pixel,
//   w1 . (n x dn/dy) + w2 . (n x dn/dx) = 0      (image y pointing down),
// six unknowns, one homogeneous linear equation per pixel. Then c3 is along
// w1 x w2 and C = [k u1 + a c3; k u2 + b c3; s c3] (u = w x c3) with k, a, b, s
// fitted so that C^T recorded ~ fitted. `out` gets the lamps C^-T fitted.
bool integrable_gauge(const PsResult& r, const std::vector<cv::Vec3d>& recorded, const std::vector<cv::Vec3d>& fitted,
                      std::vector<cv::Vec3d>& out) {
  const int n = static_cast<int>(recorded.size());
  cv::Mat ok = r.reliable & r.mask;
  cv::Mat w;
  ok.convertTo(w, CV_32F, 1.0 / 255);
  cv::Mat nm = r.normals.clone();
  nm.setTo(cv::Scalar::all(0), ~ok);
  cv::GaussianBlur(nm, nm, cv::Size(0, 0), 1.0);
  cv::Mat ws;
  cv::GaussianBlur(w, ws, cv::Size(0, 0), 1.0);
  cv::Mat inner;
  cv::erode(ok, inner, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(5, 5)));
  const int count = cv::countNonZero(inner);
  if (count < 500) return false;
  const int stride = std::max(1, static_cast<int>(std::sqrt(double(count) / 60000.0)));
  auto at = [&](int x, int y) {
    cv::Vec3d v(nm.at<cv::Vec3f>(y, x));
    return v / std::max(1e-6, double(ws.at<float>(y, x)));
  };
  std::vector<cv::Vec<double, 6>> rows;
  for (int y = 1; y < r.normals.rows - 1; y += stride)
    for (int x = 1; x < r.normals.cols - 1; x += stride) {
      if (!inner.at<uint8_t>(y, x)) continue;
      cv::Vec3d c = at(x, y);
      const double len = cv::norm(c);
      if (!(len > 0.5)) continue;
      c /= len;
      const cv::Vec3d dx = (at(x + 1, y) - at(x - 1, y)) * 0.5, dy = (at(x, y + 1) - at(x, y - 1)) * 0.5;
      const cv::Vec3d a = c.cross(dy), b = c.cross(dx);
      rows.push_back({a[0], a[1], a[2], b[0], b[1], b[2]});
    }
  if (rows.size() < 300) return false;
  {  // Every pixel about one say: rows longer than the median (limbs, creases) scaled down to it.
    std::vector<double> len(rows.size());
    for (size_t i = 0; i < rows.size(); ++i) len[i] = cv::norm(rows[i]);
    std::vector<double> sorted = len;
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    const double med = std::max(1e-12, sorted[sorted.size() / 2]);
    for (size_t i = 0; i < rows.size(); ++i)
      if (len[i] > med) rows[i] *= med / len[i];
  }
  cv::Vec<double, 6> v;
  std::vector<double> res(rows.size());
  for (int round = 0; round < 2; ++round) {
    cv::Matx<double, 6, 6> S = cv::Matx<double, 6, 6>::zeros();
    double cut = 1e30;
    if (round > 0) {  // drop the worst tenth (occluding edges, creases: not one smooth surface)
      std::vector<double> sorted = res;
      std::nth_element(sorted.begin(), sorted.begin() + sorted.size() * 9 / 10, sorted.end());
      cut = sorted[sorted.size() * 9 / 10];
    }
    for (size_t i = 0; i < rows.size(); ++i)
      if (res[i] <= cut || round == 0) S += rows[i] * rows[i].t();
    cv::Mat evals, evecs;
    cv::eigen(cv::Mat(S), evals, evecs);
    // The smallest eigenvalue must stand clear of the next: one condition, well posed.
    if (!(evals.at<double>(5) < 0.2 * evals.at<double>(4))) return false;
    for (int k = 0; k < 6; ++k) v[k] = evecs.at<double>(5, k);
    for (size_t i = 0; i < rows.size(); ++i) res[i] = std::abs(rows[i].dot(v));
  }
  const cv::Vec3d w1(v[0], v[1], v[2]), w2(v[3], v[4], v[5]);
  cv::Vec3d c3 = w1.cross(w2);
  if (!(cv::norm(c3) > 1e-9)) return false;
  c3 /= cv::norm(c3);
  const cv::Vec3d u1 = w1.cross(c3), u2 = w2.cross(c3);
  // C^T rec = k (u1 rx + u2 ry) + c3 (a rx + b ry + s rz), linear in (k, a, b, s).
  cv::Mat A(3 * n, 4, CV_64F), B(3 * n, 1, CV_64F);
  for (int i = 0; i < n; ++i) {
    const cv::Vec3d& q = recorded[i];
    const cv::Vec3d col0 = u1 * q[0] + u2 * q[1];
    for (int d = 0; d < 3; ++d) {
      A.at<double>(3 * i + d, 0) = col0[d];
      A.at<double>(3 * i + d, 1) = c3[d] * q[0];
      A.at<double>(3 * i + d, 2) = c3[d] * q[1];
      A.at<double>(3 * i + d, 3) = c3[d] * q[2];
      B.at<double>(3 * i + d) = fitted[i][d];
    }
  }
  cv::Mat p;
  if (!cv::solve(A, B, p, cv::DECOMP_SVD)) return false;
  const double k = p.at<double>(0), a = p.at<double>(1), b = p.at<double>(2), s = p.at<double>(3);
  const cv::Vec3d c1 = u1 * k + c3 * a, c2 = u2 * k + c3 * b, c3s = c3 * s;
  const cv::Matx33d C(c1[0], c1[1], c1[2], c2[0], c2[1], c2[2], c3s[0], c3s[1], c3s[2]);
  if (!(std::abs(cv::determinant(C)) > 1e-9)) return false;
  const cv::Matx33d CinvT = C.inv().t();
  out.resize(n);
  for (int i = 0; i < n; ++i) out[i] = CinvT * fitted[i];
  return true;
}

// One round of light refinement (see PsOptions::refine_lights): each lamp's
// vector (intensity x direction) fitted to the grey photos given the solved
// normals and albedo, over the reliable pixels that lamp lights clearly
// (shadowed, saturated and far-off samples -- highlights -- left out); then
// the whole set of fitted vectors mapped by the one linear transform that
// brings them closest to the recorded ones, since the photos alone fix the
// lamps only up to such a transform. False when the data does not allow it.
bool refine_round(const ImageSet& set, const PsResult& r, const PsOptions& options, std::vector<Light>& lights) {
  const int n = static_cast<int>(set.images.size());
  const cv::Size size = set.images[0].size();
  // Pixels: reliable, a stride so that about 40k are used.
  const int count = cv::countNonZero(r.reliable & r.mask);
  if (count < 300) return false;
  const int stride = std::max(1, static_cast<int>(std::sqrt(double(count) / 40000.0)));
  struct Px {
    cv::Vec3d b;  // grey albedo x normal
    float g[kMaxPatternLights * 2];
    float peak;
  };
  if (n > kMaxPatternLights * 2) return false;
  const bool amb = options.subtract_ambient && !set.ambient.empty() && set.ambient.size() == size;
  std::vector<Px> px;
  px.reserve(static_cast<size_t>(count / (stride * stride) + 16));
  for (int y = 0; y < size.height; y += stride) {
    const uint8_t* ok = r.reliable.ptr<uint8_t>(y);
    const uint8_t* m = r.mask.ptr<uint8_t>(y);
    const cv::Vec3f* nr = r.normals.ptr<cv::Vec3f>(y);
    const cv::Vec3f* al = r.albedo.ptr<cv::Vec3f>(y);
    for (int x = 0; x < size.width; x += stride) {
      if (!ok[x] || !m[x]) continue;
      Px p;
      const double rho = (al[x][0] + al[x][1] + al[x][2]) / 3.0;
      if (!(rho > 0)) continue;
      p.b = cv::Vec3d(nr[x][0], nr[x][1], nr[x][2]) * rho;
      p.peak = 0;
      for (int i = 0; i < n; ++i) {
        const cv::Vec3f v = set.images[i].at<cv::Vec3f>(y, x);
        float g = (v[0] + v[1] + v[2]) / 3.f;
        if (amb) {
          const cv::Vec3f a = set.ambient.at<cv::Vec3f>(y, x);
          g -= (a[0] + a[1] + a[2]) / 3.f;
        }
        p.peak = std::max(p.peak, g);
        // a sample with any channel saturated is left out of the fit (as the solve leaves it out)
        p.g[i] = std::max({v[0], v[1], v[2]}) >= options.saturation ? -1.f : g;
      }
      px.push_back(p);
    }
  }
  if (px.size() < 200) return false;
  std::vector<cv::Vec3d> fitted(n), recorded(n);
  for (int i = 0; i < n; ++i) {
    const Light& l = lights[i];
    const double e = (l.intensity[0] + l.intensity[1] + l.intensity[2]) / 3.0;
    recorded[i] = l.direction / cv::norm(l.direction) * e;
    cv::Vec3d cur = recorded[i];
    // Three rounds: fit, then drop samples off by more than 3 robust sigmas (highlights, cast shadows).
    double cut = 1e30;
    for (int round = 0; round < 3; ++round) {
      cv::Matx33d A = cv::Matx33d::zeros();
      cv::Vec3d rhs(0, 0, 0);
      std::vector<float> res;
      res.reserve(px.size());
      int used = 0;
      for (const Px& p : px) {
        const float g = p.g[i];
        if (g < options.shadow_fraction * p.peak) continue;  // shadowed, or saturated (-1)
        const double pred = p.b.dot(cur);
        if (pred <= 0.05 * p.peak) continue;  // near the terminator: attached shadow's edge
        const double d = g - pred;
        if (round > 0 && std::abs(d) > cut) continue;
        res.push_back(static_cast<float>(std::abs(d)));
        A += p.b * p.b.t();
        rhs += p.b * double(g);
        ++used;
      }
      if (used < 100) return false;
      // Conditioning: the normals must spread in every direction.
      cv::Vec3d ev;
      cv::eigen(A, ev);
      if (!(ev[2] > 1e-3 * ev[0])) return false;
      cur = A.solve(rhs, cv::DECOMP_CHOLESKY);
      std::nth_element(res.begin(), res.begin() + res.size() / 2, res.end());
      cut = std::max(3.0 * 1.4826 * res[res.size() / 2], 1e-4);
    }
    fitted[i] = cur;
  }
  // The gauge. The photos fix the lamps only up to one linear map (any C
  // with normals C n and lamps C^-T l shades alike). Integrable normals (a
  // surface's) leave 3 of its 9 numbers free (the bas-relief ambiguity);
  // those, or all 9 when the normals can't say, are taken from the recorded lamps.
  std::vector<cv::Vec3d> out(n);
  if (!integrable_gauge(r, recorded, fitted, out)) {
    cv::Matx33d FF = cv::Matx33d::zeros(), RF = cv::Matx33d::zeros();  // M minimising sum |M fitted - recorded|^2
    for (int i = 0; i < n; ++i) {
      FF += fitted[i] * fitted[i].t();
      RF += recorded[i] * fitted[i].t();
    }
    if (std::abs(cv::determinant(FF)) < 1e-12) return false;
    const cv::Matx33d M = RF * FF.inv();
    for (int i = 0; i < n; ++i) out[i] = M * fitted[i];
  }
  for (int i = 0; i < n; ++i) {
    const cv::Vec3d v = out[i];
    const double len = cv::norm(v);
    if (!(len > 0)) return false;
    const double e_old = (lights[i].intensity[0] + lights[i].intensity[1] + lights[i].intensity[2]) / 3.0;
    lights[i].direction = v / len;
    lights[i].intensity *= static_cast<float>(len / e_old);
  }
  return true;
}

}  // namespace

Status photometric_stereo_into(const ImageSet& set, const cv::Mat& mask_in, const PsOptions& options,
                               const Progress& progress, PsResult& result) {
  if (Status st = solve_once(set, mask_in, options, progress, result); !st) return st;
  result.lights_refined = false;
  result.light_change_deg.clear();
  if (!options.refine_lights || !options.robust || result.model_used != LightModel::distant) return Status::success();
  std::vector<Light> lights = set.lights;
  ImageSet view = set;  // shares the photos; only the lights differ
  std::vector<double> moved(set.lights.size());
  for (int it = 0; it < options.refine_iterations; ++it) {
    if (!refine_round(set, result, options, lights)) break;
    // Directions that moved implausibly far are not a calibration error: keep the last plausible ones.
    for (size_t i = 0; i < lights.size(); ++i) {
      const double c = lights[i].direction.dot(set.lights[i].direction / cv::norm(set.lights[i].direction));
      moved[i] = std::acos(std::clamp(c, -1.0, 1.0)) * 180 / CV_PI;
    }
    if (*std::max_element(moved.begin(), moved.end()) > options.refine_max_deg) break;
    view.lights = lights;
    PsResult next;
    if (Status st = solve_once(view, mask_in, options, {}, next); !st) break;
    result = std::move(next);
    result.lights_refined = true;
    result.lights = view.lights;
    result.light_change_deg = moved;
  }
  return Status::success();
}

namespace {

Status solve_once(const ImageSet& set, const cv::Mat& mask_in, const PsOptions& options, const Progress& progress,
                  PsResult& result) {
  if (Status st = options.check(); !st) return make_error("photometric stereo options: " + st.message());
  const int n = static_cast<int>(set.images.size());
  if (n < 3)
    return make_error("photometric stereo needs at least 3 lights, the set has " + std::to_string(n));
  if (set.lights.size() != set.images.size())
    return make_error("the set has " + std::to_string(set.images.size()) + " images but " +
                      std::to_string(set.lights.size()) + " lights");
  const cv::Size size = set.images[0].size();
  if (size.width <= 0 || size.height <= 0) return make_error("the set's images are empty");
  for (int i = 0; i < n; ++i) {
    const cv::Mat& im = set.images[i];
    if (im.type() != CV_32FC3) return make_error("image " + std::to_string(i) + " is not CV_32FC3 (linear float BGR)");
    if (im.size() != size)
      return make_error("image " + std::to_string(i) + " is " + std::to_string(im.cols) + "x" +
                        std::to_string(im.rows) + ", image 0 is " + std::to_string(size.width) + "x" +
                        std::to_string(size.height));
  }
  cv::Mat mask;
  if (mask_in.empty()) {
    mask = cv::Mat(size, CV_8UC1, cv::Scalar(255));
  } else {
    if (mask_in.type() != CV_8UC1) return make_error("the mask is not CV_8UC1");
    if (mask_in.size() != size)
      return make_error("the mask is " + std::to_string(mask_in.cols) + "x" + std::to_string(mask_in.rows) +
                        ", the images are " + std::to_string(size.width) + "x" + std::to_string(size.height));
    mask = mask_in;
  }
  const int solved = cv::countNonZero(mask);
  if (solved == 0) return make_error("the mask is empty: no object pixels to solve");

  Setup s;
  s.n = n;
  s.width = size.width;
  s.height = size.height;
  s.robust = options.robust;
  s.shadow_fraction = options.shadow_fraction;
  s.saturation = options.saturation;
  s.min_signal = options.min_signal;
  s.outlier_fraction = options.outlier_fraction;
  s.diffuse_chroma = options.robust ? options.diffuse_chroma : 0.f;
  s.dir.resize(size_t(n) * 3);
  s.inv_e.resize(size_t(n) * 3);
  bool have_positions = true;
  for (int i = 0; i < n; ++i) {
    const Light& l = set.lights[i];
    const double len = cv::norm(l.direction);
    if (!(len > 0.5 && len < 1.5))
      return make_error("light " + std::to_string(i) + " has a direction of length " + std::to_string(len));
    for (int c = 0; c < 3; ++c) s.dir[i * 3 + c] = static_cast<float>(l.direction[c] / len);
    for (int c = 0; c < 3; ++c) {
      const float e = l.intensity[2 - c];  // intensity is [r,g,b]; channel 0 is B
      if (!(e > 0.f)) return make_error("light " + std::to_string(i) + " has a non-positive intensity");
      s.inv_e[i * 3 + c] = 1.f / e;
    }
    if (!l.position_m) have_positions = false;
  }
  LightModel model = options.light_model;
  const bool near_possible = have_positions && set.camera.focal_px > 0;
  if (model == LightModel::automatic) model = near_possible ? LightModel::near : LightModel::distant;
  if (model == LightModel::near) {
    if (!have_positions) return make_error("the near-light model needs every lamp's position_m; the set lacks some");
    if (!(set.camera.focal_px > 0)) return make_error("the near-light model needs the camera focal length (camera.focal_px)");
    if (n > kMaxNearLights) return make_error("the near-light model supports at most 32 lamps, the set has " + std::to_string(n));
  }
  s.near = model == LightModel::near;
  if (Status st = check_directions(s.dir, n, "light directions"); !st) return make_error(st.message());
  if (s.near) {
    s.pos.resize(size_t(n) * 3);
    s.pos_norm2.resize(n);
    std::vector<float> pdir(size_t(n) * 3);
    for (int i = 0; i < n; ++i) {
      const cv::Vec3d p = *set.lights[i].position_m;
      const double r = cv::norm(p);
      if (!(r > 1e-6)) return make_error("lamp " + std::to_string(i) + " sits at the rig origin");
      for (int c = 0; c < 3; ++c) {
        s.pos[i * 3 + c] = static_cast<float>(p[c]);
        pdir[i * 3 + c] = static_cast<float>(p[c] / r);
      }
      s.pos_norm2[i] = static_cast<float>(r * r);
    }
    if (Status st = check_directions(pdir, n, "lamp positions"); !st) return make_error(st.message());
    s.f = static_cast<float>(set.camera.focal_px);
    s.cx = static_cast<float>(set.camera.cx > 0 ? set.camera.cx : (size.width - 1) * 0.5);
    s.cy = static_cast<float>(set.camera.cy > 0 ? set.camera.cy : (size.height - 1) * 0.5);
  }
  s.full = n >= 32 ? 0xffffffffu : ((1u << n) - 1u);
  if (!s.near) {
    s.use_cache = n <= kMaxPatternLights;
    if (s.use_cache) {
      const size_t patterns = size_t(1) << n;
      s.pinv.assign(patterns * 3 * n, 0.f);
      s.pinv_ok.assign(patterns, 0);
      if (s.robust) {
        for (uint32_t p = 0; p < patterns; ++p)
          if (std::popcount(p) >= 3) s.pinv_ok[p] = pattern_pinv(s.dir, n, p, s.pinv.data() + size_t(p) * 3 * n);
      } else {
        s.pinv_ok[s.full] = pattern_pinv(s.dir, n, s.full, s.pinv.data() + size_t(s.full) * 3 * n);
      }
    } else if (!s.robust) {
      // Too many lamps for a pattern cache: the one pseudo-inverse of all of them.
      cv::Mat L(n, 3, CV_64F);
      for (int i = 0; i < n; ++i)
        for (int c = 0; c < 3; ++c) L.at<double>(i, c) = s.dir[i * 3 + c];
      cv::Mat P;
      cv::invert(L, P, cv::DECOMP_SVD);
      s.pinv.assign(size_t(3) * n, 0.f);
      for (int r = 0; r < 3; ++r)
        for (int i = 0; i < n; ++i) s.pinv[size_t(r) * n + i] = static_cast<float>(P.at<double>(r, i));
    }
  }
  s.images.resize(n);
  std::vector<cv::Mat> holders;  // continuous copies when needed
  for (int i = 0; i < n; ++i) {
    if (set.images[i].isContinuous()) {
      s.images[i] = set.images[i].ptr<float>();
    } else {
      holders.push_back(set.images[i].clone());
      s.images[i] = holders.back().ptr<float>();
    }
  }
  cv::Mat ambient;
  if (options.subtract_ambient && !set.ambient.empty()) {
    if (set.ambient.type() != CV_32FC3 || set.ambient.size() != size)
      return make_error("the ambient frame does not match the images (type or size)");
    ambient = set.ambient.isContinuous() ? set.ambient : set.ambient.clone();
    s.ambient = ambient.ptr<float>();
  }

  result.model_used = model;
  if (result.mask.data != mask.data) mask.copyTo(result.mask);
  result.solved_pixels = solved;
  // Every pixel is written by solve_rows (zeros outside the mask). Fresh
  // full-resolution results are prefaulted in one call (big_buffers.hpp).
  for (cv::Mat* m : {&result.normals, &result.albedo, &result.residual})
    if (m->empty()) m->allocator = prefault_allocator();
  result.normals.create(size, CV_32FC3);
  result.albedo.create(size, CV_32FC3);
  result.residual.create(size, CV_32FC1);
  result.reliable.create(size, CV_8UC1);

  std::atomic<bool> cancelled{false};
  cv::Mat zfull;
  bool failed_depth = false;
  run_parallel(options.threads, [&] {
    if (s.near) {
      // Depth refinement on a sub-sampled grid: z = 0 first, then integrate the
      // normals into a depth map and solve again.
      progress.report(0.0, "near light: depth");
      DepthGrid grid = make_depth_grid(size, mask, s.f, s.cx, s.cy);
      std::vector<float> zrow;
      for (int it = 0; it <= options.near_iterations; ++it) {
        if (progress.cancelled()) {
          cancelled = true;
          return;
        }
        tbb::parallel_for(tbb::blocked_range<int>(0, grid.rows, 2), [&](const tbb::blocked_range<int>& r) {
          Scratch sc;
          sc.resize(s.n, grid.cols);
          std::vector<float> zr(grid.cols);
          for (int gyi = r.begin(); gyi < r.end(); ++gyi) {
            const int y = grid.y0 + gyi * grid.step;
            for (int k = 0; k < grid.cols; ++k) zr[k] = grid.z.at<float>(gyi, k);
            RowOut out;
            out.normals = grid.normals.ptr<float>(gyi);
            out.reliable = grid.reliable.ptr<uint8_t>(gyi);
            solve_row(s, sc, y, grid.x0, grid.step, grid.cols, zr.data(), mask.ptr<uint8_t>(y) + grid.x0, out);
          }
        });
        if (it == options.near_iterations) break;
        if (!integrate_depth(grid)) {
          failed_depth = true;
          break;
        }
        progress.report(0.3 * (it + 1) / std::max(1, options.near_iterations), "near light: depth");
      }
      zfull = upsample_depth(grid, size);
    }
    const int batches = 8;
    for (int bi = 0; bi < batches; ++bi) {
      if (progress.cancelled()) {
        cancelled = true;
        return;
      }
      const int y0 = size.height * bi / batches, y1 = size.height * (bi + 1) / batches;
      solve_rows(s, mask, s.near ? &zfull : nullptr, y0, y1, result);
      progress.report((s.near ? 0.3 : 0.0) + (s.near ? 0.7 : 1.0) * (bi + 1) / batches, "normals");
    }
  });
  if (cancelled) return make_error("photometric stereo cancelled");
  if (failed_depth) VLOG_WARN("PS", "near-light depth refinement did not converge; kept the previous depth");
  if (s.near) {
    result.depth.create(size, CV_32FC1);
    result.depth.setTo(0);
    // Depth along -z from the camera at z = 1.
    cv::subtract(cv::Scalar(1.0), zfull, result.depth, mask);
  } else {
    result.depth.release();
  }
  result.unreliable_pixels = solved - cv::countNonZero(result.reliable);
  if (options.robust && options.fill_unreliable && result.unreliable_pixels > 0)
    fill_from_neighbours(result.normals, mask, result.reliable);
  progress.report(1.0, "normals");
  return Status::success();
}

}  // namespace

AngularError angular_error(const cv::Mat& normals, const cv::Mat& truth, const cv::Mat& mask) {
  AngularError e;
  if (normals.empty() || truth.empty() || normals.size() != truth.size()) return e;
  std::vector<float> deg;
  deg.reserve(size_t(normals.total()));
  for (int y = 0; y < normals.rows; ++y) {
    const cv::Vec3f* a = normals.ptr<cv::Vec3f>(y);
    const cv::Vec3f* t = truth.ptr<cv::Vec3f>(y);
    const uint8_t* m = mask.empty() ? nullptr : mask.ptr<uint8_t>(y);
    for (int x = 0; x < normals.cols; ++x) {
      if (m && !m[x]) continue;
      const float la = std::sqrt(a[x].dot(a[x])), lt = std::sqrt(t[x].dot(t[x]));
      if (la < 1e-6f || lt < 1e-6f) continue;
      const double c = std::clamp(double(a[x].dot(t[x])) / (double(la) * lt), -1.0, 1.0);
      deg.push_back(static_cast<float>(std::acos(c) * 180.0 / CV_PI));
    }
  }
  e.pixels = static_cast<int>(deg.size());
  if (deg.empty()) return e;
  double sum = 0;
  for (float d : deg) sum += d;
  e.mean_deg = sum / deg.size();
  auto nth = [&](double q) {
    size_t k = std::min(deg.size() - 1, static_cast<size_t>(q * (deg.size() - 1) + 0.5));
    std::nth_element(deg.begin(), deg.begin() + k, deg.end());
    return double(deg[k]);
  };
  e.median_deg = nth(0.5);
  e.p95_deg = nth(0.95);
  e.max_deg = *std::max_element(deg.begin(), deg.end());
  return e;
}

cv::Mat residual_picture(const PsResult& result, float full_scale) {
  cv::Mat out(result.residual.size(), CV_8UC3, cv::Scalar::all(0));
  const float sc = full_scale > 0 ? 255.f / full_scale : 255.f;
  for (int y = 0; y < out.rows; ++y) {
    const float* r = result.residual.ptr<float>(y);
    const uint8_t* m = result.mask.ptr<uint8_t>(y);
    const uint8_t* ok = result.reliable.ptr<uint8_t>(y);
    cv::Vec3b* o = out.ptr<cv::Vec3b>(y);
    for (int x = 0; x < out.cols; ++x) {
      if (!m[x]) continue;
      if (!ok[x]) {
        o[x] = cv::Vec3b(0, 0, 255);
        continue;
      }
      const uint8_t v = static_cast<uint8_t>(std::clamp(r[x] * sc, 0.f, 255.f));
      o[x] = cv::Vec3b(v, v, v);
    }
  }
  return out;
}

}  // namespace veneer::ps
