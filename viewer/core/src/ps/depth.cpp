// Near-light depth refinement on a sub-sampled grid (see depth.hpp).
#include "depth.hpp"

#include <algorithm>
#include <cmath>
#include <deque>
#include <vector>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace veneer::ps {

DepthGrid make_depth_grid(cv::Size size, const cv::Mat& mask, float f, float cx, float cy) {
  DepthGrid g;
  g.step = std::max(1, (std::max(size.width, size.height) + 63) / 64);
  g.x0 = std::min(g.step / 2, size.width - 1);
  g.y0 = std::min(g.step / 2, size.height - 1);
  g.cols = (size.width - 1 - g.x0) / g.step + 1;
  g.rows = (size.height - 1 - g.y0) / g.step + 1;
  g.f = f;
  g.cx = cx;
  g.cy = cy;
  g.mask = cv::Mat(g.rows, g.cols, CV_8UC1, cv::Scalar(0));
  for (int r = 0; r < g.rows; ++r)
    for (int c = 0; c < g.cols; ++c) g.mask.at<uint8_t>(r, c) = mask.at<uint8_t>(g.y0 + r * g.step, g.x0 + c * g.step);
  g.z = cv::Mat(g.rows, g.cols, CV_32FC1, cv::Scalar(0));
  g.normals = cv::Mat(g.rows, g.cols, CV_32FC3, cv::Scalar::all(0));
  g.reliable = cv::Mat(g.rows, g.cols, CV_8UC1, cv::Scalar(0));
  g.full_mask = mask;
  return g;
}

namespace {

// Fills cells outside `valid` with the value of the nearest valid cell (BFS order).
void fill_outside(cv::Mat& z, const std::vector<uint8_t>& valid) {
  const int cols = z.cols, rows = z.rows;
  std::vector<uint8_t> done(valid);
  std::deque<int> q;
  for (int i = 0; i < cols * rows; ++i)
    if (done[i]) q.push_back(i);
  float* zp = z.ptr<float>();
  while (!q.empty()) {
    const int i = q.front();
    q.pop_front();
    const int r = i / cols, c = i % cols;
    const int nb[4][2] = {{r - 1, c}, {r + 1, c}, {r, c - 1}, {r, c + 1}};
    for (auto& p : nb) {
      if (p[0] < 0 || p[0] >= rows || p[1] < 0 || p[1] >= cols) continue;
      const int j = p[0] * cols + p[1];
      if (done[j]) continue;
      done[j] = 1;
      zp[j] = zp[i];
      q.push_back(j);
    }
  }
}

}  // namespace

bool integrate_depth(DepthGrid& g) {
  const int cols = g.cols, rows = g.rows, total = cols * rows;
  std::vector<uint8_t> valid(total, 0);
  std::vector<float> p(total, 0.f), q(total, 0.f), wcell(total, 0.f);
  int count = 0;
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) {
      const int i = r * cols + c;
      const cv::Vec3f n = g.normals.at<cv::Vec3f>(r, c);
      if (!g.mask.at<uint8_t>(r, c) || n.dot(n) < 0.5f) continue;
      valid[i] = 1;
      ++count;
      const float nz = std::max(n[2], 0.1f);
      p[i] = std::clamp(-n[0] / nz, -10.f, 10.f);  // dz/dX
      q[i] = std::clamp(-n[1] / nz, -10.f, 10.f);  // dz/dY
      wcell[i] = g.reliable.at<uint8_t>(r, c) ? 1.f : 0.1f;
    }
  }
  if (count == 0) return false;
  // Edges between neighbouring valid cells: z_b - z_a = d.
  struct Edge {
    int a, b;
    float d, w;
  };
  std::vector<Edge> edges;
  edges.reserve(size_t(count) * 2);
  const float* zp = g.z.ptr<float>();
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) {
      const int a = r * cols + c;
      if (!valid[a]) continue;
      const float h = g.step * (1.f - zp[a]) / g.f;  // metres per cell at this depth
      if (c + 1 < cols && valid[a + 1]) {
        edges.push_back({a, a + 1, h * 0.5f * (p[a] + p[a + 1]), std::min(wcell[a], wcell[a + 1])});
      }
      if (r + 1 < rows && valid[a + cols]) {
        // Image rows go down, Y goes up.
        edges.push_back({a, a + cols, -h * 0.5f * (q[a] + q[a + cols]), std::min(wcell[a], wcell[a + cols])});
      }
    }
  }
  // Normal equations (weighted graph Laplacian + a weak pull to the current z),
  // solved by Jacobi-preconditioned conjugate gradients from the current z.
  const float lambda = 1e-4f;
  std::vector<double> diag(total, 0.0), rhs(total, 0.0);
  for (int i = 0; i < total; ++i)
    if (valid[i]) {
      diag[i] = lambda;
      rhs[i] = lambda * zp[i];
    }
  for (const Edge& e : edges) {
    diag[e.a] += e.w;
    diag[e.b] += e.w;
    rhs[e.a] -= e.w * e.d;
    rhs[e.b] += e.w * e.d;
  }
  auto apply = [&](const std::vector<double>& x, std::vector<double>& y) {
    for (int i = 0; i < total; ++i) y[i] = valid[i] ? lambda * x[i] : 0.0;
    for (const Edge& e : edges) {
      const double t = e.w * (x[e.a] - x[e.b]);
      y[e.a] += t;
      y[e.b] -= t;
    }
  };
  std::vector<double> x(total, 0.0), res(total), z(total), dir(total), ad(total);
  for (int i = 0; i < total; ++i) x[i] = valid[i] ? zp[i] : 0.0;
  apply(x, ad);
  double rz = 0, bnorm = 0;
  for (int i = 0; i < total; ++i) {
    res[i] = valid[i] ? rhs[i] - ad[i] : 0.0;
    z[i] = valid[i] ? res[i] / diag[i] : 0.0;
    dir[i] = z[i];
    rz += res[i] * z[i];
    bnorm += rhs[i] * rhs[i];
  }
  const double tol = 1e-12 * std::max(bnorm, 1e-30);
  for (int it = 0; it < 2000; ++it) {
    double rr = 0;
    for (int i = 0; i < total; ++i) rr += res[i] * res[i];
    if (rr <= tol) break;
    apply(dir, ad);
    double dad = 0;
    for (int i = 0; i < total; ++i) dad += dir[i] * ad[i];
    if (!(dad > 0)) break;
    const double alpha = rz / dad;
    double rz_new = 0;
    for (int i = 0; i < total; ++i) {
      if (!valid[i]) continue;
      x[i] += alpha * dir[i];
      res[i] -= alpha * ad[i];
      z[i] = res[i] / diag[i];
      rz_new += res[i] * z[i];
    }
    const double beta = rz_new / rz;
    rz = rz_new;
    for (int i = 0; i < total; ++i) dir[i] = valid[i] ? z[i] + beta * dir[i] : 0.0;
  }
  // Anchor every connected part at its occluding contour (see depth.hpp).
  std::vector<int> label(total, -1);
  std::vector<int> stack;
  std::vector<double> offsets;
  float* out = g.z.ptr<float>();
  for (int s = 0; s < total; ++s) {
    if (!valid[s] || label[s] >= 0) continue;
    std::vector<int> part;
    stack.assign(1, s);
    label[s] = s;
    double all_sum = 0;
    offsets.clear();
    while (!stack.empty()) {
      const int i = stack.back();
      stack.pop_back();
      part.push_back(i);
      const int r = i / cols, c = i % cols;
      bool border = false;
      const int nb[4][2] = {{r - 1, c}, {r + 1, c}, {r, c - 1}, {r, c + 1}};
      for (auto& pp : nb) {
        if (pp[0] < 0 || pp[0] >= rows || pp[1] < 0 || pp[1] >= cols) {
          border = true;
          continue;
        }
        const int j = pp[0] * cols + pp[1];
        if (!valid[j]) {
          border = true;
          continue;
        }
        if (label[j] < 0) {
          label[j] = s;
          stack.push_back(j);
        }
      }
      all_sum += x[i];
      if (!border) continue;
      // Walk from the cell along the outward image-plane normal to the mask's edge.
      const cv::Vec3f n = g.normals.at<cv::Vec3f>(r, c);
      const float lat = std::sqrt(n[0] * n[0] + n[1] * n[1]);
      double rise = 0;
      if (lat > 0.05f && !g.full_mask.empty()) {
        const float dx = n[0] / lat, dy = -n[1] / lat;
        const int px = g.x0 + c * g.step, py = g.y0 + r * g.step;
        const int limit = 3 * g.step + 2;
        int dist = limit;
        for (int k = 1; k <= limit; ++k) {
          const int qx = int(std::lround(px + dx * k)), qy = int(std::lround(py + dy * k));
          if (qx < 0 || qy < 0 || qx >= g.full_mask.cols || qy >= g.full_mask.rows ||
              !g.full_mask.at<uint8_t>(qy, qx)) {
            dist = k;
            break;
          }
        }
        const double d_m = (dist - 0.5) * (1.0 - x[i]) / g.f;
        const double slope = std::min(double(lat) / std::max(double(n[2]), 0.05), 20.0);
        rise = 2.0 * d_m * slope;
      }
      offsets.push_back(x[i] - rise);
    }
    double shift = all_sum / double(part.size());
    if (!offsets.empty()) {
      std::nth_element(offsets.begin(), offsets.begin() + offsets.size() / 2, offsets.end());
      shift = offsets[offsets.size() / 2];
    }
    for (int i : part) out[i] = static_cast<float>(std::clamp(x[i] - shift, -0.5, 0.5));
  }
  fill_outside(g.z, valid);
  return true;
}

cv::Mat upsample_depth(const DepthGrid& g, cv::Size size) {
  cv::Mat full(size, CV_32FC1);
  const float inv = 1.f / g.step;
  tbb::parallel_for(tbb::blocked_range<int>(0, size.height, 16), [&](const tbb::blocked_range<int>& rr) {
    for (int y = rr.begin(); y < rr.end(); ++y) {
      const float fy = std::clamp((y - g.y0) * inv, 0.f, float(g.rows - 1));
      const int r0 = std::min(int(fy), g.rows - 1), r1 = std::min(r0 + 1, g.rows - 1);
      const float ty = fy - r0;
      const float* z0 = g.z.ptr<float>(r0);
      const float* z1 = g.z.ptr<float>(r1);
      float* o = full.ptr<float>(y);
      for (int x = 0; x < size.width; ++x) {
        const float fx = std::clamp((x - g.x0) * inv, 0.f, float(g.cols - 1));
        const int c0 = std::min(int(fx), g.cols - 1), c1 = std::min(c0 + 1, g.cols - 1);
        const float tx = fx - c0;
        const float top = z0[c0] + (z0[c1] - z0[c0]) * tx;
        const float bot = z1[c0] + (z1[c1] - z1[c0]) * tx;
        o[x] = top + (bot - top) * ty;
      }
    }
  });
  return full;
}

}  // namespace veneer::ps
