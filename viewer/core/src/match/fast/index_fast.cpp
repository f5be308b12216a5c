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



// The scans below run 8 points (or boxes) at a time with AVX2 and FMA, and
// one at a time elsewhere (an ARM board; -DVENEER_AVX2=OFF, for any x86-64;
// test_core_match_fast_portable builds it on every run). Both give
// the same answers: the distances are sq3's, the ties go to the lower id.
#if defined(__AVX2__) && defined(__FMA__)
#define VENEER_INDEX_AVX2 1
#include <immintrin.h>
#endif

#include "index_detail.hpp"

namespace veneer::match::fast {

using namespace detail;


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
    fallback_ = make_kdtree();
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

}  // namespace veneer::match::fast
