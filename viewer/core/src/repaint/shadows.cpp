// Cast shadows from the normals (shadows.hpp).
#include "veneer/repaint/shadows.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <string>

#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>

namespace veneer::repaint {

Status ShadowOptions::check() const {
  if (azimuths < 8 || azimuths > 256)
    return make_error("shadows: azimuths " + std::to_string(azimuths) + " is outside 8..256");
  if (!(softness_deg >= 0.1 && softness_deg <= 45))
    return make_error("shadows: softness_deg " + std::to_string(softness_deg) + " is outside [0.1, 45]");
  if (!(max_slope >= 1 && max_slope <= 1000))
    return make_error("shadows: max_slope " + std::to_string(max_slope) + " is outside [1, 1000]");
  if (max_cells < 1000 || max_cells > 100000000)
    return make_error("shadows: max_cells " + std::to_string(max_cells) + " is outside 1000..10^8");
  if (!(near_px >= 0 && near_px <= 64))
    return make_error("shadows: near_px " + std::to_string(near_px) + " is outside [0, 64]");
  if (!(min_visibility >= 0 && min_visibility <= 1))
    return make_error("shadows: min_visibility " + std::to_string(min_visibility) + " is outside [0, 1]");
  if (!(observed_window_deg >= 0 && observed_window_deg <= 180))
    return make_error("shadows: observed_window_deg " + std::to_string(observed_window_deg) + " is outside [0, 180]");
  if (!(observed_reach_deg >= 0 && observed_reach_deg <= 180))
    return make_error("shadows: observed_reach_deg " + std::to_string(observed_reach_deg) + " is outside [0, 180]");
  if (!(observed_below_deg >= 0 && observed_below_deg <= 90))
    return make_error("shadows: observed_below_deg " + std::to_string(observed_below_deg) + " is outside [0, 90]");
  if (!(observed_margin_deg >= 0 && observed_margin_deg <= 30))
    return make_error("shadows: observed_margin_deg " + std::to_string(observed_margin_deg) + " is outside [0, 30]");
  return {};
}

namespace {

constexpr float kCodePerDeg = 255.f / 90.f;  // a horizon's elevation, 0..90 degrees, in a byte

// One level of the height field's grid: object cells, their slopes, their heights (in the level's own cells).
struct Level {
  int w = 0, h = 0;
  std::vector<uint8_t> valid;
  std::vector<float> p, q;  // dz/dx, dz/dy (image axes, y down)
  std::vector<float> z;
};

// The grid at `step` pixels per cell: a cell is object when at least half its pixels are; its slopes from its
// pixels' mean normal.
Level base_level(const cv::Mat& normals, const cv::Mat& mask, int step, float max_slope) {
  Level g;
  g.w = (mask.cols + step - 1) / step;
  g.h = (mask.rows + step - 1) / step;
  const size_t cells = static_cast<size_t>(g.w) * g.h;
  g.valid.assign(cells, 0);
  g.p.assign(cells, 0.f);
  g.q.assign(cells, 0.f);
  g.z.assign(cells, 0.f);
  cv::parallel_for_(cv::Range(0, g.h), [&](const cv::Range& rows) {
    for (int cy = rows.start; cy < rows.end; ++cy)
      for (int cx = 0; cx < g.w; ++cx) {
        cv::Vec3f sum(0, 0, 0);
        int in = 0, all = 0;
        for (int y = cy * step; y < std::min(mask.rows, (cy + 1) * step); ++y)
          for (int x = cx * step; x < std::min(mask.cols, (cx + 1) * step); ++x) {
            ++all;
            if (!mask.at<uchar>(y, x)) continue;
            const cv::Vec3f n = normals.at<cv::Vec3f>(y, x);
            if (n.dot(n) < 0.25f) continue;
            sum += n;
            ++in;
          }
        if (in == 0 || 2 * in < all) continue;
        const size_t i = static_cast<size_t>(cy) * g.w + cx;
        const float len = std::sqrt(sum.dot(sum));
        if (!(len > 0)) continue;
        const cv::Vec3f n = sum / len;
        const float nz = std::max(n[2], 1e-3f);
        g.valid[i] = 1;
        g.p[i] = std::clamp(-n[0] / nz, -max_slope, max_slope);
        g.q[i] = std::clamp(n[1] / nz, -max_slope, max_slope);  // the rig's y goes up, the image's down
      }
  });
  return g;
}

// The level of half the resolution: a cell is object when any of its four is; slopes averaged.
Level coarser(const Level& f) {
  Level c;
  c.w = (f.w + 1) / 2;
  c.h = (f.h + 1) / 2;
  const size_t cells = static_cast<size_t>(c.w) * c.h;
  c.valid.assign(cells, 0);
  c.p.assign(cells, 0.f);
  c.q.assign(cells, 0.f);
  c.z.assign(cells, 0.f);
  for (int y = 0; y < c.h; ++y)
    for (int x = 0; x < c.w; ++x) {
      float sp = 0, sq = 0;
      int in = 0;
      for (int dy = 0; dy < 2; ++dy)
        for (int dx = 0; dx < 2; ++dx) {
          const int fx = 2 * x + dx, fy = 2 * y + dy;
          if (fx >= f.w || fy >= f.h) continue;
          const size_t j = static_cast<size_t>(fy) * f.w + fx;
          if (!f.valid[j]) continue;
          sp += f.p[j], sq += f.q[j], ++in;
        }
      if (in == 0) continue;
      const size_t i = static_cast<size_t>(y) * c.w + x;
      c.valid[i] = 1;
      c.p[i] = sp / in, c.q[i] = sq / in;
    }
  return c;
}

// Least squares over the edges between neighbouring object cells (z_b - z_a = the mean slope between them), a
// weak pull to the start, by Jacobi-preconditioned conjugate gradients from the level's z.
bool solve_level(Level& g, int max_iterations, double tolerance, const Progress& progress) {
  const int w = g.w, h = g.h;
  std::vector<int> index(static_cast<size_t>(w) * h, -1), cell;
  for (int i = 0; i < w * h; ++i)
    if (g.valid[i]) index[i] = static_cast<int>(cell.size()), cell.push_back(i);
  const int n = static_cast<int>(cell.size());
  if (n == 0) return true;
  struct Edge {
    int a, b;
    float d;
  };
  std::vector<Edge> edges;
  edges.reserve(static_cast<size_t>(n) * 2);
  for (int k = 0; k < n; ++k) {
    const int i = cell[k], x = i % w, y = i / w;
    if (x + 1 < w && index[i + 1] >= 0) edges.push_back({k, index[i + 1], 0.5f * (g.p[i] + g.p[i + 1])});
    if (y + 1 < h && index[i + w] >= 0) edges.push_back({k, index[i + w], 0.5f * (g.q[i] + g.q[i + w])});
  }
  const double lambda = 1e-4;
  std::vector<double> x(n), diag(n, lambda), rhs(n);
  for (int k = 0; k < n; ++k) x[k] = g.z[cell[k]], rhs[k] = lambda * x[k];
  for (const Edge& e : edges) {
    diag[e.a] += 1, diag[e.b] += 1;
    rhs[e.a] -= e.d, rhs[e.b] += e.d;
  }
  auto apply = [&](const std::vector<double>& v, std::vector<double>& out) {
    for (int k = 0; k < n; ++k) out[k] = lambda * v[k];
    for (const Edge& e : edges) {
      const double t = v[e.a] - v[e.b];
      out[e.a] += t, out[e.b] -= t;
    }
  };
  std::vector<double> r(n), zz(n), dir(n), ad(n);
  apply(x, ad);
  double rz = 0, bnorm = 0;
  for (int k = 0; k < n; ++k) {
    r[k] = rhs[k] - ad[k];
    zz[k] = r[k] / diag[k];
    dir[k] = zz[k];
    rz += r[k] * zz[k];
    bnorm += rhs[k] * rhs[k];
  }
  const double tol = tolerance * tolerance * std::max(bnorm, 1e-30);
  for (int it = 0; it < max_iterations; ++it) {
    double rr = 0;
    for (int k = 0; k < n; ++k) rr += r[k] * r[k];
    if (rr <= tol) break;
    if ((it & 63) == 63 && progress.cancelled()) return false;
    apply(dir, ad);
    double dad = 0;
    for (int k = 0; k < n; ++k) dad += dir[k] * ad[k];
    if (!(dad > 0)) break;
    const double alpha = rz / dad;
    double rz_new = 0;
    for (int k = 0; k < n; ++k) {
      x[k] += alpha * dir[k];
      r[k] -= alpha * ad[k];
      zz[k] = r[k] / diag[k];
      rz_new += r[k] * zz[k];
    }
    const double beta = rz_new / std::max(rz, 1e-300);
    rz = rz_new;
    for (int k = 0; k < n; ++k) dir[k] = zz[k] + beta * dir[k];
  }
  for (int k = 0; k < n; ++k) g.z[cell[k]] = static_cast<float>(x[k]);
  return true;
}

// The finer level's start from the coarser's solution: bilinear over the coarser's object cells, in the finer's
// units (twice the coarser's).
void prolong(const Level& c, Level& f) {
  for (int y = 0; y < f.h; ++y)
    for (int x = 0; x < f.w; ++x) {
      const size_t i = static_cast<size_t>(y) * f.w + x;
      if (!f.valid[i]) continue;
      const float cx = (x + 0.5f) / 2 - 0.5f, cy = (y + 0.5f) / 2 - 0.5f;
      const int x0 = static_cast<int>(std::floor(cx)), y0 = static_cast<int>(std::floor(cy));
      const float fx = cx - x0, fy = cy - y0;
      float sw = 0, sz = 0;
      for (int dy = 0; dy < 2; ++dy)
        for (int dx = 0; dx < 2; ++dx) {
          const int xx = x0 + dx, yy = y0 + dy;
          if (xx < 0 || yy < 0 || xx >= c.w || yy >= c.h) continue;
          const size_t j = static_cast<size_t>(yy) * c.w + xx;
          if (!c.valid[j]) continue;
          const float wgt = (dx ? fx : 1 - fx) * (dy ? fy : 1 - fy);
          sw += wgt, sz += wgt * c.z[j];
        }
      const size_t parent = static_cast<size_t>(y / 2) * c.w + x / 2;
      f.z[i] = 2.f * (sw > 1e-6f ? sz / sw : c.z[parent]);
    }
}

// Each connected part of the grid's object cells moved so that its outline's mean height is 0.
void anchor_parts(Level& g) {
  cv::Mat valid(g.h, g.w, CV_8UC1, g.valid.data());
  cv::Mat labels;
  const int parts = cv::connectedComponents(valid, labels, 4, CV_32S);
  std::vector<double> sum(parts, 0.0);
  std::vector<int> count(parts, 0);
  for (int y = 0; y < g.h; ++y)
    for (int x = 0; x < g.w; ++x) {
      const size_t i = static_cast<size_t>(y) * g.w + x;
      if (!g.valid[i]) continue;
      const bool outline = x == 0 || y == 0 || x + 1 == g.w || y + 1 == g.h || !g.valid[i - 1] || !g.valid[i + 1] ||
                           !g.valid[i - g.w] || !g.valid[i + g.w];
      if (!outline) continue;
      const int l = labels.at<int>(y, x);
      sum[l] += g.z[i], ++count[l];
    }
  for (int y = 0; y < g.h; ++y)
    for (int x = 0; x < g.w; ++x) {
      const size_t i = static_cast<size_t>(y) * g.w + x;
      const int l = labels.at<int>(y, x);
      if (g.valid[i] && count[l] > 0) g.z[i] -= static_cast<float>(sum[l] / count[l]);
    }
}

Status check_inputs(const cv::Mat& values, int type, const cv::Mat& mask, const char* what) {
  if (mask.empty() || mask.type() != CV_8UC1) return make_error("shadows: the mask must be CV_8UC1");
  if (values.type() != type || values.size() != mask.size())
    return make_error(std::string("shadows: the ") + what + " must be " + (type == CV_32FC3 ? "CV_32FC3" : "CV_32FC1") +
                      " of the mask's size (" + std::to_string(mask.cols) + "x" + std::to_string(mask.rows) + ")");
  if (cv::countNonZero(mask) == 0) return make_error("shadows: the mask is empty");
  return {};
}

// The grid's heights in pixels (CV_32FC1, grid-sized, 0 outside) and its object cells (CV_8UC1).
Status solve_grid(const cv::Mat& normals, const cv::Mat& mask, int step, double max_slope, cv::Mat* height,
                  cv::Mat* cells, const Progress& progress) {
  std::vector<Level> levels;
  levels.push_back(base_level(normals, mask, step, static_cast<float>(max_slope)));
  while (std::max(levels.back().w, levels.back().h) > 32) levels.push_back(coarser(levels.back()));
  for (int l = static_cast<int>(levels.size()) - 1; l >= 0; --l) {
    if (l + 1 < static_cast<int>(levels.size())) prolong(levels[l + 1], levels[l]);
    const bool coarsest = l + 1 == static_cast<int>(levels.size());
    if (!solve_level(levels[l], coarsest ? 4000 : 400, coarsest ? 1e-8 : 1e-5, progress))
      return make_error("shadows: cancelled");
    progress.report(0.5 * (1.0 - static_cast<double>(l) / levels.size()), "height from normals");
  }
  Level& g = levels.front();
  anchor_parts(g);
  *height = cv::Mat(g.h, g.w, CV_32FC1);
  *cells = cv::Mat(g.h, g.w, CV_8UC1);
  for (int i = 0; i < g.w * g.h; ++i) {
    height->at<float>(i / g.w, i % g.w) = g.valid[i] ? g.z[i] * static_cast<float>(step) : 0.f;
    cells->at<uchar>(i / g.w, i % g.w) = g.valid[i] ? 255 : 0;
  }
  return {};
}

// Bilinear weights of pixel (x, y) on a grid of `step` pixels per cell (cell centres at (c + 0.5) step - 0.5).
struct Bilinear {
  int x0, y0;
  float fx, fy;
};
inline Bilinear bilinear(int x, int y, int step) {
  const float gx = (x + 0.5f) / step - 0.5f, gy = (y + 0.5f) / step - 0.5f;
  const int x0 = static_cast<int>(std::floor(gx)), y0 = static_cast<int>(std::floor(gy));
  return {x0, y0, gx - x0, gy - y0};
}

// One azimuth's horizons over the box's object cells, into `plane` (CV_8UC1 of the box).
void sweep(const cv::Mat& height, const cv::Mat& cells, const cv::Rect& box, int step, double theta, int near_cells,
           cv::Mat& plane) {
  const double c = std::cos(theta), s = std::sin(theta);
  // the box's cells in (t, o): t along the azimuth, o across it
  double tmin = 1e30, tmax = -1e30, omin = 1e30, omax = -1e30;
  for (int v : {0, box.height - 1})
    for (int u : {0, box.width - 1}) {
      const double t = u * c + v * s, o = -u * s + v * c;
      tmin = std::min(tmin, t), tmax = std::max(tmax, t), omin = std::min(omin, o), omax = std::max(omax, o);
    }
  tmin = std::floor(tmin) - 1, omin = std::floor(omin) - 1;
  const int nt = static_cast<int>(std::ceil(tmax) - tmin) + 2, no = static_cast<int>(std::ceil(omax) - omin) + 2;
  cv::Mat R(no, nt, CV_32FC1, cv::Scalar(-1));  // the horizon's elevation in degrees; -1: no object there
  std::vector<float> H(nt);
  std::vector<cv::Vec2f> hull;  // (u = -t, height) of the samples behind, their upper hull
  const float inv_step = 1.f / step;
  for (int j = 0; j < no; ++j) {
    const double o = omin + j;
    for (int i = 0; i < nt; ++i) {
      const double t = tmin + i;
      const double u = t * c - o * s + box.x, v = t * s + o * c + box.y;
      H[i] = std::numeric_limits<float>::quiet_NaN();
      const int xr = static_cast<int>(std::lround(u)), yr = static_cast<int>(std::lround(v));
      if (xr < 0 || yr < 0 || xr >= cells.cols || yr >= cells.rows || !cells.at<uchar>(yr, xr)) continue;
      const int x0 = static_cast<int>(std::floor(u)), y0 = static_cast<int>(std::floor(v));
      const float fx = static_cast<float>(u - x0), fy = static_cast<float>(v - y0);
      float sw = 0, sz = 0;
      for (int dy = 0; dy < 2; ++dy)
        for (int dx = 0; dx < 2; ++dx) {
          const int xx = x0 + dx, yy = y0 + dy;
          if (xx < 0 || yy < 0 || xx >= cells.cols || yy >= cells.rows || !cells.at<uchar>(yy, xx)) continue;
          const float wgt = (dx ? fx : 1 - fx) * (dy ? fy : 1 - fy);
          sw += wgt, sz += wgt * height.at<float>(yy, xx);
        }
      H[i] = sw > 1e-6f ? sz / sw * inv_step : height.at<float>(yr, xr) * inv_step;  // in cells
    }
    hull.clear();
    float* out = R.ptr<float>(j);
    for (int i = nt - 1; i >= 0; --i) {
      // the sample near_cells ahead joins the hull (points come in increasing u = -t)
      const int k = i + near_cells;
      if (k < nt && !std::isnan(H[k])) {
        const cv::Vec2f p(static_cast<float>(-k), H[k]);
        while (hull.size() >= 2) {
          const cv::Vec2f& a = hull[hull.size() - 2];
          const cv::Vec2f& b = hull.back();
          // b on or below the line a-p: not on the upper hull
          if ((b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]) >= 0)
            hull.pop_back();
          else
            break;
        }
        hull.push_back(p);
      }
      if (std::isnan(H[i])) continue;
      if (hull.empty()) {
        out[i] = 0;
        continue;
      }
      // the hull point seen highest from (u_i, H[i]): the slopes from it are unimodal along the hull
      const float ui = static_cast<float>(-i), hi = H[i];
      auto slope = [&](const cv::Vec2f& q) { return (q[1] - hi) / (ui - q[0]); };
      int lo = 0, up = static_cast<int>(hull.size()) - 1;
      while (lo < up) {
        const int mid = (lo + up) / 2;
        if (slope(hull[mid]) < slope(hull[mid + 1]))
          lo = mid + 1;
        else
          up = mid;
      }
      const float best = slope(hull[lo]);
      out[i] = best > 0 ? static_cast<float>(std::atan(best) * 180 / CV_PI) : 0.f;
    }
  }
  // back to the box's cells
  plane = cv::Mat(box.size(), CV_8UC1, cv::Scalar(0));
  for (int v = 0; v < box.height; ++v)
    for (int u = 0; u < box.width; ++u) {
      if (!cells.at<uchar>(v + box.y, u + box.x)) continue;
      const double t = u * c + v * s - tmin, o = -u * s + v * c - omin;
      const int i0 = static_cast<int>(std::floor(t)), j0 = static_cast<int>(std::floor(o));
      const float ft = static_cast<float>(t - i0), fo = static_cast<float>(o - j0);
      float sw = 0, sa = 0;
      for (int dj = 0; dj < 2; ++dj)
        for (int di = 0; di < 2; ++di) {
          const int ii = i0 + di, jj = j0 + dj;
          if (ii < 0 || jj < 0 || ii >= nt || jj >= no) continue;
          const float a = R.at<float>(jj, ii);
          if (a < 0) continue;
          const float wgt = (di ? ft : 1 - ft) * (dj ? fo : 1 - fo);
          sw += wgt, sa += wgt * a;
        }
      if (sw > 1e-6f) plane.at<uchar>(v, u) = cv::saturate_cast<uchar>(sa / sw * kCodePerDeg);
    }
}

}  // namespace

Expected<cv::Mat> height_from_normals(const cv::Mat& normals, const cv::Mat& mask, int step, double max_slope,
                                      const Progress& progress) {
  if (auto s = check_inputs(normals, CV_32FC3, mask, "normals"); !s) return s.error();
  if (step < 1 || step > 64) return make_error("shadows: step " + std::to_string(step) + " is outside 1..64");
  if (!(max_slope >= 1 && max_slope <= 1000))
    return make_error("shadows: max_slope " + std::to_string(max_slope) + " is outside [1, 1000]");
  cv::Mat grid, cells;
  if (auto s = solve_grid(normals, mask, step, max_slope, &grid, &cells, progress); !s) return s.error();
  cv::Mat out(mask.size(), CV_32FC1, cv::Scalar(0));
  cv::parallel_for_(cv::Range(0, mask.rows), [&](const cv::Range& rows) {
    for (int y = rows.start; y < rows.end; ++y)
      for (int x = 0; x < mask.cols; ++x) {
        if (!mask.at<uchar>(y, x)) continue;
        const Bilinear b = bilinear(x, y, step);
        float sw = 0, sz = 0;
        for (int dy = 0; dy < 2; ++dy)
          for (int dx = 0; dx < 2; ++dx) {
            const int xx = b.x0 + dx, yy = b.y0 + dy;
            if (xx < 0 || yy < 0 || xx >= grid.cols || yy >= grid.rows || !cells.at<uchar>(yy, xx)) continue;
            const float wgt = (dx ? b.fx : 1 - b.fx) * (dy ? b.fy : 1 - b.fy);
            sw += wgt, sz += wgt * grid.at<float>(yy, xx);
          }
        out.at<float>(y, x) = sw > 1e-6f ? sz / sw : 0.f;
      }
  });
  return out;
}

Expected<ShadowMap> ShadowMap::make(const cv::Mat& normals, const cv::Mat& mask, const ShadowOptions& options,
                                    const Progress& progress) {
  if (auto s = options.check(); !s) return s.error();
  if (auto s = check_inputs(normals, CV_32FC3, mask, "normals"); !s) return s.error();
  const double object = cv::countNonZero(mask);
  int step = 1;
  while (object / (static_cast<double>(step) * step) > options.max_cells) ++step;
  ShadowMap map;
  map.options_ = options;
  map.size_ = mask.size();
  map.step_ = step;
  if (auto s = solve_grid(normals, mask, step, options.max_slope, &map.height_, &map.cells_, progress.part(0, 0.5));
      !s)
    return s.error();
  if (auto s = map.sweep_all(progress.part(0.5, 1.0)); !s) return s.error();
  return map;
}

Expected<ShadowMap> ShadowMap::from_height(const cv::Mat& height, const cv::Mat& mask, int step,
                                           const ShadowOptions& options, const Progress& progress) {
  if (auto s = options.check(); !s) return s.error();
  if (auto s = check_inputs(height, CV_32FC1, mask, "height"); !s) return s.error();
  if (step < 1 || step > 64) return make_error("shadows: step " + std::to_string(step) + " is outside 1..64");
  ShadowMap map;
  map.options_ = options;
  map.size_ = mask.size();
  map.step_ = step;
  // the grid: a cell is object when at least half its pixels are; its height their mean
  const int gw = (mask.cols + step - 1) / step, gh = (mask.rows + step - 1) / step;
  map.height_ = cv::Mat(gh, gw, CV_32FC1, cv::Scalar(0));
  map.cells_ = cv::Mat(gh, gw, CV_8UC1, cv::Scalar(0));
  for (int cy = 0; cy < gh; ++cy)
    for (int cx = 0; cx < gw; ++cx) {
      double sum = 0;
      int in = 0, all = 0;
      for (int y = cy * step; y < std::min(mask.rows, (cy + 1) * step); ++y)
        for (int x = cx * step; x < std::min(mask.cols, (cx + 1) * step); ++x) {
          ++all;
          if (mask.at<uchar>(y, x)) sum += height.at<float>(y, x), ++in;
        }
      if (in == 0 || 2 * in < all) continue;
      map.cells_.at<uchar>(cy, cx) = 255;
      map.height_.at<float>(cy, cx) = static_cast<float>(sum / in);
    }
  if (auto s = map.sweep_all(progress); !s) return s.error();
  return map;
}

Status ShadowMap::sweep_all(const Progress& progress) {
  box_ = cv::boundingRect(cells_);
  const int k_all = options_.azimuths;
  const int near_cells = std::max(1, static_cast<int>(std::ceil(options_.near_px / step_ - 1e-9)));
  planes_.assign(k_all, cv::Mat());
  std::atomic<int> done{0};
  std::atomic<bool> stop{false};
  cv::parallel_for_(cv::Range(0, k_all), [&](const cv::Range& r) {
    for (int k = r.start; k < r.end; ++k) {
      if (stop || progress.cancelled()) {
        stop = true;
        return;
      }
      sweep(height_, cells_, box_, step_, 2 * CV_PI * k / k_all, near_cells, planes_[k]);
      progress.report(static_cast<double>(++done) / k_all, "horizons");
    }
  });
  if (stop) return make_error("shadows: cancelled");
  return {};
}

float ShadowMap::code_at(int x, int y, int k) const { return code_at(planes_, x, y, k); }

float ShadowMap::code_at(const std::vector<cv::Mat>& planes, int x, int y, int k) const {
  const Bilinear b = bilinear(x, y, step_);
  const cv::Mat& plane = planes[k];
  float sw = 0, sa = 0;
  for (int dy = 0; dy < 2; ++dy)
    for (int dx = 0; dx < 2; ++dx) {
      const int xx = b.x0 + dx, yy = b.y0 + dy;
      if (xx < 0 || yy < 0 || xx >= cells_.cols || yy >= cells_.rows || !cells_.at<uchar>(yy, xx)) continue;
      const float wgt = (dx ? b.fx : 1 - b.fx) * (dy ? b.fy : 1 - b.fy);
      sw += wgt, sa += wgt * plane.at<uchar>(yy - box_.y, xx - box_.x);
    }
  if (sw > 1e-6f) return sa / sw;
  // a pixel whose cells are all outside the object: its nearest cell's
  const int xn = std::clamp((x / step_), box_.x, box_.x + box_.width - 1);
  const int yn = std::clamp((y / step_), box_.y, box_.y + box_.height - 1);
  return cells_.at<uchar>(yn, xn) ? plane.at<uchar>(yn - box_.y, xn - box_.x) : 0.f;
}

Status ShadowMap::observe(const std::vector<cv::Vec3d>& lamps, const std::vector<cv::Mat>& shadowed,
                          const std::vector<cv::Mat>& lit) {
  if (shadowed.size() != lamps.size() || lit.size() != lamps.size())
    return make_error("shadows: " + std::to_string(lamps.size()) + " lamps, " + std::to_string(shadowed.size()) +
                      " shadow masks and " + std::to_string(lit.size()) + " lit masks");
  for (size_t i = 0; i < lamps.size(); ++i)
    if (shadowed[i].type() != CV_8UC1 || shadowed[i].size() != size_ || lit[i].type() != CV_8UC1 ||
        lit[i].size() != size_)
      return make_error("shadows: the photos' shadow masks must be CV_8UC1 of the map's size");
  const int k_all = azimuths();
  const float margin = static_cast<float>(options_.observed_margin_deg);
  const double window = options_.observed_window_deg;
  // per lamp: its elevation and the azimuths its window covers
  struct Lamp {
    float elevation;
    std::vector<int> ks;
  };
  // an azimuth takes what the lamps nearest it in azimuth saw (within `window` of the nearest, and 90 degrees):
  // between two lamps each speaks for its half, across a gap in the ring (the thesis rig's empty socket) too
  std::vector<Lamp> info(lamps.size());
  std::vector<double> az(lamps.size(), 0.0);
  std::vector<uint8_t> has(lamps.size(), 0);
  for (size_t i = 0; i < lamps.size(); ++i) {
    const cv::Vec3d& l = lamps[i];
    info[i].elevation = static_cast<float>(std::atan2(l[2], std::hypot(l[0], l[1])) * 180 / CV_PI);
    has[i] = std::hypot(l[0], l[1]) > 1e-3 * cv::norm(l);  // a lamp on the axis has no azimuth
    az[i] = std::atan2(-l[1], l[0]) * 180 / CV_PI;
  }
  for (int k = 0; k < k_all; ++k) {
    std::vector<double> d(lamps.size(), 1e9);
    double nearest = 1e9;
    for (size_t i = 0; i < lamps.size(); ++i)
      if (has[i]) d[i] = std::abs(std::remainder(360.0 * k / k_all - az[i], 360.0)), nearest = std::min(nearest, d[i]);
    for (size_t i = 0; i < lamps.size(); ++i)
      if (d[i] <= std::min(nearest + window, options_.observed_reach_deg)) info[i].ks.push_back(k);
  }
  for (cv::Mat& p : planes_) p = p.clone();  // a copy of this map (sharing the planes) keeps its own
  const bool height_field = options_.observed_below_deg >= 90;
  if (!height_field) {
    if (observed_.empty())
      for (const cv::Mat& p : planes_) observed_.push_back(cv::Mat(p.size(), CV_8UC1, cv::Scalar(0)));
    else
      for (cv::Mat& p : observed_) p = p.clone();
  }
  // per cell, what the photos say: the share of its pixels in shadow, lit
  cv::parallel_for_(cv::Range(box_.y, box_.y + box_.height), [&](const cv::Range& rows) {
    for (int cy = rows.start; cy < rows.end; ++cy)
      for (int cx = box_.x; cx < box_.x + box_.width; ++cx) {
        if (!cells_.at<uchar>(cy, cx)) continue;
        for (int pass = 0; pass < 2; ++pass)  // lit first: where two lamps' windows overlap the shadow wins
          for (size_t i = 0; i < lamps.size(); ++i) {
            const cv::Mat& m = pass == 0 ? lit[i] : shadowed[i];
            int on = 0, all = 0;
            for (int y = cy * step_; y < std::min(size_.height, (cy + 1) * step_); ++y)
              for (int x = cx * step_; x < std::min(size_.width, (cx + 1) * step_); ++x) ++all, on += m.at<uchar>(y, x) != 0;
            if (2 * on <= all) continue;
            const float bound = (info[i].elevation + (pass == 0 ? -margin : margin)) * kCodePerDeg;
            const uchar code = cv::saturate_cast<uchar>(bound);
            for (int k : info[i].ks) {
              if (pass == 1 && !height_field) {  // kept apart: it holds only down to observed_below_deg
                uchar& o = observed_[k].at<uchar>(cy - box_.y, cx - box_.x);
                o = std::max(o, cv::saturate_cast<uchar>(info[i].elevation * kCodePerDeg));
                continue;
              }
              uchar& h = planes_[k].at<uchar>(cy - box_.y, cx - box_.x);
              h = pass == 0 ? std::min(h, code) : std::max(h, code);
            }
          }
      }
  });
  return {};
}

Expected<PhotoShadows> photo_shadows(const std::vector<cv::Mat>& photos, const cv::Mat& normals, const cv::Mat& mask,
                                     const std::vector<cv::Vec3d>& lamps, double dark, double bright) {
  if (auto s = check_inputs(normals, CV_32FC3, mask, "normals"); !s) return s.error();
  if (photos.size() != lamps.size())
    return make_error("shadows: " + std::to_string(photos.size()) + " photos for " + std::to_string(lamps.size()) +
                      " lamps");
  for (const cv::Mat& p : photos)
    if ((p.type() != CV_32FC3 && p.type() != CV_32FC1) || p.size() != mask.size())
      return make_error("shadows: the photos must be CV_32FC3 or CV_32FC1 of the mask's size");
  std::vector<cv::Vec3f> dirs;
  for (const cv::Vec3d& l : lamps) {
    const cv::Vec3d u = l / std::max(1e-12, cv::norm(l));
    dirs.emplace_back(static_cast<float>(u[0]), static_cast<float>(u[1]), static_cast<float>(u[2]));
  }
  PhotoShadows out;
  out.albedo = cv::Mat(mask.size(), CV_32FC1, cv::Scalar(0));
  for (size_t i = 0; i < photos.size(); ++i) {
    out.shadowed.emplace_back(mask.size(), CV_8UC1, cv::Scalar(0));
    out.lit.emplace_back(mask.size(), CV_8UC1, cv::Scalar(0));
  }
  auto grey_at = [&](size_t i, int y, int x) {
    if (photos[i].type() == CV_32FC1) return photos[i].at<float>(y, x);
    const cv::Vec3f v = photos[i].at<cv::Vec3f>(y, x);
    return (v[0] + v[1] + v[2]) / 3.f;
  };
  cv::parallel_for_(cv::Range(0, mask.rows), [&](const cv::Range& rows) {
    std::vector<float> r;
    for (int y = rows.start; y < rows.end; ++y)
      for (int x = 0; x < mask.cols; ++x) {
        if (!mask.at<uchar>(y, x)) continue;
        const cv::Vec3f n = normals.at<cv::Vec3f>(y, x);
        r.clear();
        for (size_t i = 0; i < dirs.size(); ++i) {
          const float nl = n.dot(dirs[i]);
          if (nl > 0.2f) r.push_back(grey_at(i, y, x) / nl);
        }
        if (r.empty()) continue;
        // the albedo from the brighter samples: up to half the lamps may be in a cast shadow
        const size_t at = (r.size() - 1) * 7 / 10;
        std::nth_element(r.begin(), r.begin() + static_cast<long>(at), r.end());
        const float rho = r[at];
        out.albedo.at<float>(y, x) = rho;
        for (size_t i = 0; i < dirs.size(); ++i) {
          const float nl = n.dot(dirs[i]);
          if (nl <= 0.2f) continue;
          const float g = grey_at(i, y, x), pred = rho * nl;
          if (g < static_cast<float>(dark) * pred) out.shadowed[i].at<uchar>(y, x) = 255;
          if (g > static_cast<float>(bright) * pred) out.lit[i].at<uchar>(y, x) = 255;
        }
      }
  });
  return out;
}

float ShadowMap::horizon_deg(int x, int y, int k) const { return code_at(x, y, k) / kCodePerDeg; }

PixelHorizons ShadowMap::at(const std::vector<int>& pixels) const {
  PixelHorizons out;
  out.pixels_ = pixels;
  out.softness_deg_ = static_cast<float>(options_.softness_deg);
  out.min_visibility_ = static_cast<float>(options_.min_visibility);
  const int n = static_cast<int>(pixels.size()), k_all = azimuths();
  out.planes_ = cv::Mat(k_all, n, CV_8UC1, cv::Scalar(0));
  if (!observed_.empty()) out.observed_ = cv::Mat(k_all, n, CV_8UC1, cv::Scalar(0));
  out.observed_below_deg_ = static_cast<float>(options_.observed_below_deg);
  out.observed_margin_deg_ = static_cast<float>(options_.observed_margin_deg);
  cv::parallel_for_(cv::Range(0, n), [&](const cv::Range& r) {
    for (int i = r.start; i < r.end; ++i) {
      const int x = pixels[i] % size_.width, y = pixels[i] / size_.width;
      for (int k = 0; k < k_all; ++k) out.planes_.at<uchar>(k, i) = cv::saturate_cast<uchar>(code_at(x, y, k));
      if (!observed_.empty())
        for (int k = 0; k < k_all; ++k) {
          // nearest, not bilinear: an observed shadow's edge stays where the photo had it
          const int xn = std::clamp(x / step_ - box_.x, 0, box_.width - 1), yn = std::clamp(y / step_ - box_.y, 0, box_.height - 1);
          out.observed_.at<uchar>(k, i) = observed_[k].at<uchar>(yn, xn);
        }
    }
  });
  return out;
}

namespace {

// What a light direction asks of the horizons: the two azimuths about it, the weight of the second, and the
// visibility as a*code + b before clamping (code the horizon in bytes).
struct LightQuery {
  int k0 = 0, k1 = 0;
  float w1 = 0, a = 0, b = 1;
  float elevation = 90;  // degrees above the image plane
};
LightQuery query(const cv::Vec3d& l, int azimuths, float softness_deg) {
  LightQuery q;
  const double r = std::hypot(l[0], l[1]);
  const double elevation = std::atan2(l[2], r) * 180 / CV_PI;
  // the light's direction in the image (y down)
  double az = std::atan2(-l[1], l[0]) / (2 * CV_PI) * azimuths;
  az = std::fmod(az + azimuths, static_cast<double>(azimuths));
  q.k0 = std::min(static_cast<int>(std::floor(az)), azimuths - 1);
  q.k1 = (q.k0 + 1) % azimuths;
  q.w1 = static_cast<float>(az - q.k0);
  q.a = -1.f / (kCodePerDeg * softness_deg);
  q.b = static_cast<float>(elevation / softness_deg + 0.5);
  q.elevation = static_cast<float>(elevation);
  return q;
}

}  // namespace

cv::Mat ShadowMap::visibility(const cv::Vec3d& l) const {
  cv::Mat out(size_, CV_32FC1, cv::Scalar(1));
  const LightQuery q = query(l, azimuths(), static_cast<float>(options_.softness_deg));
  cv::parallel_for_(cv::Range(0, size_.height), [&](const cv::Range& rows) {
    for (int y = rows.start; y < rows.end; ++y) {
      float* o = out.ptr<float>(y);
      for (int x = 0; x < size_.width; ++x) {
        const Bilinear b = bilinear(x, y, step_);
        bool any = false;
        for (int dy = 0; dy < 2 && !any; ++dy)
          for (int dx = 0; dx < 2 && !any; ++dx) {
            const int xx = b.x0 + dx, yy = b.y0 + dy;
            any = xx >= 0 && yy >= 0 && xx < cells_.cols && yy < cells_.rows && cells_.at<uchar>(yy, xx);
          }
        if (!any) continue;
        const float code = (1 - q.w1) * code_at(x, y, q.k0) + q.w1 * code_at(x, y, q.k1);
        o[x] = std::clamp(q.a * code + q.b, static_cast<float>(options_.min_visibility), 1.f);
      }
    }
  });
  return out;
}

void PixelHorizons::visibility(const cv::Vec3d& l, int from, int count, float* out) const {
  const LightQuery q = query(l, planes_.rows, softness_deg_);
  const uchar* h0 = planes_.ptr<uchar>(q.k0) + from;
  const uchar* h1 = planes_.ptr<uchar>(q.k1) + from;
  const float a0 = q.a * (1 - q.w1), a1 = q.a * q.w1, b = q.b, lo = min_visibility_;
  for (int i = 0; i < count; ++i) out[i] = std::min(1.f, std::max(lo, a0 * h0[i] + a1 * h1[i] + b));
  if (observed_.empty()) return;
  // the photos' shadows: as a horizon at the lamp's elevation + margin, held down to observed_below_deg below it
  const uchar* o = observed_.ptr<uchar>(q.w1 < 0.5f ? q.k0 : q.k1) + from;
  const float e = q.elevation, soft = softness_deg_;
  for (int i = 0; i < count; ++i) {
    if (!o[i]) continue;
    const float lamp = o[i] / kCodePerDeg;
    const float above = std::clamp((lamp + observed_margin_deg_ - e) / soft + 0.5f, 0.f, 1.f);
    const float below = std::clamp((e - (lamp - observed_below_deg_ - 10.f)) / 10.f, 0.f, 1.f);
    out[i] = std::max(lo, std::min(out[i], 1.f - above * below));
  }
}

std::vector<float> PixelHorizons::visibility(const cv::Vec3d& l) const {
  std::vector<float> out(pixels_.size());
  if (!pixels_.empty()) visibility(l, 0, static_cast<int>(pixels_.size()), out.data());
  return out;
}

}  // namespace veneer::repaint
