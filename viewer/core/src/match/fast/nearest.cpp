// k nearest by the full feature distance (nearest.hpp).
//
// 1x1 features of 3 values (normals): the exact index over the values.
// Everything else: each patch vector v (P*P pixels x C channels) is projected
// on orthonormal functions -- per channel the patch mean (times P) and, for
// P > 1, its x and y ramps -- and the C channels of each onto their 3
// principal directions W (identity when C = 3): y has 3 (1x1) or 9 values.
// The rows of that linear map are orthonormal, so |y_a - y_b| <= |v_a - v_b|:
// the projected distance is a lower bound of the true one. The kd-tree over y
// gives candidates in order of that bound; they are re-ranked by the exact
// distance, and the k-th exact distance is proven final once it is below the
// bound of the first candidate not taken. Otherwise the list grows once (x4),
// after which the best found is kept (counted as not certified: approximate,
// see Stats::certified).
// Intensities at 1x1: when the 3 principal directions keep >= 99.9 % of the
// variance, a pixel the projection does not certify is looked up by the exact
// kd-tree at full dimension (exact); between 90 and 99.9 % the grown list's best
// is kept (approximate); below 90 % every pixel goes to the full-dimension tree.
#include "nearest.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <chrono>
#include <cstdio>

#include "index_fast.hpp"

namespace veneer::match::fast {

// Per channel, the patch's coefficients on three orthonormal spatial
// functions: the constant 1/P, and the ramps x/nu and y/nu (nu^2 = P * sum of
// i^2 over -r..r). Output rows: [mean (c), ramp x (c), ramp y (c)], or just the
// mean for 1x1.
// Interior pixels (patch wholly on the object) share work along each run of
// them on an image row: per column, the sums over the P rows (plain and
// weighted by dy), then per pixel the P columns of those -- (2 + 3) P c
// operations instead of 3 P^2 c. Rim pixels read their stored patch. Every
// value is summed in a fixed order, so the result does not depend on threads.
void patch_moments(const Object& o, int threads, std::vector<float>& out, int& per_row, bool means_only) {
  const int c = o.channels, p = o.patch, r = p / 2;
  const int parts = p > 1 && !means_only ? 3 : 1;
  per_row = parts * c;
  double sum_i2 = 0;
  for (int i = -r; i <= r; ++i) sum_i2 += i * i;
  const float inv_nu = p > 1 ? static_cast<float>(1.0 / std::sqrt(p * sum_i2)) : 0.0f;
  const float inv_p = 1.0f / static_cast<float>(p);
  const int n = o.rows();
  out.assign(static_cast<size_t>(n) * per_row, 0.0f);
  if (p == 1) {
    std::copy(o.flat.begin(), o.flat.end(), out.begin());
    return;
  }
  auto direct = [&](int i) {
    size_t stride;
    const float* q = o.patch_ptr(i, stride);
    float* m = out.data() + static_cast<size_t>(i) * per_row;
    for (int y = 0; y < p; ++y)
      for (int x = 0; x < p; ++x)
        for (int k = 0; k < c; ++k) {
          const float v = q[y * stride + x * c + k];
          m[k] += v;
          if (parts > 1) {
            m[c + k] += static_cast<float>(x - r) * v;
            m[2 * c + k] += static_cast<float>(y - r) * v;
          }
        }
    for (int k = 0; k < c; ++k) m[k] *= inv_p;
    if (parts > 1)
      for (int k = 0; k < c; ++k) m[c + k] *= inv_nu, m[2 * c + k] *= inv_nu;
  };
  // object rows per image row (rows are in scan order)
  const int h = o.size.height;
  std::vector<int> at(h + 1, 0);
  for (const cv::Point& pt : o.pixels) ++at[pt.y + 1];
  for (int y = 0; y < h; ++y) at[y + 1] += at[y];
  parallel_rows(h, threads, 4, [&](int yb, int ye) {
    std::vector<float> v0, v2;  // per column of a run: sum over dy, and of dy * value
    for (int y = yb; y < ye; ++y) {
      for (int i = at[y]; i < at[y + 1];) {
        if (o.slot[i] >= 0) {
          direct(i++);
          continue;
        }
        int j = i + 1;
        while (j < at[y + 1] && o.slot[j] < 0 && o.pixels[j].x == o.pixels[j - 1].x + 1) ++j;
        const int xa = o.pixels[i].x - r, cols = o.pixels[j - 1].x + r - xa + 1, len = cols * c;
        v0.assign(len, 0.0f);
        v2.assign(len, 0.0f);
        for (int dy = -r; dy <= r; ++dy) {
          const float* row = o.values.ptr<float>(y + dy) + static_cast<size_t>(xa) * c;
          const float w = static_cast<float>(dy);
          if (parts > 1)
            for (int t = 0; t < len; ++t) v0[t] += row[t], v2[t] += w * row[t];
          else
            for (int t = 0; t < len; ++t) v0[t] += row[t];
        }
        if (parts == 1) {
          for (int q = i; q < j; ++q) {
            float* m = out.data() + static_cast<size_t>(q) * per_row;
            const float* a0 = v0.data() + (o.pixels[q].x - r - xa) * c;
            for (int dx = 0; dx < p; ++dx)
              for (int k = 0; k < c; ++k) m[k] += a0[dx * c + k];
            for (int k = 0; k < c; ++k) m[k] *= inv_p;
          }
          i = j;
          continue;
        }
        for (int q = i; q < j; ++q) {
          float* m = out.data() + static_cast<size_t>(q) * per_row;
          const int base = (o.pixels[q].x - r - xa) * c;
          for (int dx = 0; dx < p; ++dx) {
            const float w = static_cast<float>(dx - r);
            const float* a0 = v0.data() + base + dx * c;
            const float* a2 = v2.data() + base + dx * c;
            for (int k = 0; k < c; ++k) m[k] += a0[k], m[c + k] += w * a0[k], m[2 * c + k] += a2[k];
          }
          for (int k = 0; k < c; ++k) m[k] *= inv_p, m[c + k] *= inv_nu, m[2 * c + k] *= inv_nu;
        }
        i = j;
      }
    }
  });
}

namespace {

// Top-3 principal directions of the rows of a and b (c columns), as 3 x c.
cv::Mat principal3(const std::vector<float>& a, const std::vector<float>& b, int c, int per_row, double& explained) {
  cv::Mat acc = cv::Mat::zeros(c, c, CV_64F);
  std::vector<double> mean(c, 0.0);
  size_t count = 0;
  for (const auto* v : {&a, &b}) {
    const size_t rows = v->size() / per_row;
    const size_t step = std::max<size_t>(1, rows / 20000);  // a fixed subsample: deterministic
    for (size_t i = 0; i < rows; i += step) {
      const float* r = v->data() + i * per_row;
      for (int x = 0; x < c; ++x) {
        mean[x] += r[x];
        for (int y = x; y < c; ++y) acc.at<double>(x, y) += static_cast<double>(r[x]) * r[y];
      }
      ++count;
    }
  }
  for (int x = 0; x < c; ++x) mean[x] /= static_cast<double>(count);
  for (int x = 0; x < c; ++x)
    for (int y = x; y < c; ++y) {
      const double v = acc.at<double>(x, y) / static_cast<double>(count) - mean[x] * mean[y];
      acc.at<double>(x, y) = acc.at<double>(y, x) = v;
    }
  cv::Mat values, vectors;
  cv::eigen(acc, values, vectors);  // descending eigenvalues, eigenvectors as rows
  double total = 0, top = 0;
  for (int i = 0; i < c; ++i) total += std::max(0.0, values.at<double>(i));
  for (int i = 0; i < std::min(3, c); ++i) top += std::max(0.0, values.at<double>(i));
  explained = total > 0 ? top / total : 1.0;
  cv::Mat w = cv::Mat::zeros(3, c, CV_32F);
  for (int i = 0; i < std::min(3, c); ++i)
    for (int x = 0; x < c; ++x) w.at<float>(i, x) = static_cast<float>(vectors.at<double>(i, x));
  return w;
}

// Each of the `parts` blocks of c channels projected on the 3 rows of w.
void project(const std::vector<float>& m, int c, int parts, const cv::Mat& w, std::vector<float>& y) {
  const size_t rows = m.size() / (static_cast<size_t>(parts) * c);
  const int out = 3 * parts;
  y.assign(rows * out, 0.0f);
  for (size_t i = 0; i < rows; ++i)
    for (int part = 0; part < parts; ++part)
      for (int j = 0; j < 3; ++j) {
        float s = 0;
        const float* v = m.data() + (i * parts + part) * c;
        for (int x = 0; x < c; ++x) s += w.at<float>(j, x) * v[x];
        y[i * out + part * 3 + j] = s;
      }
}

}  // namespace

static thread_local long dbg_scanned = 0, dbg_added = 0, dbg_q = 0, dbg_fresh = 0;
namespace {

inline float sq3(float ax, float ay, float az, float bx, float by, float bz) {
  float s = 0;
  float t = ax - bx;
  s += t * t;
  t = ay - by;
  s += t * t;
  t = az - bz;
  s += t * t;
  return s;
}

// Exact k nearest unit directions, warm-started: the k rows found for a
// nearby query bound the k-th distance of this one before anything is
// scanned, so only the buckets within that reach are visited (neighbouring
// patches have nearly the same mean direction, so the reach is small). The
// buckets are octahedral cells (uv = (x, y) / |n|_1, one layer per
// hemisphere, rows of cells contiguous). For unit p, q with |p - q| <= c:
//   u_p - u_q = (x_p - x_q) / s_p + u_q (s_q - s_p) / s_p,  |s_q - s_p| <= sqrt(3) c,
// so |u_p - u_q| <= c sqrt((1 + |u_q|)^2 + 2 u_q^2) / max(1, s_q - sqrt(3) c)
// (Cauchy-Schwarz; s = |n|_1 >= 1), the same for v, whatever p's layer: the
// box of cells of that reach holds every row that can be among the k nearest.
// Distances and ties (to the lower id) as OctGridIndex, so the lists agree.
class DirectionKnn {
 public:
  void build(const std::vector<float>& dirs, int n, double per_cell) {
    n_ = n;
    side_ = std::clamp(static_cast<int>(std::sqrt(1.0 * n / per_cell)), 4, 1024);
    cells_ = side_ * side_;
    scale_ = 0.5f * static_cast<float>(side_);
    start_.assign(static_cast<size_t>(2 * cells_ + 1), 0);
    std::vector<int> of(n);
    for (int i = 0; i < n; ++i) {
      const float* p = &dirs[static_cast<size_t>(i) * 3];
      int cx, cy;
      const int layer = cell(p, cx, cy);
      of[i] = layer * cells_ + cy * side_ + cx;
      ++start_[of[i] + 1];
    }
    for (int c = 0; c < 2 * cells_; ++c) start_[c + 1] += start_[c];
    std::vector<int> fill(start_.begin(), start_.end() - 1);
    x_.resize(n), y_.resize(n), z_.resize(n), id_.resize(n);
    for (int i = 0; i < n; ++i) {  // in row order: cells keep ascending ids
      const int at = fill[of[i]]++;
      const float* p = &dirs[static_cast<size_t>(i) * 3];
      x_[at] = p[0], y_[at] = p[1], z_[at] = p[2], id_[at] = i;
    }
  }

  // approximately the k nearest: the k nearest among the cells within `rad`
  // cells of q (grown until they hold k rows), ascending by (distance, id).
  struct Scratch {
    std::vector<float> d, sel;
    std::vector<int> id, out;
  };
  void knn_near(const float* q, int k, float rad, int* ids, Scratch& w) const {
    const float qx = q[0], qy = q[1], qz = q[2];
    float u, v;
    uv(q, u, v);
    const int layer = q[2] < 0 ? 1 : 0;
    const float fu = (u + 1.0f) * scale_, fv = (v + 1.0f) * scale_;
    int x0, x1, y0, y1, got;
    bool whole;
    for (;; rad *= 1.5f) {
      x0 = std::clamp(static_cast<int>(std::floor(fu - rad)), 0, side_ - 1);
      x1 = std::clamp(static_cast<int>(std::floor(fu + rad)), 0, side_ - 1);
      y0 = std::clamp(static_cast<int>(std::floor(fv - rad)), 0, side_ - 1);
      y1 = std::clamp(static_cast<int>(std::floor(fv + rad)), 0, side_ - 1);
      got = 0;
      for (int y = y0; y <= y1; ++y) got += count(layer, y, x0, x1);
      whole = x0 == 0 && y0 == 0 && x1 == side_ - 1 && y1 == side_ - 1;
      if (got >= k || whole) break;
    }
    if (got < k) {  // the whole layer is too few: both layers
      layer_all(q, k, ids);
      return;
    }
    w.d.resize(got);
    w.id.resize(got);
    int m = 0;
    for (int y = y0; y <= y1; ++y) {
      const int c0 = layer * cells_ + y * side_;
      const int b = start_[c0 + x0], e = start_[c0 + x1 + 1];
      float* dd = w.d.data() + m;
      for (int at = b; at < e; ++at) dd[at - b] = sq3(x_[at], y_[at], z_[at], qx, qy, qz);
      std::copy(id_.begin() + b, id_.begin() + e, w.id.begin() + m);
      m += e - b;
    }
    if (m == k) {
      std::copy_n(w.id.begin(), k, ids);
      return;
    }
    // each row's rank by (distance, id), counted without branches: the
    // rows ranked below k are the answer
    const float* dd = w.d.data();
    const int* ii = w.id.data();
    w.out.resize(m + 1);
    int* picked = w.out.data();
    int out = 0;
    for (int i = 0; i < m; ++i) {
      const float di = dd[i];
      const int id = ii[i];
      int rank = 0;
      for (int j = 0; j < m; ++j) rank += (dd[j] < di) | ((dd[j] == di) & (ii[j] < id));
      picked[out] = id;
      out += rank < k;
    }
    std::copy_n(picked, k, ids);
  }
  void layer_all(const float* q, int k, int* ids) const {
    std::vector<float> d(k);
    TopK top(k, ids, d.data());
    for (int l = 0; l < 2; ++l)
      for (int y = 0; y < side_; ++y) scan(l, y, 0, side_ - 1, q[0], q[1], q[2], kInfinity, top);
  }

  // ids/d: the k nearest (k <= rows), ascending by (distance, id). `guess`:
  // k distinct rows near the answer, or nullptr.
  void knn(const float* q, int k, const int* guess, int* ids, float* d) const {
    const float qx = q[0], qy = q[1], qz = q[2];
    float u, v;
    uv(q, u, v);
    int cx, cy;
    const int layer = cell(q, cx, cy);
    float bound = kInfinity;  // >= the k-th nearest distance
    if (guess) {
      bound = 0;
      for (int j = 0; j < k; ++j) {
        const int at = where(guess[j]);
        bound = std::max(bound, sq3(x_[at], y_[at], z_[at], qx, qy, qz));
      }
    }
    float reach_u = 0, reach_v = 0;
    bool both = false;
    dbg_q++;
    if (!reach(bound, q, u, v, reach_u, reach_v, both) || box_cells(u, v, reach_u, reach_v) > kMaxBox) {
      dbg_fresh++;
      // no usable guess: grow a box of cells around q until it holds k rows
      for (int rad = 1;; ++rad) {
        const int x0 = std::max(0, cx - rad), x1 = std::min(side_ - 1, cx + rad);
        const int y0 = std::max(0, cy - rad), y1 = std::min(side_ - 1, cy + rad);
        int got = 0;
        for (int y = y0; y <= y1; ++y) got += count(layer, y, x0, x1);
        const bool whole = x0 == 0 && y0 == 0 && x1 == side_ - 1 && y1 == side_ - 1;
        if (got < k && !whole) continue;
        if (got >= k) {
          TopK top(k, ids, d);
          for (int y = y0; y <= y1; ++y) scan(layer, y, x0, x1, qx, qy, qz, kInfinity, top);
          bound = top.worst();
        } else {
          bound = kInfinity;
        }
        break;
      }
      if (!reach(bound, q, u, v, reach_u, reach_v, both)) {  // everything
        TopK top(k, ids, d);
        for (int l = 0; l < 2; ++l)
          for (int y = 0; y < side_; ++y) scan(l, y, 0, side_ - 1, qx, qy, qz, kInfinity, top);
        return;
      }
    }
    const int x0 = std::clamp(static_cast<int>(std::floor((u - reach_u + 1.0f) * scale_)), 0, side_ - 1);
    const int x1 = std::clamp(static_cast<int>(std::floor((u + reach_u + 1.0f) * scale_)), 0, side_ - 1);
    const int y0 = std::clamp(static_cast<int>(std::floor((v - reach_v + 1.0f) * scale_)), 0, side_ - 1);
    const int y1 = std::clamp(static_cast<int>(std::floor((v + reach_v + 1.0f) * scale_)), 0, side_ - 1);
    TopK top(k, ids, d);
    for (int l = 0; l < 2; ++l) {
      if (l != layer && !both) continue;
      for (int y = y0; y <= y1; ++y) scan(l, y, x0, x1, qx, qy, qz, bound, top);
    }
  }

 private:
  static constexpr float kInfinity = std::numeric_limits<float>::infinity();
  static constexpr int kMaxBox = 400;  // cells; a larger box means the guess was poor
  int n_ = 0, side_ = 1, cells_ = 1;
  float scale_ = 0.5f;
  std::vector<int> start_;
  std::vector<float> x_, y_, z_;
  std::vector<int> id_;
  std::vector<int> slot_of_;  // row -> bucket order (filled lazily by where())

  static void uv(const float* m, float& u, float& v) {
    const float s = std::fabs(m[0]) + std::fabs(m[1]) + std::fabs(m[2]);
    if (!(s > 0)) {
      u = v = 0;
      return;
    }
    u = m[0] / s;
    v = m[1] / s;
  }
  int cell(const float* m, int& cx, int& cy) const {
    float u, v;
    uv(m, u, v);
    cx = std::clamp(static_cast<int>((u + 1.0f) * scale_), 0, side_ - 1);
    cy = std::clamp(static_cast<int>((v + 1.0f) * scale_), 0, side_ - 1);
    return m[2] < 0 ? 1 : 0;
  }
  int where(int row) const { return rank_[row]; }
  int count(int layer, int y, int x0, int x1) const {
    const int c0 = layer * cells_ + y * side_;
    return start_[c0 + x1 + 1] - start_[c0 + x0];
  }
  void scan(int layer, int y, int x0, int x1, float qx, float qy, float qz, float bound, TopK& top) const {
    const int c0 = layer * cells_ + y * side_;
    const int e = start_[c0 + x1 + 1];
    for (int at = start_[c0 + x0]; at < e; ++at) {
      const float dist = sq3(x_[at], y_[at], z_[at], qx, qy, qz);
      dbg_scanned++;
      if (dist <= bound) top.add(dist, id_[at]), dbg_added++;
    }
  }
  int box_cells(float u, float v, float ru, float rv) const {
    const float w = std::min(2.0f, 2 * ru) * scale_ + 2, h = std::min(2.0f, 2 * rv) * scale_ + 2;
    return static_cast<int>(w * h);
  }
  // uv reach of a chord sqrt(bound) around unit q; false when it is everything
  static bool reach(float bound, const float* q, float u, float v, float& ru, float& rv, bool& both) {
    if (!(bound < kInfinity)) return false;
    const float chord = std::sqrt(bound) * 1.0001f + 1e-5f;
    if (chord >= 1.0f) return false;
    const float s_q = std::fabs(q[0]) + std::fabs(q[1]) + std::fabs(q[2]);
    const float denom = std::max(1.0f, s_q - 1.7320509f * chord);
    const float au = std::fabs(u), av = std::fabs(v);
    ru = chord * std::sqrt((1.0f + au) * (1.0f + au) + 2.0f * au * au) / denom * 1.0001f + 1e-5f;
    rv = chord * std::sqrt((1.0f + av) * (1.0f + av) + 2.0f * av * av) / denom * 1.0001f + 1e-5f;
    both = std::fabs(q[2]) <= chord;
    return true;
  }

 public:
  std::vector<int> rank_;  // row -> bucket order
  void index_rows() {
    rank_.resize(n_);
    for (int at = 0; at < n_; ++at) rank_[id_[at]] = at;
  }
};

}  // namespace

// Nearest normal patch, approximate and fast: candidates are the 12 source
// rows whose patch-mean direction is nearest (exact, DirectionKnn, warm-started
// from the left or upper neighbour's 12), plus the matches of the left and
// upper neighbours shifted by one pixel (as in PatchMatch's propagation); the
// exact patch distance picks among them, the propagated ones first (they win
// about half the time, and a low best distance lets the others stop early).
// Rows are taken in fixed blocks, each in scan order, so the result does not
// depend on threads. The 9-D certified search (below) is exact but its
// kd-tree costs ~10 us per query; this path trades that for a stated
// tolerance (tests).
Status nearest_patch_normals(const Object& dst, const Object& src, int threads, const Progress& progress,
                             NearestLists& out, Stats* stats) {
  const int n = dst.rows(), ns = src.rows();
  // unit patch-mean directions (rows of 3)
  int per_row = 0;
  std::vector<float> mom_d, mom_s;
  auto directions = [&](const Object& o, std::vector<float>& m) {
    patch_moments(o, threads, m, per_row, true);
    const int rows = o.rows();
    std::vector<float> y(static_cast<size_t>(rows) * 3);
    for (int i = 0; i < rows; ++i) {
      const float* v = m.data() + static_cast<size_t>(i) * per_row;
      const float len = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
      for (int j = 0; j < 3; ++j) y[static_cast<size_t>(i) * 3 + j] = len > 1e-9f ? v[j] / len : 0.0f;
      if (!(len > 1e-9f)) y[static_cast<size_t>(i) * 3 + 2] = 1.0f;
    }
    return y;
  };
  auto T0 = std::chrono::steady_clock::now();
  const std::vector<float> yd = directions(dst, mom_d), ys = directions(src, mom_s);
  const bool use_lb = getenv("PK_LB") != nullptr;
  long pruned = 0, evals = 0;
  auto T1 = std::chrono::steady_clock::now();
  DirectionKnn grid;
  const double pcell = getenv("PK_CELL") ? atof(getenv("PK_CELL")) : 4.0;
  const float prad = getenv("PK_RAD") ? atof(getenv("PK_RAD")) : 1.0f;
  const bool approx = !getenv("PK_EXACTKNN");
  grid.build(ys, ns, pcell);
  grid.index_rows();
  const int kc = std::min(ns, 12);
  auto T2 = std::chrono::steady_clock::now();
  const int block = 1024, blocks = (n + block - 1) / block;
  const bool walk = !src.row_of.empty() && !dst.row_of.empty();
  std::atomic<bool> stop{false};
  parallel_rows(blocks, threads, 1, [&](int bb, int be) {
    std::vector<float> buf(static_cast<size_t>(dst.dims));
    std::vector<int> lists(static_cast<size_t>(block) * kc);  // this block's rows' 12
    std::vector<float> cd(kc);
    DirectionKnn::Scratch scratch;
    for (int blk = bb; blk < be; ++blk) {
      if (progress.cancelled()) stop = true;
      if (stop) return;
      const int r0 = blk * block, r1 = std::min(n, r0 + block);
      for (int d = r0; d < r1; ++d) {
        const cv::Point pt = dst.pixels[d];
        int* cid = &lists[static_cast<size_t>(d - r0) * kc];
        const int* guess = nullptr;
        if (walk) {
          const int left = dst.row_at(pt.x - 1, pt.y), up = dst.row_at(pt.x, pt.y - 1);
          if (left >= r0 && left < d) guess = &lists[static_cast<size_t>(left - r0) * kc];
          else if (up >= r0 && up < d) guess = &lists[static_cast<size_t>(up - r0) * kc];
        } else if (d > r0) {
          guess = cid - kc;
        }
        if (approx) grid.knn_near(&yd[static_cast<size_t>(d) * 3], kc, prad, cid, scratch);
        else grid.knn(&yd[static_cast<size_t>(d) * 3], kc, guess, cid, cd.data());
        dst.gather(d, buf.data());
        int best = -1;
        float best_sq = std::numeric_limits<float>::infinity();
        const float* qm = &mom_d[static_cast<size_t>(d) * per_row];
        auto offer = [&](int s) {
          if (s < 0 || s == best) return;
          if (use_lb && best >= 0) {
            const float* sm = &mom_s[static_cast<size_t>(s) * per_row];
            float lb = 0;
            for (int j = 0; j < 9; ++j) { const float t = qm[j] - sm[j]; lb += t * t; }
            if (lb * 0.9999f > best_sq) { ++pruned; return; }
          }
          ++evals;
          const float v = patch_sq(buf.data(), src, s, best_sq);
          if (v < best_sq || (v == best_sq && s < best)) best_sq = v, best = s;
        };
        if (walk) {
          for (const cv::Point off : {cv::Point(-1, 0), cv::Point(0, -1)}) {
            const int nb = dst.row_at(pt.x + off.x, pt.y + off.y);
            if (nb < r0 || nb >= d) continue;  // only rows this block already matched
            const cv::Point m = src.pixels[out.ids[nb]];
            offer(src.row_at(m.x - off.x, m.y - off.y));
          }
        }
        for (int j = 0; j < kc; ++j) offer(cid[j]);
        out.ids[d] = best;
        out.sq[d] = best_sq;
      }
    }
  });
  auto T3 = std::chrono::steady_clock::now();
  if (getenv("PK_DBG")) fprintf(stderr, "pruned %ld evals %ld\n", pruned, evals);
  if (getenv("PK_DBG")) fprintf(stderr, "dirs %.2f build %.2f loop %.2f\n", std::chrono::duration<double,std::milli>(T1-T0).count(), std::chrono::duration<double,std::milli>(T2-T1).count(), std::chrono::duration<double,std::milli>(T3-T2).count());
  if (stop) return make_error("cancelled during nearest search");
  if (stats) {
    stats->index = "grid";
    stats->projected_dims = 3;
    stats->explained_variance = 1;
    stats->certified = 0;  // approximate by design
    stats->candidates = kc + 2;
  }
  return {};
}

Status nearest_centres(const Object& dst, const Object& src, int threads, const Progress& progress,
                       std::vector<int>& ids) {
  const int n = dst.rows();
  ids.assign(n, -1);
  if (dst.channels != 3) return make_error("nearest_centres: 3 values per pixel needed");
  OctGridIndex grid;
  grid.build(src.flat.data(), src.rows(), 3);
  std::atomic<bool> stop{false};
  parallel_rows(n, threads, 256, [&](int b, int e) {
    if (progress.cancelled()) stop = true;
    if (stop) return;
    float sq;
    for (int d = b; d < e; ++d)  // neighbouring pixels have neighbouring normals: start from the last match
      grid.nearest_from(dst.flat.data() + static_cast<size_t>(d) * 3, 1, &ids[d], &sq, d > b ? ids[d - 1] : -1);
  });
  if (stop) return make_error("cancelled during nearest search");
  return {};
}

Status nearest_lists(const Object& dst, const Object& src, int k, const std::string& index_kind, int threads,
                     const Progress& progress, NearestLists& out, Stats* stats) {
  const int n = dst.rows(), ns = src.rows();
  out.k = k;
  out.ids.assign(static_cast<size_t>(n) * k, -1);
  out.sq.assign(static_cast<size_t>(n) * k, std::numeric_limits<float>::infinity());
  std::atomic<bool> stop{false};
  auto cancelled = [&] {
    if (progress.cancelled()) stop = true;
    return stop.load(std::memory_order_relaxed);
  };

  // Direct exact search over the pixel values.
  auto direct = [&](NearestIndex& index, const char* name) -> Status {
    index.build(src.flat.data(), ns, src.channels);
    const auto* grid = dynamic_cast<const OctGridIndex*>(&index);
    parallel_rows(n, threads, 256, [&](int b, int e) {
      if (cancelled()) return;
      for (int d = b; d < e; ++d) {
        const float* q = dst.flat.data() + static_cast<size_t>(d) * dst.channels;
        int* ids = &out.ids[static_cast<size_t>(d) * k];
        float* sq = &out.sq[static_cast<size_t>(d) * k];
        // neighbouring pixels have neighbouring normals: start from the last match
        if (grid && k == 1)
          grid->nearest_from(q, k, ids, sq, d > b ? out.ids[d - 1] : -1);
        else
          index.knn(q, k, ids, sq);
      }
    });
    if (stop) return make_error("cancelled during nearest search");
    if (stats) stats->index = name, stats->projected_dims = 0, stats->certified = 1, stats->explained_variance = 1;
    return {};
  };
  if (dst.patch == 1 && dst.channels == 3) {
    // long lists: the kd-tree (measured faster at k = 100 by bench_match)
    auto index = make_index(k > 16 ? std::string("kdtree") : index_kind);
    if (!index) return make_error("unknown fast index '" + index_kind + "' (grid, kdtree)");
    return direct(*index, k > 16 || index_kind != "grid" ? "kdtree" : "grid");
  }

  if (dst.channels == 3 && dst.patch > 1 && k == 1) return nearest_patch_normals(dst, src, threads, progress, out, stats);
  std::vector<float> md, ms;
  int per_row = 0;
  patch_moments(dst, threads, md, per_row);
  patch_moments(src, threads, ms, per_row);
  const int c = dst.channels, parts = per_row / c;
  double explained = 1;
  if (dst.patch == 1 && c > 3) {
    const cv::Mat w = principal3(md, ms, c, per_row, explained);
    if (explained < 0.9) {  // the projection keeps too little: full dimension
      auto index = make_kdtree();
      auto s = direct(*index, "kdtree");
      if (stats) stats->explained_variance = explained;
      return s;
    }
  }
  // y: per spatial function, the 3 principal channel directions (identity for normals)
  std::vector<float> yd, ys;
  if (c == 3) {
    yd = std::move(md);
    ys = std::move(ms);
  } else {
    const cv::Mat w = principal3(md, ms, c, per_row, explained);
    project(md, c, parts, w, yd);
    project(ms, c, parts, w, ys);
  }
  const int ydims = 3 * parts;
  auto index = make_kdtree();
  index->build(ys.data(), ns, ydims);
  // One growth step (x4); past it the best found is kept (not certified).
  const int first = std::min(ns, std::max(12, 2 * k + 8));
  const int cap = std::min(ns, (k > 1 ? 4 : 2) * first);
  std::atomic<int> certified{0};
  std::atomic<long> exact_distances{0};
  // With nearly all variance kept (>= 99.9 %: Lambertian sets), a pixel the projection
  // cannot certify asks the exact kd-tree at full dimension; otherwise (shadows,
  // highlights) that would be most pixels at ~10 us each, and the grown
  // candidate list's best is kept instead (approximate, counted in Stats).
  std::unique_ptr<NearestIndex> full;
  if (dst.patch == 1 && explained >= 0.999) {
    full = make_kdtree();
    full->build(src.flat.data(), ns, c);
  }
  parallel_rows(n, threads, 128, [&](int b, int e) {
    if (cancelled()) return;
    std::vector<float> buf(static_cast<size_t>(dst.dims));
    std::vector<int> cid;
    std::vector<float> clb;
    int local_certified = 0;
    long local_exact = 0;
    for (int d = b; d < e; ++d) {
      dst.gather(d, buf.data());
      int* ids = &out.ids[static_cast<size_t>(d) * k];
      float* sq = &out.sq[static_cast<size_t>(d) * k];
      for (int want = first;; want = std::min(cap, want * 4)) {
        cid.resize(want);
        clb.resize(want);
        index->knn(&yd[static_cast<size_t>(d) * ydims], want, cid.data(), clb.data());
        TopK top(k, ids, sq);
        for (int j = 0; j < want && cid[j] >= 0; ++j) {
          const float bound = top.worst();
          const float v = patch_sq(buf.data(), src, cid[j], bound);
          if (v <= bound) top.add(v, cid[j]);
        }
        // Proven when every source row is seen, or the next row's lower
        // bound (>= the last candidate's) is above the k-th exact distance.
        const bool all = want >= ns;
        const bool proven = all || clb[want - 1] * (1.0f - 1e-4f) > top.worst();
        if (proven) ++local_certified;
        local_exact += want;
        if (!proven && full) {
          full->knn(dst.flat.data() + static_cast<size_t>(d) * c, k, ids, sq);
          ++local_certified;  // exact all the same
          break;
        }
        if (proven || want >= cap) break;
      }
    }
    certified += local_certified;
    exact_distances += local_exact;
  });
  if (stop) return make_error("cancelled during nearest search");
  if (stats) {
    stats->index = "kdtree";
    stats->projected_dims = ydims;
    stats->explained_variance = explained;
    stats->certified = n > 0 ? static_cast<double>(certified.load()) / n : 1.0;
    stats->candidates = n > 0 ? static_cast<double>(exact_distances.load()) / n : 0.0;
  }
  return {};
}

}  // namespace veneer::match::fast
