// The fast engine's exact nearest-neighbour indices: the octahedral grid over
// the sphere of normals and the nanoflann kd-tree.
#include "index_fast.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>
#include <vector>

#include <nanoflann.hpp>

namespace veneer::match::fast {

namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

// Keeps the k best (distance, id) pairs, ties to the lower id. Small k: a
// sorted array; large k: a max-heap sorted once at the end (finish()).
struct Best {
  int k;
  int* ids;
  float* d;
  int filled = 0;
  bool heap;
  std::vector<std::pair<float, int>> h;
  Best(int k_, int* ids_, float* d_) : k(k_), ids(ids_), d(d_), heap(k_ > 16) {
    for (int j = 0; j < k; ++j) ids[j] = -1, d[j] = kInf;
    if (heap) h.reserve(k);
  }
  float worst() const {
    if (heap) return static_cast<int>(h.size()) < k ? kInf : h.front().first;
    return filled < k ? kInf : d[k - 1];
  }
  int worst_id() const {
    if (heap) return static_cast<int>(h.size()) < k ? std::numeric_limits<int>::max() : h.front().second;
    return filled < k ? std::numeric_limits<int>::max() : ids[k - 1];
  }
  void add(float dist, int id) {
    if (heap) {
      const std::pair<float, int> e(dist, id);
      if (static_cast<int>(h.size()) < k) {
        h.push_back(e);
        std::push_heap(h.begin(), h.end());
      } else if (e < h.front()) {
        std::pop_heap(h.begin(), h.end());
        h.back() = e;
        std::push_heap(h.begin(), h.end());
      }
      return;
    }
    if (filled == k && !(dist < d[k - 1] || (dist == d[k - 1] && id < ids[k - 1]))) return;
    int j = filled < k ? filled++ : k - 1;
    while (j > 0 && (d[j - 1] > dist || (d[j - 1] == dist && ids[j - 1] > id))) {
      d[j] = d[j - 1];
      ids[j] = ids[j - 1];
      --j;
    }
    d[j] = dist;
    ids[j] = id;
  }
  void finish() {
    if (!heap) return;
    std::sort_heap(h.begin(), h.end());
    for (size_t j = 0; j < h.size(); ++j) d[j] = h[j].first, ids[j] = h[j].second;
  }
};

// Same arithmetic, in the same order, as squared_distance() of features.hpp,
// so that exact indices report bit-identical distances to the brute force.
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

// ---------------------------------------------------------------------------
// kd-tree (nanoflann): exact, any dimension.
struct Cloud {
  const float* pts = nullptr;
  size_t n = 0;
  int dims = 0;
  size_t kdtree_get_point_count() const { return n; }
  float kdtree_get_pt(size_t i, size_t d) const { return pts[i * static_cast<size_t>(dims) + d]; }
  template <class Box>
  bool kdtree_get_bbox(Box&) const {
    return false;
  }
};

// Squared L2 accumulated dimension by dimension from 0, as squared_distance().
template <class T, class DataSource>
struct L2Ordered {
  using ElementType = T;
  using DistanceType = T;
  const DataSource& data;
  explicit L2Ordered(const DataSource& d) : data(d) {}
  T evalMetric(const T* a, size_t b, size_t size) const {
    T s = 0;
    const T* p = data.pts + b * static_cast<size_t>(data.dims);
    for (size_t i = 0; i < size; ++i) {
      T t = a[i] - p[i];
      s += t * t;
    }
    return s;
  }
  template <typename U, typename V>
  T accum_dist(const U a, const V b, const size_t) const {
    return (a - b) * (a - b);
  }
};

using Tree = nanoflann::KDTreeSingleIndexAdaptor<L2Ordered<float, Cloud>, Cloud, -1, uint32_t>;

class KdTreeIndex final : public NearestIndex {
 public:
  void build(const float* points, int n, int dims) override {
    cloud_.pts = points;
    cloud_.n = static_cast<size_t>(std::max(0, n));
    cloud_.dims = dims;
    tree_.reset();
    if (n <= 0) return;
    tree_ = std::make_unique<Tree>(dims, cloud_, nanoflann::KDTreeSingleIndexAdaptorParams(12));
  }
  void knn(const float* query, int k, int* ids, float* sq_dists) const override {
    Best best(k, ids, sq_dists);
    if (!tree_ || k <= 0) return;
    // nanoflann breaks ties by visiting order; ask for a few more and re-sort
    // by (distance, id) so ties go to the lower id like the brute force.
    const int want = static_cast<int>(std::min<size_t>(cloud_.n, static_cast<size_t>(k) + 4));
    uint32_t idx[512];
    float dist[512];
    std::vector<uint32_t> idx_big;
    std::vector<float> dist_big;
    uint32_t* pi = idx;
    float* pd = dist;
    if (want > 512) {
      idx_big.resize(want);
      dist_big.resize(want);
      pi = idx_big.data();
      pd = dist_big.data();
    }
    nanoflann::KNNResultSet<float, uint32_t> rs(static_cast<size_t>(want));
    rs.init(pi, pd);
    tree_->findNeighbors(rs, query, nanoflann::SearchParams(32, 0.0f, false));
    const int got = static_cast<int>(rs.size());
    for (int j = 0; j < got; ++j) best.add(pd[j], static_cast<int>(pi[j]));
    best.finish();
  }
  std::string name() const override { return "kdtree"; }

 private:
  Cloud cloud_;
  std::unique_ptr<Tree> tree_;
};

}  // namespace

// ---------------------------------------------------------------------------
// Octahedral grid. A direction n maps to uv = (x, y) / (|x| + |y| + |z|) in the
// diamond |u| + |v| <= 1; the upper (z >= 0) and lower (z < 0) hemispheres get
// one layer each, and both layers agree on the equator, so the two diamonds
// glued along their rim are the sphere. The map is Lipschitz: |duv| <= L dθ.
// Crudely |J| <= 1/s + |(x,y)| |sign(n)| / s^2 <= 1 + sqrt(3) (s = |n|_1 >= 1);
// the true stretch over tangent directions peaks at the golden ratio 1.618
// where the equator meets an axis (dense sampling of 2e7 tangents agrees), so
// L = 1.7 is used. A great-circle arc crosses the equator at most once, so for unit
// directions the angle between q and p is at least |uv(q) - uv(p)| / L whatever
// their layers. A point p with | |p| - 1 | <= eps is within eps of its
// direction, hence for any query q:
//   |q - p| >= sqrt(|q|^2 + 1 - 2 |q| cos θ) - eps.
// Rings of cells around q's cell are searched until that bound for the
// unvisited cells exceeds the k-th best: the result is exact.


OctGridIndex::OctGridIndex(int cells_per_side) : fixed_side_(cells_per_side) {}
OctGridIndex::~OctGridIndex() = default;

// Largest box of cells visited directly (else ring by ring): 16-49 measured
// alike on bull <- orange, 0 (rings only) 25-30 % slower.
constexpr int kBoxCells = 25;

static inline void oct_uv(float x, float y, float z, float& u, float& v) {
  const float s = std::fabs(x) + std::fabs(y) + std::fabs(z);
  u = x / s;
  v = y / s;
}

void OctGridIndex::build(const float* points, int n, int dims) {
  n_ = std::max(0, n);
  dims_ = dims;
  fallback_.reset();
  xs_.clear();
  ys_.clear();
  zs_.clear();
  ids_.clear();
  start_.clear();
  if (n_ == 0) return;
  float eps = 0;
  bool usable = dims == 3;
  if (usable) {
    for (int i = 0; i < n_; ++i) {
      const float* p = points + static_cast<size_t>(i) * 3;
      const float len = std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
      eps = std::max(eps, std::fabs(len - 1.0f));
    }
    // Far-from-unit points (or zeros) make the sphere lookup pointless: exact
    // still, but the kd-tree is the better tool for them.
    usable = eps <= 0.05f;
  }
  if (!usable) {
    fallback_ = std::make_unique<KdTreeIndex>();
    fallback_->build(points, n, dims);
    return;
  }
  eps_ = eps + 1e-6f;
  // ~4 points per used cell (normals seen by a camera fill half the diamond);
  // 0.5 sqrt(n) measured best between 0.35 and 2 (bull <- orange, 21k and 211k
  // source points, queries in scan order seeded with the previous match).
  side_ = fixed_side_ > 0 ? fixed_side_ : std::clamp(static_cast<int>(0.5 * std::sqrt(1.0 * n_)), 8, 512);
  // CSR over (uv cell, layer) with the two layers of a uv cell adjacent, so
  // a query reads one contiguous run per uv cell.
  const int cells = side_ * side_;
  start_.assign(static_cast<size_t>(2 * cells + 1), 0);
  std::vector<int> cell(static_cast<size_t>(n_));
  const float scale = 0.5f * static_cast<float>(side_);
  for (int i = 0; i < n_; ++i) {
    const float* p = points + static_cast<size_t>(i) * 3;
    float u, v;
    oct_uv(p[0], p[1], p[2], u, v);
    const int cx = std::clamp(static_cast<int>((u + 1.0f) * scale), 0, side_ - 1);
    const int cy = std::clamp(static_cast<int>((v + 1.0f) * scale), 0, side_ - 1);
    const int c = 2 * (cy * side_ + cx) + (p[2] < 0 ? 1 : 0);
    cell[i] = c;
    ++start_[c + 1];
  }
  for (size_t c = 1; c < start_.size(); ++c) start_[c] += start_[c - 1];
  xs_.resize(n_);
  ys_.resize(n_);
  zs_.resize(n_);
  ids_.resize(n_);
  std::vector<int> fill(start_.begin(), start_.end() - 1);
  for (int i = 0; i < n_; ++i) {  // ascending ids within a cell
    const int at = fill[cell[i]]++;
    const float* p = points + static_cast<size_t>(i) * 3;
    xs_[at] = p[0];
    ys_[at] = p[1];
    zs_[at] = p[2];
    ids_[at] = i;
  }
  points_ = points;
}

void OctGridIndex::knn(const float* query, int k, int* ids, float* sq_dists) const {
  nearest_from(query, k, ids, sq_dists, -1);
}

void OctGridIndex::nearest_from(const float* query, int k, int* ids, float* sq_dists, int hint) const {
  if (fallback_) {
    fallback_->knn(query, k, ids, sq_dists);
    return;
  }
  Best best(k, ids, sq_dists);
  if (n_ == 0 || k <= 0) return;
  const float qx = query[0], qy = query[1], qz = query[2];
  const float qn = std::sqrt(qx * qx + qy * qy + qz * qz);
  if (!(qn > 1e-6f)) {  // no direction: every cell is as near as any other
    for (int i = 0; i < n_; ++i) {
      const float* p = points_ + static_cast<size_t>(i) * 3;
      best.add(sq3(p[0], p[1], p[2], qx, qy, qz), i);
    }
    best.finish();
    return;
  }
  float u, v;
  oct_uv(qx, qy, qz, u, v);
  const float scale = 0.5f * static_cast<float>(side_);
  const float h = 1.0f / scale;  // cell size in uv
  const int ci = std::clamp(static_cast<int>((u + 1.0f) * scale), 0, side_ - 1);
  const int cj = std::clamp(static_cast<int>((v + 1.0f) * scale), 0, side_ - 1);

  // k = 1: the best pair in two scalars (the common case); else Best.
  const bool one = k == 1;
  float best_d = kInf;
  int best_id = std::numeric_limits<int>::max();
  // Largest u and v distances at which a point could still beat the k-th best.
  // For unit p, q with chord |p - q| <= c and s = |x| + |y| + |z| (>= 1):
  //   u_p - u_q = (x_p - x_q) / s_p + u_q (s_q - s_p) / s_p, |s_q - s_p| <= |p - q|_1, so
  //   |u_p - u_q| <= c sqrt((1 + |u_q|)^2 + 2 u_q^2) / max(1, s_q - sqrt(3) c)
  // (Cauchy-Schwarz), and the same for v: tighter than the global stretch
  // bound, which scanned ~3x the cells near the pole.
  float reach_u = kInf, reach_v = kInf;
  const float s_q = (std::fabs(qx) + std::fabs(qy) + std::fabs(qz)) / qn;
  const float gain_u = std::sqrt((1.0f + std::fabs(u)) * (1.0f + std::fabs(u)) + 2.0f * u * u);
  const float gain_v = std::sqrt((1.0f + std::fabs(v)) * (1.0f + std::fabs(v)) + 2.0f * v * v);
  auto update_reach = [&] {
    const float w = one ? best_d : best.worst();
    if (!(w < kInf)) {
      reach_u = reach_v = kInf;
      return;
    }
    // the angle θ between the directions of q and of any point that could
    // still win: cos θ >= c (points within eps of unit length)
    const float r = std::sqrt(w) + eps_;
    const float c = (qn * qn + 1.0f - r * r) / (2.0f * qn);
    if (c <= -1.0f) {
      reach_u = reach_v = kInf;
      return;
    }
    // chord between the unit directions: 2 sin(θ / 2) = 2 sqrt((1 - cos θ) / 2)
    const float chord = (2.0f * std::sqrt(std::clamp(0.5f * (1.0f - c), 0.0f, 1.0f))) * 1.0001f + 1e-6f;
    const float denom = std::max(1.0f, s_q - 1.7320509f * chord);
    reach_u = chord * gain_u / denom * 1.0001f + 1e-5f;
    reach_v = chord * gain_v / denom * 1.0001f + 1e-5f;
  };
  auto scan_cell = [&](int cx, int cy) {
    // uv distance from the query to this cell's rectangle
    const float x0 = -1.0f + cx * h, y0 = -1.0f + cy * h;
    const float dx = std::max({0.0f, x0 - u, u - (x0 + h)});
    const float dy = std::max({0.0f, y0 - v, v - (y0 + h)});
    if (dx > reach_u || dy > reach_v) return;
    const int c = 2 * (cy * side_ + cx);
    const int b = start_[c], e = start_[c + 2];
    if (b == e) return;
    if (one) {
      const float before = best_d;
      for (int i = b; i < e; ++i) {
        const float d = sq3(xs_[i], ys_[i], zs_[i], qx, qy, qz);
        if (d < best_d || (d == best_d && ids_[i] < best_id)) best_d = d, best_id = ids_[i];
      }
      if (best_d < before) update_reach();
      return;
    }
    bool improved = false;
    for (int i = b; i < e; ++i) {
      const float d = sq3(xs_[i], ys_[i], zs_[i], qx, qy, qz);
      if (d < best.worst() || (d == best.worst() && ids_[i] < best.worst_id())) {
        best.add(d, ids_[i]);
        improved = true;
      }
    }
    if (improved) update_reach();
  };
  if (hint >= 0 && hint < n_ && k == 1) {
    // A point known to be near (the previous pixel's match) bounds the search
    // from the start; meeting it again in its cell changes nothing.
    const float* p = points_ + static_cast<size_t>(hint) * 3;
    best_d = sq3(p[0], p[1], p[2], qx, qy, qz);
    best_id = hint;
    update_reach();
  }
  // With a bound from the hint, the query's own cell and then every cell that
  // meets the box of reach around the query (computed once: the reach only
  // shrinks) is all there is to visit; no rings needed.
  // With a bound from the hint, the query's own cell and then every cell that
  // meets the box of reach around the query (computed once: the reach only
  // shrinks) is all there is to visit, when that box is small; else rings.
  if (reach_u < kInf) {
    scan_cell(ci, cj);
    const int x0 = std::clamp(static_cast<int>(std::floor((u - reach_u + 1.0f) * scale)), 0, side_ - 1);
    const int x1 = std::clamp(static_cast<int>(std::floor((u + reach_u + 1.0f) * scale)), 0, side_ - 1);
    const int y0 = std::clamp(static_cast<int>(std::floor((v - reach_v + 1.0f) * scale)), 0, side_ - 1);
    const int y1 = std::clamp(static_cast<int>(std::floor((v + reach_v + 1.0f) * scale)), 0, side_ - 1);
    if ((x1 - x0 + 1) * (y1 - y0 + 1) <= kBoxCells) {
      for (int cy = y0; cy <= y1; ++cy)
        for (int cx = x0; cx <= x1; ++cx)
          if (cx != ci || cy != cj) scan_cell(cx, cy);
      if (one && best_d < kInf) ids[0] = best_id, sq_dists[0] = best_d;
      best.finish();
      return;
    }
  }
  for (int r = 0;; ++r) {
    if (r > 0) {
      // everything unvisited lies outside the square of rings < r
      const int lo_x = ci - r + 1, hi_x = ci + r - 1, lo_y = cj - r + 1, hi_y = cj + r - 1;
      // stop when every side is at the grid's edge or beyond reach
      bool open = false;
      if (lo_x > 0 && u - (-1.0f + lo_x * h) <= reach_u) open = true;
      if (hi_x < side_ - 1 && (-1.0f + (hi_x + 1) * h) - u <= reach_u) open = true;
      if (lo_y > 0 && v - (-1.0f + lo_y * h) <= reach_v) open = true;
      if (hi_y < side_ - 1 && (-1.0f + (hi_y + 1) * h) - v <= reach_v) open = true;
      if (!open) break;
    }
    const int x0 = ci - r, x1 = ci + r, y0 = cj - r, y1 = cj + r;
    for (int cy = std::max(0, y0); cy <= std::min(side_ - 1, y1); ++cy) {
      if (cy == y0 || cy == y1) {
        for (int cx = std::max(0, x0); cx <= std::min(side_ - 1, x1); ++cx) scan_cell(cx, cy);
      } else {
        if (x0 >= 0) scan_cell(x0, cy);
        if (x1 < side_ && x1 != x0) scan_cell(x1, cy);
      }
    }
  }
  if (one && best_d < kInf) ids[0] = best_id, sq_dists[0] = best_d;
  best.finish();
}

std::unique_ptr<NearestIndex> make_index(const std::string& kind) {
  if (kind == "grid") return std::make_unique<OctGridIndex>();
  if (kind == "kdtree") return std::make_unique<KdTreeIndex>();
  return nullptr;
}

std::unique_ptr<NearestIndex> make_kdtree() { return std::make_unique<KdTreeIndex>(); }

}  // namespace veneer::match::fast
