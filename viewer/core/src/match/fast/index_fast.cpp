// The fast engine's exact nearest-neighbour indices: the octahedral grid over
// the sphere of normals and the nanoflann kd-tree.
#include "index_fast.hpp"

#include "object.hpp"  // parallel_rows

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <tuple>
#include <utility>
#include <vector>

#include <nanoflann.hpp>

// The scans below run 8 points (or boxes) at a time with AVX2 and FMA, and
// one at a time elsewhere (an ARM board; -DVENEER_AVX2=OFF, for any x86-64;
// test_core_match_fast_portable builds it on every run). Both give
// the same answers: the distances are sq3's, the ties go to the lower id.
#if defined(__AVX2__) && defined(__FMA__)
#define VENEER_INDEX_AVX2 1
#include <immintrin.h>
#endif

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
  __attribute__((always_inline)) float worst() const {
    if (heap) return static_cast<int>(h.size()) < k ? kInf : h.front().first;
    return filled < k ? kInf : d[k - 1];
  }
  __attribute__((always_inline)) int worst_id() const {
    if (heap) return static_cast<int>(h.size()) < k ? std::numeric_limits<int>::max() : h.front().second;
    return filled < k ? std::numeric_limits<int>::max() : ids[k - 1];
  }
  __attribute__((always_inline)) void add(float dist, int id) {
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
    search(query, k, std::numeric_limits<float>::max(), ids, sq_dists);
  }
  // The tree prunes with the radius from the first node: every point within
  // it is a candidate, and the k nearest are among them.
  void knn_within(const float* query, int k, float radius_sq, int* ids, float* sq_dists) const override {
    search(query, k, radius_sq, ids, sq_dists);
  }
  std::string name() const override { return "kdtree"; }

 private:
  // The result set nanoflann fills: the k best by (distance, id), ties to the
  // lower id as the brute force, whatever order the tree visits them in.
  // nanoflann offers a point only when it is strictly nearer than
  // worstDist(), and reads a subtree while its bound is at most that, so
  // worstDist() is one float past the k-th best: a point tying with it is
  // still offered (asking for a few more and re-sorting missed the lowest id
  // among many equal distances). Points at or past the radius never are.
  struct TieSet {
    Best& best;
    float radius_sq;
    float worstDist() const { return std::min(radius_sq, std::nextafter(best.worst(), kInf)); }
    bool addPoint(float dist, uint32_t id) {
      best.add(dist, static_cast<int>(id));
      return true;
    }
    bool full() const { return best.worst() < kInf; }
  };
  void search(const float* query, int k, float radius_sq, int* ids, float* sq_dists) const {
    Best best(k, ids, sq_dists);
    if (!tree_ || k <= 0) return;
    TieSet set{best, radius_sq};
    tree_->findNeighbors(set, query, nanoflann::SearchParams(32, 0.0f, false));
    best.finish();
  }
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


OctGridIndex::OctGridIndex(int cells_per_side, bool lookup) : lookup_(lookup), fixed_side_(cells_per_side) {}
OctGridIndex::~OctGridIndex() = default;

// Most nodes with points for which a wide search reads their 3-D boxes at
// once instead of rings of cells (nearest_from).
constexpr long kFewBoxes = 256;

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
  unique_ = Runs{};
  k1_ = View{};
  sub_ = SubGrids{};
  eq_next_.clear();
  boxes_ = BoxSet{};
  boxes_made_ = false;
  occupied_ = 0;
  if (n_ == 0) return;
  // Per point: its distance from unit length and its cell (in parallel).
  std::vector<int> cell(static_cast<size_t>(n_));
  bool usable = dims == 3;
  float eps = 0;
  if (usable) {
    // ~4 points per used cell (normals seen by a camera fill half the diamond);
    // 0.5 sqrt(n) measured best between 0.35 and 2 (bull <- orange, 21k and 211k
    // source points, queries in scan order seeded with the previous match).
    side_ = fixed_side_ > 0 ? fixed_side_ : std::clamp(static_cast<int>(0.5 * std::sqrt(1.0 * n_)), 8, 512);
    const float scale = 0.5f * static_cast<float>(side_);
    const int chunk = 8192, chunks = (n_ + chunk - 1) / chunk;
    std::vector<float> eps_of(chunks, 0.0f);
    parallel_rows(chunks, 0, 1, [&](int cb, int ce) {
      for (int ch = cb; ch < ce; ++ch) {
        float e = 0;
        for (int i = ch * chunk; i < std::min(n_, (ch + 1) * chunk); ++i) {
          const float* p = points + static_cast<size_t>(i) * 3;
          const float len = std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
          e = std::max(e, std::fabs(len - 1.0f));
          float u, v;
          oct_uv(p[0], p[1], p[2], u, v);
          const int cx = std::clamp(static_cast<int>((u + 1.0f) * scale), 0, side_ - 1);
          const int cy = std::clamp(static_cast<int>((v + 1.0f) * scale), 0, side_ - 1);
          cell[i] = 2 * (cy * side_ + cx) + (p[2] < 0 ? 1 : 0);
        }
        eps_of[ch] = std::isnan(e) ? 1e30f : e;
      }
    });
    for (float e : eps_of) eps = std::max(eps, e);
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
  // CSR over (uv cell, layer) with the two layers of a uv cell adjacent, so
  // a query reads one contiguous run per uv cell.
  const int cells = side_ * side_;
  start_.assign(static_cast<size_t>(2 * cells + 1), 0);
  // Counting sort by cell in kParts fixed runs of ids (a fixed split: the
  // layout does not depend on the thread count): per-run counts, then every
  // run scatters its points in parallel after the earlier runs' points of the
  // same cell, so ids ascend within a cell.
  constexpr int kParts = 4;
  const int nodes = 2 * cells, part = (n_ + kParts - 1) / kParts;
  std::vector<int> count(static_cast<size_t>(kParts) * nodes, 0);
  parallel_rows(kParts, 0, 1, [&](int pb, int pe) {
    for (int k = pb; k < pe; ++k) {
      int* c = count.data() + static_cast<size_t>(k) * nodes;
      for (int i = k * part; i < std::min(n_, (k + 1) * part); ++i) ++c[cell[i]];
    }
  });
  for (int c = 0, at = 0; c < nodes; ++c) {
    start_[c] = at;
    for (int k = 0; k < kParts; ++k) {
      int& v = count[static_cast<size_t>(k) * nodes + c];
      const int here = v;
      v = at;  // this run's first place in the cell
      at += here;
    }
  }
  start_[nodes] = n_;
  // 8 far points of padding: scan_run reads whole groups of 8
  xs_.resize(static_cast<size_t>(n_) + 8);
  ys_.resize(static_cast<size_t>(n_) + 8);
  zs_.resize(static_cast<size_t>(n_) + 8);
  ids_.resize(static_cast<size_t>(n_) + 8);
  for (int i = n_; i < n_ + 8; ++i) xs_[i] = ys_[i] = zs_[i] = 1e18f, ids_[i] = std::numeric_limits<int>::max();
  slot_of_.resize(n_);
  parallel_rows(kParts, 0, 1, [&](int pb, int pe) {
    for (int k = pb; k < pe; ++k) {
      int* fill = count.data() + static_cast<size_t>(k) * nodes;
      for (int i = k * part; i < std::min(n_, (k + 1) * part); ++i) {
        const int at = fill[cell[i]]++;
        const float* p = points + static_cast<size_t>(i) * 3;
        xs_[at] = p[0];
        ys_[at] = p[1];
        zs_[at] = p[2];
        ids_[at] = i;
        slot_of_[i] = at;
      }
    }
  });
  points_ = points;
  // For the lookup: each (uv cell, layer) without points sends its queries to
  // the nearest one (in cells, breadth first) that has some. Within a layer
  // cells are 4-neighbours; the layers meet at the diamond's rim (the equator),
  // where a cell touching it neighbours the same cell of the other layer.
  near_.assign(static_cast<size_t>(2 * cells), -1);
  std::vector<int> queue;
  queue.reserve(static_cast<size_t>(2 * cells));
  for (int c = 0; c < 2 * cells; ++c)
    if (start_[c] < start_[c + 1]) near_[c] = c, queue.push_back(c);
  occupied_ = static_cast<int>(queue.size());
  const float h = 2.0f / static_cast<float>(side_);
  auto edge = [&](int i) { return std::max(std::fabs(-1.0f + i * h), std::fabs(-1.0f + (i + 1) * h)); };
  auto inner = [&](int i) { return -1.0f + i * h < 0.0f && -1.0f + (i + 1) * h > 0.0f ? 0.0f : std::min(std::fabs(-1.0f + i * h), std::fabs(-1.0f + (i + 1) * h)); };
  // cells wholly outside the diamond |u| + |v| <= 1 never see a query: not visited
  for (int c = 0; c < cells; ++c)
    if (inner(c % side_) + inner(c / side_) > 1.0f && start_[2 * c] == start_[2 * c + 2])
      near_[2 * c] = near_[2 * c + 1] = -2;
  for (size_t qi = 0; qi < queue.size(); ++qi) {
    const int node = queue[qi], c = node >> 1, cx = c % side_, cy = c / side_;
    const int nb[5] = {cx > 0 ? node - 2 : -1, cx + 1 < side_ ? node + 2 : -1, cy > 0 ? node - 2 * side_ : -1,
                       cy + 1 < side_ ? node + 2 * side_ : -1, edge(cx) + edge(cy) >= 1.0f ? (node ^ 1) : -1};
    for (int t : nb)
      if (t >= 0 && near_[t] == -1) near_[t] = near_[node], queue.push_back(t);
  }
  // |u| is largest at a column's outer edge; the gain grows with |u|
  gain_col_.resize(side_);
  for (int i = 0; i < side_; ++i) {
    const float a = std::max(std::fabs(-1.0f + 2.0f * i / side_), std::fabs(-1.0f + 2.0f * (i + 1) / side_));
    gain_col_[i] = std::sqrt((1.0f + a) * (1.0f + a) + 2.0f * a * a) * 1.0001f;
  }
  gain_row_ = gain_col_;
  build_unique();
  if (unique_.n > 0)
    k1_ = View{unique_.xs.data(), unique_.ys.data(), unique_.zs.data(), unique_.ids.data(),
               unique_.start.data(), unique_.slot_of.data(), unique_.n};
  else
    k1_ = View{xs_.data(), ys_.data(), zs_.data(), ids_.data(), start_.data(), slot_of_.data(), n_};
  build_subgrids();
}

// Equal points in one run cost a k = 1 scan without changing its answer: of
// equals the lowest id wins every tie, and ids ascend within a run, so the
// first of each is all that scan needs. Only crowded runs are searched for
// equals (a light one scans in a few vectors anyway), by sorting their slots.
void OctGridIndex::build_unique() {
  constexpr int kCrowded = 32;
  const int nodes = static_cast<int>(start_.size()) - 1;
  std::vector<int> crowded;
  for (int node = 0; node < nodes; ++node)
    if (start_[node + 1] - start_[node] > kCrowded) crowded.push_back(node);
  if (crowded.empty()) return;
  // per slot: the slot of its first equal (itself when it is the first)
  std::vector<int> first(static_cast<size_t>(n_));
  for (int i = 0; i < n_; ++i) first[i] = i;
  std::atomic<int> dropped{0};
  parallel_rows(static_cast<int>(crowded.size()), 0, 1, [&](int cb, int ce) {
    std::vector<int> order;
    int local = 0;
    for (int c = cb; c < ce; ++c) {
      const int b = start_[crowded[c]], e = start_[crowded[c] + 1];
      order.resize(static_cast<size_t>(e - b));
      for (int i = b; i < e; ++i) order[i - b] = i;
      std::sort(order.begin(), order.end(), [&](int x, int y) {
        return std::tie(xs_[x], ys_[x], zs_[x], x) < std::tie(xs_[y], ys_[y], zs_[y], y);
      });
      for (size_t t = 1; t < order.size(); ++t) {
        const int a = order[t - 1], i = order[t];
        if (xs_[a] == xs_[i] && ys_[a] == ys_[i] && zs_[a] == zs_[i]) first[i] = first[a], ++local;
      }
    }
    dropped.fetch_add(local, std::memory_order_relaxed);
  });
  if (dropped.load() == 0) return;
  Runs& u = unique_;
  u.n = n_ - dropped.load();
  u.start.assign(static_cast<size_t>(nodes) + 1, 0);
  for (int node = 0; node < nodes; ++node) {
    int kept = 0;
    for (int i = start_[node]; i < start_[node + 1]; ++i) kept += first[i] == i;
    u.start[node + 1] = u.start[node] + kept;
  }
  // 8 far points of padding, as the full arrays
  u.xs.assign(static_cast<size_t>(u.n) + 8, 1e18f);
  u.ys.assign(static_cast<size_t>(u.n) + 8, 1e18f);
  u.zs.assign(static_cast<size_t>(u.n) + 8, 1e18f);
  u.ids.assign(static_cast<size_t>(u.n) + 8, std::numeric_limits<int>::max());
  std::vector<int> place(static_cast<size_t>(n_));  // slot -> its place in u (the first equal's)
  for (int node = 0; node < nodes; ++node) {
    int at = u.start[node];
    for (int i = start_[node]; i < start_[node + 1]; ++i) {
      if (first[i] != i) {
        place[i] = place[first[i]];  // the first equal comes earlier in the run
        continue;
      }
      u.xs[at] = xs_[i], u.ys[at] = ys_[i], u.zs[at] = zs_[i], u.ids[at] = ids_[i];
      place[i] = at++;
    }
  }
  u.slot_of.resize(static_cast<size_t>(n_));
  for (int id = 0; id < n_; ++id) u.slot_of[id] = place[slot_of_[id]];
  // each group of equals chained by ascending id (slots ascend with ids in a run)
  eq_next_.assign(static_cast<size_t>(n_), -1);
  std::vector<int> last(static_cast<size_t>(n_));  // first equal's slot -> the group's last slot so far
  for (int i = 0; i < n_; ++i) {
    last[i] = i;
    if (first[i] == i) continue;
    eq_next_[ids_[last[first[i]]]] = ids_[i];
    last[first[i]] = i;
  }
}

void OctGridIndex::Boxes::reset(size_t n) {
  for (int a = 0; a < 3; ++a) lo[a].assign(n + 8, kInf), hi[a].assign(n + 8, -kInf);
}

void OctGridIndex::Boxes::set(size_t at, const View& v, int b, int e) {
  float lx = kInf, ly = kInf, lz = kInf, hx = -kInf, hy = -kInf, hz = -kInf;
  for (int i = b; i < e; ++i) {
    lx = std::min(lx, v.xs[i]), ly = std::min(ly, v.ys[i]), lz = std::min(lz, v.zs[i]);
    hx = std::max(hx, v.xs[i]), hy = std::max(hy, v.ys[i]), hz = std::max(hz, v.zs[i]);
  }
  lo[0][at] = lx, lo[1][at] = ly, lo[2][at] = lz, hi[0][at] = hx, hi[1][at] = hy, hi[2][at] = hz;
}

// The 3-D boxes of the nodes with points, of the sub-cells and of their
// tiles, from the k = 1 arrays (the same points as the full ones, equals
// aside), on the thread that first needs them: a search can run inside a
// parallel loop, and a nested one under the lock could wait on itself.
const OctGridIndex::BoxSet& OctGridIndex::boxes() const {
  if (boxes_made_.load(std::memory_order_acquire)) return boxes_;
  std::lock_guard<std::mutex> lock(boxes_mutex_);
  if (boxes_made_.load(std::memory_order_relaxed)) return boxes_;
  BoxSet& bs = boxes_;
  const int nodes = 2 * side_ * side_;
  for (int node = 0; node < nodes; ++node)
    if (k1_.start[node] < k1_.start[node + 1]) bs.node_of.push_back(node);
  bs.node.reset(bs.node_of.size());
  for (size_t j = 0; j < bs.node_of.size(); ++j) bs.node.set(j, k1_, k1_.start[bs.node_of[j]], k1_.start[bs.node_of[j] + 1]);
  if (!sub_.at.empty()) {
    bs.sub.reset(sub_.start.size());
    // tiles: the last row and column of each node's tiles cut at S
    bs.tile_at.assign(static_cast<size_t>(nodes), -1);
    int tiles = 0;
    for (int node = 0; node < nodes; ++node)
      if (sub_.at[node] >= 0) {
        const int t = (sub_.side[node] + 7) / 8;
        bs.tile_at[node] = tiles;
        tiles += t * t;
      }
    bs.tile.reset(static_cast<size_t>(tiles));
    for (int node = 0; node < nodes; ++node) {
      if (sub_.at[node] < 0) continue;
      const int at = sub_.at[node], S = sub_.side[node], T = (S + 7) / 8;
      for (int k = 0; k < S * S; ++k) {
        bs.sub.set(static_cast<size_t>(at + k), k1_, sub_.start[at + k], sub_.start[at + k + 1]);
        const size_t tile = static_cast<size_t>(bs.tile_at[node] + (k / S / 8) * T + (k % S) / 8);
        for (int a = 0; a < 3; ++a) {
          bs.tile.lo[a][tile] = std::min(bs.tile.lo[a][tile], bs.sub.lo[a][at + k]);
          bs.tile.hi[a][tile] = std::max(bs.tile.hi[a][tile], bs.sub.hi[a][at + k]);
        }
      }
    }
  }
  boxes_made_.store(true, std::memory_order_release);
  return boxes_;
}

// A crowded run of the k = 1 arrays (over 256 points: thousands where the
// source's normals cluster, as on the faces of a box seen with noise; the
// orange's densest cells stay below, and at 64 its coherent map took ~0.7 ms
// longer at 150k px for the same answers) is
// reordered by an S x S grid over its cell (S ~ sqrt(points / 4), 2..64), row
// by row, keeping where each sub-cell starts; within a sub-cell the order
// stays (ids ascending). The k = 1 search then reads the query's own sub-cell
// first and, of the rest of the run, only the sub-cells within reach of its
// best so far: the same answer, from a few dozen points instead of thousands.
void OctGridIndex::build_subgrids() {
  constexpr int kSubCrowded = 256;
  const int nodes = 2 * side_ * side_;
  std::vector<int> crowded;
  for (int node = 0; node < nodes; ++node)
    if (k1_.start[node + 1] - k1_.start[node] > kSubCrowded) crowded.push_back(node);
  if (crowded.empty()) return;
  sub_.at.assign(static_cast<size_t>(nodes), -1);
  sub_.side.assign(static_cast<size_t>(nodes), 0);
  sub_.row_has.assign(static_cast<size_t>(side_), 0);
  int total = 0;
  for (int node : crowded) {
    const int len = k1_.start[node + 1] - k1_.start[node];
    const int S = std::clamp(static_cast<int>(std::sqrt(len / 4.0)), 2, 64);
    sub_.at[node] = total;
    sub_.side[node] = S;
    sub_.row_has[(node >> 1) / side_] = 1;
    total += S * S + 1;
  }
  sub_.start.assign(static_cast<size_t>(total), 0);
  sub_.near.assign(static_cast<size_t>(total), 0);
  // old place -> new place: every id's place is remapped when ids share
  // places (the deduplicated arrays), else only the moved points' are set
  const bool shared = k1_.n < n_;
  std::vector<int> moved(shared ? static_cast<size_t>(k1_.n) : 0);
  for (size_t i = 0; i < moved.size(); ++i) moved[i] = static_cast<int>(i);
  const float scale = 0.5f * static_cast<float>(side_);
  parallel_rows(static_cast<int>(crowded.size()), 0, 1, [&](int cb, int ce) {
    std::vector<int> sub_of, fill;
    std::vector<float> tx, ty, tz;
    std::vector<int> tid;
    for (int c = cb; c < ce; ++c) {
      const int node = crowded[c], b = k1_.start[node], e = k1_.start[node + 1], len = e - b;
      const int S = sub_.side[node], cx = (node >> 1) % side_, cy = (node >> 1) / side_;
      int* ss = sub_.start.data() + sub_.at[node];
      sub_of.resize(static_cast<size_t>(len));
      for (int i = b; i < e; ++i) {
        float u, v;
        oct_uv(k1_.xs[i], k1_.ys[i], k1_.zs[i], u, v);
        const int sx = std::clamp(static_cast<int>(((u + 1.0f) * scale - cx) * S), 0, S - 1);
        const int sy = std::clamp(static_cast<int>(((v + 1.0f) * scale - cy) * S), 0, S - 1);
        sub_of[i - b] = sy * S + sx;
        ++ss[sy * S + sx + 1];
      }
      ss[0] = b;
      for (int k = 0; k < S * S; ++k) ss[k + 1] += ss[k];
      fill.assign(ss, ss + S * S);
      tx.resize(len), ty.resize(len), tz.resize(len), tid.resize(len);
      for (int i = b; i < e; ++i) {
        const int at = fill[sub_of[i - b]]++;
        tx[at - b] = k1_.xs[i], ty[at - b] = k1_.ys[i], tz[at - b] = k1_.zs[i], tid[at - b] = k1_.ids[i];
        if (shared) moved[i] = at;
      }
      std::copy(tx.begin(), tx.end(), k1_.xs + b);
      std::copy(ty.begin(), ty.end(), k1_.ys + b);
      std::copy(tz.begin(), tz.end(), k1_.zs + b);
      std::copy(tid.begin(), tid.end(), k1_.ids + b);
      if (!shared)
        for (int i = b; i < e; ++i) k1_.slot_of[k1_.ids[i]] = i;
      // each empty sub-cell sends its queries to the nearest one with points
      // (in sub-cells, breadth first), as near_ does for cells
      int* near = sub_.near.data() + sub_.at[node];
      fill.clear();
      for (int k = 0; k < S * S; ++k) {
        near[k] = ss[k] < ss[k + 1] ? k : -1;
        if (near[k] == k) fill.push_back(k);
      }
      for (size_t qi = 0; qi < fill.size(); ++qi) {
        const int k = fill[qi], x = k % S, y = k / S;
        const int nb[4] = {x > 0 ? k - 1 : -1, x + 1 < S ? k + 1 : -1, y > 0 ? k - S : -1, y + 1 < S ? k + S : -1};
        for (int t : nb)
          if (t >= 0 && near[t] < 0) near[t] = near[k], fill.push_back(t);
      }
    }
  });
  if (shared)
    for (int id = 0; id < n_; ++id) k1_.slot_of[id] = moved[k1_.slot_of[id]];
}

// Largest box of cells the k = 1 path reads as rows of runs (else the cell
// by cell search of nearest_from).
constexpr int kRunCells = 49;

// Points [b, e) against q, 8 at a time (AVX2), each lane keeping its best
// (distance, id) pair with the lower-id rule, without branches; the caller
// reduces the lanes at the end (best_of). The arrays are padded past n with
// far points, so the last group reads valid memory and never wins. Distances
// are the same fused sums as sq3's, bit for bit.
#ifdef VENEER_INDEX_AVX2
struct Query {  // the query in every lane
  __m256 x, y, z;
  Query(float qx, float qy, float qz) : x(_mm256_set1_ps(qx)), y(_mm256_set1_ps(qy)), z(_mm256_set1_ps(qz)) {}
};

struct Lanes {
  __m256 d = _mm256_set1_ps(kInf);
  __m256i id = _mm256_set1_epi32(std::numeric_limits<int>::max()), slot = _mm256_set1_epi32(-1);
};

__attribute__((always_inline)) static inline void scan_lanes(const float* xs, const float* ys, const float* zs, const int* ids, int b, int e,
                              const Query& q, Lanes& l) {
  const __m256 vx = q.x, vy = q.y, vz = q.z;
  const __m256i step = _mm256_set1_epi32(8);
  __m256i slot = _mm256_add_epi32(_mm256_set1_epi32(b), _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
  const __m256i end = _mm256_set1_epi32(e);
  for (int i = b; i < e; i += 8) {
    const __m256 tx = _mm256_sub_ps(_mm256_loadu_ps(xs + i), vx);
    const __m256 ty = _mm256_sub_ps(_mm256_loadu_ps(ys + i), vy);
    const __m256 tz = _mm256_sub_ps(_mm256_loadu_ps(zs + i), vz);
    const __m256 d = _mm256_fmadd_ps(tz, tz, _mm256_fmadd_ps(ty, ty, _mm256_mul_ps(tx, tx)));
    const __m256i id = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(ids + i));
    // this lane wins: inside the run, and (d, id) below the lane's best
    const __m256i inside = _mm256_cmpgt_epi32(end, slot);
    const __m256i less = _mm256_castps_si256(_mm256_cmp_ps(d, l.d, _CMP_LT_OQ));
    const __m256i tie = _mm256_and_si256(_mm256_castps_si256(_mm256_cmp_ps(d, l.d, _CMP_EQ_OQ)), _mm256_cmpgt_epi32(l.id, id));
    const __m256i take = _mm256_and_si256(inside, _mm256_or_si256(less, tie));
    l.d = _mm256_blendv_ps(l.d, d, _mm256_castsi256_ps(take));
    l.id = _mm256_blendv_epi8(l.id, id, take);
    l.slot = _mm256_blendv_epi8(l.slot, slot, take);
    slot = _mm256_add_epi32(slot, step);
  }
}

// The lanes' best (distance, id) pair; false when no lane has one.
__attribute__((always_inline)) static inline bool best_of(const Lanes& l, float& best_d, int& best_slot) {
  // the smallest distance in every lane
  __m256 m = _mm256_min_ps(l.d, _mm256_permute2f128_ps(l.d, l.d, 1));
  m = _mm256_min_ps(m, _mm256_shuffle_ps(m, m, _MM_SHUFFLE(1, 0, 3, 2)));
  m = _mm256_min_ps(m, _mm256_shuffle_ps(m, m, _MM_SHUFFLE(2, 3, 0, 1)));
  const float dmin = _mm256_cvtss_f32(m);
  if (!(dmin < kInf)) return false;  // no lane has a point (those that do are finite)
  // among the lanes at that distance, the lowest id
  const __m256i at_min = _mm256_castps_si256(_mm256_cmp_ps(l.d, m, _CMP_EQ_OQ));
  const __m256i ids = _mm256_blendv_epi8(_mm256_set1_epi32(std::numeric_limits<int>::max()), l.id, at_min);
  __m256i t = _mm256_min_epi32(ids, _mm256_permute2x128_si256(ids, ids, 1));
  t = _mm256_min_epi32(t, _mm256_shuffle_epi32(t, _MM_SHUFFLE(1, 0, 3, 2)));
  t = _mm256_min_epi32(t, _mm256_shuffle_epi32(t, _MM_SHUFFLE(2, 3, 0, 1)));
  const __m256i hit = _mm256_and_si256(at_min, _mm256_cmpeq_epi32(ids, t));
  const int lane = __builtin_ctz(static_cast<unsigned>(_mm256_movemask_ps(_mm256_castsi256_ps(hit))));
  alignas(32) int slot[8];
  _mm256_store_si256(reinterpret_cast<__m256i*>(slot), l.slot);
  best_d = dmin;
  best_slot = slot[lane];
  return true;
}

// The smallest distance over the lanes (infinity when none has a point).
__attribute__((always_inline)) static inline float lanes_min(const Lanes& l) {
  __m128 m = _mm_min_ps(_mm256_castps256_ps128(l.d), _mm256_extractf128_ps(l.d, 1));
  m = _mm_min_ps(m, _mm_movehl_ps(m, m));
  m = _mm_min_ss(m, _mm_shuffle_ps(m, m, 1));
  return _mm_cvtss_f32(m);
}

#else
struct Query {
  float x, y, z;
  Query(float qx, float qy, float qz) : x(qx), y(qy), z(qz) {}
};

struct Lanes {  // one lane
  float d = kInf;
  int id = std::numeric_limits<int>::max(), slot = -1;
};

__attribute__((always_inline)) static inline void scan_lanes(const float* xs, const float* ys, const float* zs, const int* ids, int b, int e,
                              const Query& q, Lanes& l) {
  for (int i = b; i < e; ++i) {
    const float d = sq3(xs[i], ys[i], zs[i], q.x, q.y, q.z);
    if (d < l.d || (d == l.d && ids[i] < l.id)) l.d = d, l.id = ids[i], l.slot = i;
  }
}

__attribute__((always_inline)) static inline bool best_of(const Lanes& l, float& best_d, int& best_slot) {
  if (!(l.d < kInf)) return false;
  best_d = l.d;
  best_slot = l.slot;
  return true;
}

__attribute__((always_inline)) static inline float lanes_min(const Lanes& l) { return l.d; }
#endif

// Boxes [b, b + n) against q, 8 at a time: per box, a lower bound of the
// squared distance from q to any point in it (+inf for an empty box), through
// `take(j, bound)` for each box j (counted from b) whose bound is at most
// *limit, which the caller may lower as it goes. Per axis the gap between q
// and the box, summed as sq3 sums a point's differences: every term is at
// most the point's (rounding keeps the order), so the bound never exceeds the
// distance sq3 computes for any point in the box.
#ifdef VENEER_INDEX_AVX2
template <class Take>
static inline void boxes_within(const float* const lo[3], const float* const hi[3], int b, int n, float qx, float qy,
                                float qz, const float* limit, Take&& take) {
  const __m256 zero = _mm256_setzero_ps();
  const __m256 q[3] = {_mm256_set1_ps(qx), _mm256_set1_ps(qy), _mm256_set1_ps(qz)};
  for (int j = 0; j < n; j += 8) {
    __m256 t[3];
    for (int a = 0; a < 3; ++a)
      t[a] = _mm256_max_ps(_mm256_max_ps(_mm256_sub_ps(_mm256_loadu_ps(lo[a] + b + j), q[a]),
                                         _mm256_sub_ps(q[a], _mm256_loadu_ps(hi[a] + b + j))),
                           zero);
    const __m256 d = _mm256_fmadd_ps(t[2], t[2], _mm256_fmadd_ps(t[1], t[1], _mm256_mul_ps(t[0], t[0])));
    unsigned mask = static_cast<unsigned>(_mm256_movemask_ps(_mm256_cmp_ps(d, _mm256_set1_ps(*limit), _CMP_LE_OQ)));
    if (n - j < 8) mask &= (1u << (n - j)) - 1u;
    if (!mask) continue;
    alignas(32) float bound[8];
    _mm256_store_ps(bound, d);
    for (; mask; mask &= mask - 1) {
      const int lane = __builtin_ctz(mask);
      if (bound[lane] <= *limit) take(j + lane, bound[lane]);
    }
  }
}
#else
template <class Take>
static inline void boxes_within(const float* const lo[3], const float* const hi[3], int b, int n, float qx, float qy,
                                float qz, const float* limit, Take&& take) {
  const float q[3] = {qx, qy, qz};
  for (int j = 0; j < n; ++j) {
    float t[3];
    for (int a = 0; a < 3; ++a) t[a] = std::max(std::max(lo[a][b + j] - q[a], q[a] - hi[a][b + j]), 0.0f);
    const float bound = sq3(t[0], t[1], t[2], 0.0f, 0.0f, 0.0f);  // (t - 0 is t exactly)
    if (bound <= *limit) take(j, bound);
  }
}
#endif

// k = 1 for a query of near-unit length (the engine's normals): the hint (a
// point likely near, e.g. the previous pixel's match) and the query's own
// cell first; then every cell within
// reach of that best, read as one run of points per row of cells. Exact by the
// bound explained above; false (nothing written) when the box would be large,
// the query far from unit length, or there is nothing to start from.
bool OctGridIndex::nearest1(const float* query, int& slot, int& id, float& sq, bool exact) const {
  const float qx = query[0], qy = query[1], qz = query[2];
  const float q2 = qx * qx + qy * qy + qz * qz;
  if (!(q2 > 0.81f && q2 < 1.21f)) return false;
  // | |q| - 1 | = |q2 - 1| / (|q| + 1), and |q| + 1 > 1.9
  const float dq = std::fabs(q2 - 1.0f) * (1.0f / 1.9f);
  const float s = std::fabs(qx) + std::fabs(qy) + std::fabs(qz);
  const float inv = 1.0f / s;
  const float u = qx * inv, v = qy * inv;
  const float scale = 0.5f * static_cast<float>(side_);
  const int ci = std::clamp(static_cast<int>((u + 1.0f) * scale), 0, side_ - 1);
  const int cj = std::clamp(static_cast<int>((v + 1.0f) * scale), 0, side_ - 1);
  const Query vq(qx, qy, qz);
  Lanes lanes;
  const float* xs = k1_.xs;
  const float* ys = k1_.ys;
  const float* zs = k1_.zs;
  const int* ids = k1_.ids;
  const int* start = k1_.start;
  // (forced inline: with the file grown, GCC stopped inlining it, +10 % on k = 1)
  auto scan = [&](int b, int e) __attribute__((always_inline)) { scan_lanes(xs, ys, zs, ids, b, e, vq, lanes); };
  if (slot >= 0 && slot < k1_.n) scan(slot, slot + 1);  // a bound from the start
  const int own = 2 * (cj * side_ + ci);
  // A point that could still beat distance d is within r = sqrt(d) of q,
  // hence its unit direction within r + eps + | |q| - 1 | of q's (the chord c
  // of the bound above); its u and v lie within these reaches of q's. The
  // gains are their largest over the query's cell column / row (tables).
  auto reach_of = [&](float d, float& reach_u, float& reach_v) __attribute__((always_inline)) {
    const float c = (std::sqrt(d) + eps_ + dq) * 1.0001f + 1e-6f;
    const float s_q = s / (1.0f + dq);  // <= s / |q|
    const float shrink = 1.0001f / std::max(1.0f, s_q - 1.7320509f * c);
    reach_u = c * gain_col_[ci] * shrink + 1e-5f;
    reach_v = c * gain_row_[cj] * shrink + 1e-5f;
  };
  // A crowded node of cell (cx, cy): the query's sub-cell (the nearest one,
  // when the query is outside the cell), or the nearest with points ...
  auto scan_own_sub = [&](int node, int cx, int cy) {
    const int at = sub_.at[node], k = nearest_sub(node, cx, cy, u, v);
    scan(sub_.start[at + k], sub_.start[at + k + 1]);
    return k;
  };
  // ... and its sub-cells within the reaches of q, sub-cell `skip` left out
  // (read already; -1: none); a row of sub-cells is one run. (The sub-cell
  // read is passed, not computed again: the compiler may fuse the two
  // computations' arithmetic differently, and a query on a sub-cell edge
  // then skipped the other one, missing its points.)
  auto scan_near_subs = [&](int node, int cx, int cy, float reach_u, float reach_v, int skip) {
    const int S = sub_.side[node];
    const int* ss = sub_.start.data() + sub_.at[node];
    const float fx = ((u + 1.0f) * scale - cx) * S, fy = ((v + 1.0f) * scale - cy) * S;
    const float rx = reach_u * scale * S, ry = reach_v * scale * S;
    // (truncation instead of floor: a negative value clamps to 0 either way)
    const int x0 = std::clamp(static_cast<int>(fx - rx), 0, S - 1), x1 = std::clamp(static_cast<int>(fx + rx), 0, S - 1);
    const int y0 = std::clamp(static_cast<int>(fy - ry), 0, S - 1), y1 = std::clamp(static_cast<int>(fy + ry), 0, S - 1);
    const int ox = skip < 0 ? -1 : skip % S, oy = skip < 0 ? -1 : skip / S;
    for (int y = y0; y <= y1; ++y) {
      const int* row = ss + y * S;
      if (y == oy && x0 <= ox && ox <= x1) {
        scan(row[x0], row[ox]);
        scan(row[ox + 1], row[x1 + 1]);
      } else {
        scan(row[x0], row[x1 + 1]);
      }
    }
  };
  auto finish = [&]() __attribute__((always_inline)) {
    float d;
    int best;
    if (!best_of(lanes, d, best)) return false;
    slot = best;
    id = ids[best];
    sq = d;
    return true;
  };
  if (!exact) {
    // the lookup: the best of the query's own cell in its layer (or the
    // nearest cell with points, when it has none) and the hint, no more
    const int node = near_[own + (qz < 0 ? 1 : 0)];
    if (node < 0) return false;  // (a cell outside the diamond: not for a unit query)
    if (!crowded(node)) {
      scan(start[node], start[node + 1]);
      return finish();
    }
    // A crowded cell. The query's own: the best of all its points, read by
    // sub-cells within reach (the same answer as reading them all). Another
    // (the query's cell has no points): the sub-cell nearest the query. A
    // query far from a dense cluster has nearly the whole cluster within
    // reach (the bound is in uv, inflated by the map's stretch), and its best
    // is an approximation anyway, as every lookup across a cell edge.
    const int read = scan_own_sub(node, (node >> 1) % side_, (node >> 1) / side_);
    if (node >> 1 == own >> 1) {
      float reach_u, reach_v;
      reach_of(lanes_min(lanes), reach_u, reach_v);
      scan_near_subs(node, ci, cj, reach_u, reach_v, read);
    }
    return finish();
  }
  int read[2] = {-1, -1};  // the sub-cell read in each layer of the own cell
  for (int node = own; node < own + 2; ++node) {
    if (crowded(node)) read[node - own] = scan_own_sub(node, ci, cj);
    else scan(start[node], start[node + 1]);
  }
  const float best_d = lanes_min(lanes);
  if (!(best_d < kInf)) return false;
  float reach_u, reach_v;
  reach_of(best_d, reach_u, reach_v);
  const int x0 = std::clamp(static_cast<int>((u - reach_u + 1.0f) * scale), 0, side_ - 1);
  const int x1 = std::clamp(static_cast<int>((u + reach_u + 1.0f) * scale), 0, side_ - 1);
  const int y0 = std::clamp(static_cast<int>((v - reach_v + 1.0f) * scale), 0, side_ - 1);
  const int y1 = std::clamp(static_cast<int>((v + reach_v + 1.0f) * scale), 0, side_ - 1);
  if ((x1 - x0 + 1) * (y1 - y0 + 1) > kRunCells) return false;
  for (int cy = y0; cy <= y1; ++cy) {
    const int row = 2 * cy * side_;
    if (sub_.row_has.empty() || !sub_.row_has[cy]) {
      if (cy == cj) {  // around the cell already read
        if (x0 < ci) scan(start[row + 2 * x0], start[row + 2 * ci]);
        if (ci < x1) scan(start[row + 2 * ci + 2], start[row + 2 * x1 + 2]);
        continue;
      }
      scan(start[row + 2 * x0], start[row + 2 * x1 + 2]);
      continue;
    }
    // node by node: runs of light nodes read together, crowded ones by sub-cell
    int b = -1, e = -1;
    for (int node = row + 2 * x0; node < row + 2 * x1 + 2; ++node) {
      const bool mine = node >> 1 == own >> 1;
      if (!crowded(node) && !mine) {
        if (b < 0) b = start[node];
        e = start[node + 1];
        continue;
      }
      if (b >= 0) scan(b, e), b = -1;
      if (crowded(node)) scan_near_subs(node, (node >> 1) % side_, cy, reach_u, reach_v, mine ? read[node - own] : -1);
    }
    if (b >= 0) scan(b, e);
  }
  return finish();
}

bool OctGridIndex::nearest_slot(const float* query, int& slot, int& id, float& sq, bool exact) const {
  if (fallback_ || n_ == 0) return false;
  return nearest1(query, slot, id, sq, exact);
}

void OctGridIndex::knn(const float* query, int k, int* ids, float* sq_dists) const {
  if (lookup_ && k == 1 && !fallback_ && n_ > 0) {
    int slot = -1;
    if (nearest1(query, slot, ids[0], sq_dists[0], false)) return;
  }
  nearest_from(query, k, ids, sq_dists, -1);
}

void OctGridIndex::nearest_from(const float* query, int k, int* ids, float* sq_dists, int hint) const {
  if (fallback_) {
    fallback_->knn(query, k, ids, sq_dists);
    return;
  }
  if (k == 1 && n_ > 0 && !fallback_) {
    int slot = hint < 0 || hint >= n_ ? -1 : k1_.slot_of[hint];
    if (nearest1(query, slot, ids[0], sq_dists[0], true)) return;
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
    // still win (points within eps of unit length): |q|^2 + 1 - 2 |q| cos θ
    // <= r^2, so the chord between the unit directions, 2 sin(θ / 2) =
    // sqrt(2 (1 - cos θ)), is at most sqrt((r^2 - (|q| - 1)^2) / |q|). (Not
    // through cos θ: 1 - cos θ cancels to 0 in floats for r below ~2e-4,
    // which once cut the reach of a source with tight clusters of normals.)
    const float r = std::sqrt(w) + eps_, off = qn - 1.0f;
    const float chord2 = (r - std::fabs(off)) * (r + std::fabs(off)) / qn;
    if (!(chord2 < 4.0f)) {
      reach_u = reach_v = kInf;
      return;
    }
    const float chord = std::sqrt(std::max(chord2, 0.0f)) * 1.0001f + 1e-6f;
    const float denom = std::max(1.0f, s_q - 1.7320509f * chord);
    reach_u = chord * gain_u / denom * 1.0001f + 1e-5f;
    reach_v = chord * gain_v / denom * 1.0001f + 1e-5f;
  };
  // The k = 1 arrays are read (equals kept once): a point that enters a
  // longer list brings its equals after it, lowest ids first, while they fit.
  const View& V = k1_;
  const bool equals = !one && !eq_next_.empty();
  auto worst = [&] { return one ? best_d : best.worst(); };
  auto scan_run = [&](int b, int e) {
    if (b >= e) return;
    if (one) {
      const float before = best_d;
      for (int i = b; i < e; ++i) {
        const float d = sq3(V.xs[i], V.ys[i], V.zs[i], qx, qy, qz);
        if (d < best_d || (d == best_d && V.ids[i] < best_id)) best_d = d, best_id = V.ids[i];
      }
      if (best_d < before) update_reach();
      return;
    }
    bool improved = false;
    for (int i = b; i < e; ++i) {
      const float d = sq3(V.xs[i], V.ys[i], V.zs[i], qx, qy, qz);
      if (!(d < best.worst() || (d == best.worst() && V.ids[i] < best.worst_id()))) continue;
      best.add(d, V.ids[i]);
      improved = true;
      if (equals)
        for (int id = eq_next_[V.ids[i]]; id >= 0 && (d < best.worst() || (d == best.worst() && id < best.worst_id()));
             id = eq_next_[id])
          best.add(d, id);
    }
    if (improved) update_reach();
  };
  // A crowded node of cell (cx, cy): its rows of sub-cells within reach, from
  // the query's row outwards, each row's sub-cells within reach as one run.
  auto scan_subs = [&](int node, int cx, int cy) __attribute__((noinline)) {
    const int S = sub_.side[node];
    const int* ss = sub_.start.data() + sub_.at[node];
    const float fx = ((u + 1.0f) * scale - cx) * S, fy = ((v + 1.0f) * scale - cy) * S;
    const int own_y = static_cast<int>(std::clamp(fy, 0.0f, S - 1.0f));
    auto row = [&](int y) {
      const float gap = std::max({0.0f, y - fy, fy - (y + 1)});  // in sub-cells
      const float ry = reach_v * scale * S, rx = reach_u * scale * S;
      if (gap > ry) return false;
      const int x0 = static_cast<int>(std::clamp(fx - rx, 0.0f, S - 1.0f));
      const int x1 = static_cast<int>(std::clamp(fx + rx, 0.0f, S - 1.0f));
      scan_run(ss[y * S + x0], ss[y * S + x1 + 1]);
      return true;
    };
    for (int y = own_y; y >= 0 && row(y); --y) {
    }
    for (int y = own_y + 1; y < S && row(y); ++y) {
    }
  };
  auto scan_cell = [&](int cx, int cy) {
    // uv distance from the query to this cell's rectangle
    const float x0 = -1.0f + cx * h, y0 = -1.0f + cy * h;
    const float dx = std::max({0.0f, x0 - u, u - (x0 + h)});
    const float dy = std::max({0.0f, y0 - v, v - (y0 + h)});
    if (dx > reach_u || dy > reach_v) return;
    const int c = 2 * (cy * side_ + cx);
    if (sub_.at.empty() || sub_.at[c] + sub_.at[c + 1] == -2) {  // neither layer crowded: one run
      scan_run(V.start[c], V.start[c + 2]);
      return;
    }
    for (int node = c; node < c + 2; ++node) {
      if (crowded(node)) scan_subs(node, cx, cy);
      else scan_run(V.start[node], V.start[node + 1]);
    }
  };
  // Far from every point (a query between a few dense clusters: a box's
  // faces), the rings cross many empty cells and reach whole clusters. Then
  // the nodes with points outside the square of rings < r are read by their
  // 3-D boxes, nearest first, while a box can still hold a winner; a crowded
  // one from the sub-cell nearest the query in uv, then by the boxes of its
  // 8 x 8 tiles (nearest first) and of their sub-cells.
  auto far = [&](int r) __attribute__((noinline)) {
    thread_local std::vector<std::pair<float, int>> order, tiles;
    order.clear();
    const BoxSet& bs = boxes();
    auto lo_hi = [](const Boxes& b, const float* lo[3], const float* hi[3]) {
      for (int a = 0; a < 3; ++a) lo[a] = b.lo[a].data(), hi[a] = b.hi[a].data();
    };
    const float *lo[3], *hi[3], *slo[3], *shi[3], *tlo[3], *thi[3];
    lo_hi(bs.node, lo, hi);
    lo_hi(bs.sub, slo, shi);
    lo_hi(bs.tile, tlo, thi);
    const float limit = worst();
    boxes_within(lo, hi, 0, static_cast<int>(bs.node_of.size()), qx, qy, qz, &limit, [&](int j, float bound) {
      const int node = bs.node_of[j], cx = (node >> 1) % side_, cy = (node >> 1) / side_;
      if (std::abs(cx - ci) >= r || std::abs(cy - cj) >= r) order.emplace_back(bound, node);
    });
    // nearest first, popped from a heap: the search usually ends after a few
    auto later = [](const std::pair<float, int>& a, const std::pair<float, int>& b) { return b < a; };
    std::make_heap(order.begin(), order.end(), later);
    for (auto end = order.end(); end != order.begin(); --end) {
      std::pop_heap(order.begin(), end, later);
      const auto [bound, node] = end[-1];
      float now = worst();
      if (bound > now) break;
      if (!crowded(node)) {
        scan_run(V.start[node], V.start[node + 1]);
        continue;
      }
      const int S = sub_.side[node], at = sub_.at[node];
      const int first = nearest_sub(node, (node >> 1) % side_, (node >> 1) / side_, u, v);
      const int* ss = sub_.start.data() + at;
      scan_run(ss[first], ss[first + 1]);
      now = worst();
      // the tiles that can hold a winner, nearest first, then their
      // sub-cells that still can, 8 per row
      const int T = (S + 7) / 8;
      tiles.clear();
      boxes_within(tlo, thi, bs.tile_at[node], T * T, qx, qy, qz, &now,
                   [&](int t, float b) { tiles.emplace_back(b, t); });
      std::sort(tiles.begin(), tiles.end());
      for (const auto& [tb, t] : tiles) {
        if (tb > now) break;
        const int x0 = (t % T) * 8, y0 = (t / T) * 8;
        for (int y = y0; y < std::min(S, y0 + 8); ++y)
          boxes_within(slo, shi, at + y * S + x0, std::min(8, S - x0), qx, qy, qz, &now, [&](int x, float) {
            const int k = y * S + x0 + x;
            if (k == first) return;
            scan_run(ss[k], ss[k + 1]);
            now = worst();
          });
      }
    }
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
  // shrinks) is all there is to visit, when that box is small; else rings.
  auto done = [&] {
    if (one && best_d < kInf) ids[0] = best_id, sq_dists[0] = best_d;
    best.finish();
  };
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
      done();
      return;
    }
  }
  // A source of a few dense clusters (under kFewBoxes nodes with points) is
  // read by their boxes at once; else the rings give way to the boxes once
  // they have crossed as many cells as there are nodes with points.
  const long far_cells = occupied_;
  if (far_cells <= kFewBoxes) {
    far(0);
    done();
    return;
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
      if (static_cast<long>(2 * r - 1) * (2 * r - 1) >= far_cells) {
        far(r);
        break;
      }
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
  done();
}

std::unique_ptr<NearestIndex> make_index(const std::string& kind) {
  if (kind == "grid") return std::make_unique<OctGridIndex>();
  if (kind == "lookup") return std::make_unique<OctGridIndex>(0, true);
  if (kind == "kdtree") return std::make_unique<KdTreeIndex>();
  return nullptr;
}

std::unique_ptr<NearestIndex> make_kdtree() { return std::make_unique<KdTreeIndex>(); }

}  // namespace veneer::match::fast
