// The octahedral grid's queries: nearest, k nearest, and the search from a
// hint, 8 points or boxes at a time with AVX2 and FMA (one elsewhere).
#include "index_fast.hpp"

#include "object.hpp"  // sq3

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
  if (kind == "kdtree") return make_kdtree();
  return nullptr;
}

}  // namespace veneer::match::fast
