// Photometric stereo's part-lit samples (PsOptions::part_lit_px): where a
// lamp's cast shadow ends, a pixel averages lit and shadowed surface (the
// lens and the sensor's low-pass filter blur the edge over a pixel or two),
// so its sample is neither shadowed nor Lambertian. Such samples sit next to
// the same lamp's shadowed ones: marked here, held back by the row solver.
#include <algorithm>
#include <bit>
#include <cmath>
#include <vector>

#include <opencv2/imgproc.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "row_solver.hpp"

namespace veneer::ps::detail {

cv::Mat near_shadow_bits(const Setup& s, const cv::Mat& mask, int radius) {
  const int W = s.width, H = s.height, n = s.n;
  cv::Mat shadowed(H, W, CV_32SC1, cv::Scalar(0)), out(H, W, CV_32SC1, cv::Scalar(0));
  const cv::Rect box = cv::boundingRect(mask);
  if (box.area() == 0 || radius <= 0) return out;
  // Shadowed samples: grey below shadow_fraction of the pixel's brightest.
  tbb::parallel_for(tbb::blocked_range<int>(box.y, box.y + box.height, 8), [&](const tbb::blocked_range<int>& r) {
    std::vector<float> g(static_cast<size_t>(n));
    for (int y = r.begin(); y < r.end(); ++y) {
      const uint8_t* m = mask.ptr<uint8_t>(y);
      uint32_t* o = shadowed.ptr<uint32_t>(y);
      for (int x = box.x; x < box.x + box.width; ++x) {
        if (!m[x]) continue;
        const size_t at = (static_cast<size_t>(y) * W + x) * 3;
        float peak = 0;
        for (int i = 0; i < n; ++i) {
          const float* p = s.images[i] + at;
          float v = 0;
          for (int c = 0; c < 3; ++c) v += (p[c] - (s.ambient ? s.ambient[at + c] : 0.f)) * s.inv_e[i * 3 + c];
          g[i] = v;
          peak = std::max(peak, v);
        }
        if (!(peak > 3.f * s.min_signal)) continue;
        uint32_t bits = 0;
        for (int i = 0; i < n; ++i) bits |= uint32_t(g[i] < s.shadow_fraction * peak) << i;
        o[x] = bits;
      }
    }
  });
  // Spread each lamp's bit over the square of `radius`: OR along rows, then columns.
  cv::Mat rows(H, W, CV_32SC1, cv::Scalar(0));
  const int x0 = std::max(0, box.x - radius), x1 = std::min(W, box.x + box.width + radius);
  const int y0 = std::max(0, box.y - radius), y1 = std::min(H, box.y + box.height + radius);
  tbb::parallel_for(tbb::blocked_range<int>(box.y, box.y + box.height, 16), [&](const tbb::blocked_range<int>& r) {
    for (int y = r.begin(); y < r.end(); ++y) {
      const uint32_t* a = shadowed.ptr<uint32_t>(y);
      uint32_t* o = rows.ptr<uint32_t>(y);
      for (int x = x0; x < x1; ++x) {
        uint32_t v = 0;
        for (int d = std::max(0, x - radius); d <= std::min(W - 1, x + radius); ++d) v |= a[d];
        o[x] = v;
      }
    }
  });
  tbb::parallel_for(tbb::blocked_range<int>(y0, y1, 16), [&](const tbb::blocked_range<int>& r) {
    for (int y = r.begin(); y < r.end(); ++y) {
      const uint8_t* m = mask.ptr<uint8_t>(y);
      uint32_t* o = out.ptr<uint32_t>(y);
      for (int x = x0; x < x1; ++x) {
        if (!m[x]) continue;
        uint32_t v = 0;
        for (int d = std::max(0, y - radius); d <= std::min(H - 1, y + radius); ++d) v |= rows.ptr<uint32_t>(d)[x];
        o[x] = v;
      }
    }
  });
  return out;
}

namespace {

constexpr int kMaxConsensusSamples = 12;  // 220 triples at most

// g solving the normal equations A g = r (A symmetric 3x3: a00 a01 a02 a11 a12 a22); false when singular.
bool solve3(const double* A, const double* r, double* g) {
  const double c00 = A[3] * A[5] - A[4] * A[4], c01 = A[2] * A[4] - A[1] * A[5], c02 = A[1] * A[4] - A[2] * A[3];
  const double c11 = A[0] * A[5] - A[2] * A[2], c12 = A[1] * A[2] - A[0] * A[4], c22 = A[0] * A[3] - A[1] * A[1];
  const double det = A[0] * c00 + A[1] * c01 + A[2] * c02;
  const double tr = (A[0] + A[3] + A[5]) / 3;
  if (!(tr > 0) || !(det > 1e-5 * tr * tr * tr)) return false;
  g[0] = (c00 * r[0] + c01 * r[1] + c02 * r[2]) / det;
  g[1] = (c01 * r[0] + c11 * r[1] + c12 * r[2]) / det;
  g[2] = (c02 * r[0] + c12 * r[1] + c22 * r[2]) / det;
  return true;
}

}  // namespace

int drop_inconsistent(const Setup& s, Scratch& b, int count) {
  const int n = s.n;
  const size_t cap = size_t(b.cap);
  const float* gxs = b.acc.data() + 9 * cap;
  const float* gys = b.acc.data() + 10 * cap;
  const float* gzs = b.acc.data() + 11 * cap;
  const float tol = s.fit_tolerance;
  int changed = 0;
  double v[kMaxNearLights][3], yv[kMaxNearLights];
  int idx[kMaxNearLights];
  for (int k = 0; k < count; ++k) {
    b.redo[k] = 0.f;
    if (b.ok[k] == 0.f || !(b.a[k] > 0.f) || b.K[k] < 4.f) continue;
    const double M = b.M[k];
    // The kept samples, their light vectors and how far each may be off.
    int m = 0;
    for (int i = 0; i < n && m < kMaxNearLights; ++i) {
      if (b.W[size_t(i) * cap + k] == 0.f) continue;
      for (int c = 0; c < 3; ++c) v[m][c] = s.near ? b.V[(size_t(i) * 3 + c) * cap + k] : s.dir[i * 3 + c];
      yv[m] = b.Y[size_t(i) * cap + k];
      idx[m++] = i;
    }
    double g[3] = {gxs[k], gys[k], gzs[k]};
    auto limit = [&](double pred) { return tol * std::max(pred, 0.25 * M) + 0.01; };
    auto worst_off = [&](const double* gg, int skip) {
      double w = 0;
      for (int j = 0; j < m; ++j) {
        if (j == skip) continue;
        const double pred = gg[0] * v[j][0] + gg[1] * v[j][1] + gg[2] * v[j][2];
        w = std::max(w, std::abs(yv[j] - pred) / limit(pred));
      }
      return w;
    };
    if (worst_off(g, -1) <= 1.0) continue;
    if (m > kMaxConsensusSamples) continue;
    // Consensus: every 3 of the kept samples fix a normal (their shading must
    // be positive); the one most of the others agree with wins, ties going to
    // the one whose disagreeing samples are plausibly off (a part-lit sample
    // darker than the fit, a highlight brighter), then to the smaller misfit.
    // Its agreeing samples are kept.
    int best_in = 0, best_plaus = -1;
    double best_err = 1e30;
    uint32_t best_set = 0;
    for (int a = 0; a < m; ++a)
      for (int c = a + 1; c < m; ++c)
        for (int d = c + 1; d < m; ++d) {
          double A[6] = {0, 0, 0, 0, 0, 0}, r[3] = {0, 0, 0};
          for (int j : {a, c, d}) {
            A[0] += v[j][0] * v[j][0];
            A[1] += v[j][0] * v[j][1];
            A[2] += v[j][0] * v[j][2];
            A[3] += v[j][1] * v[j][1];
            A[4] += v[j][1] * v[j][2];
            A[5] += v[j][2] * v[j][2];
            for (int q = 0; q < 3; ++q) r[q] += yv[j] * v[j][q];
          }
          double gj[3];
          if (!solve3(A, r, gj)) continue;
          int in = 0, plaus = 0;
          double err = 0;
          uint32_t set = 0;
          bool bad = false;
          int out = 0;
          for (int j = 0; j < m && m - out >= best_in; ++j) {  // stop once it cannot match the best
            const double pred = gj[0] * v[j][0] + gj[1] * v[j][1] + gj[2] * v[j][2];
            const double off = (yv[j] - pred) / limit(pred);
            out += std::abs(off) > 1.0;
            if (std::abs(off) <= 1.0) {
              if (!(pred > 0)) bad = true;
              ++in;
              err += off * off;
              set |= 1u << j;
            } else {
              const bool part_lit = (b.held[k] >> idx[j] & 1u) && off < 0;
              plaus += part_lit ? 2 : off > 0 ? 1 : 0;
            }
          }
          if (bad || in < 3 || m - out < best_in) continue;
          const bool better = in > best_in || (in == best_in && (plaus > best_plaus || (plaus == best_plaus && err < best_err)));
          if (!better) continue;
          best_in = in;
          best_plaus = plaus;
          best_err = err;
          best_set = set;
        }
    if (best_in == 0 || best_in == m) continue;
    // With 4 samples the 3 left fit exactly whatever they are: the one left
    // out must be plausibly off.
    if (m == 4) {
      // Only a part-lit sample darker than the fit, or the brightest when it
      // is brighter (a highlight).
      int out = 0;
      double brightest = yv[0];
      for (int j = 0; j < m; ++j) {
        brightest = std::max(brightest, yv[j]);
        if (!(best_set >> j & 1u)) out = j;
      }
      if (!(best_plaus == 2 || (best_plaus == 1 && yv[out] >= brightest))) continue;
    }
    uint32_t dropped = 0;
    for (int j = 0; j < m; ++j)
      if (!(best_set >> j & 1u)) dropped |= 1u << idx[j];
    if (!dropped) continue;
    for (int i = 0; i < n; ++i)
      if (dropped >> i & 1u) b.W[size_t(i) * cap + k] = 0.f;
    b.K[k] -= float(std::popcount(dropped));
    b.pat[k] &= ~dropped;
    b.redo[k] = 1.f;
    ++changed;
  }
  return changed;
}

}  // namespace veneer::ps::detail
