// Candidate lists (candidates.hpp) without sorted K-nearest lists.
//
// The choice only needs the *set* of the K nearest source rows, not its order:
// it is the row with the smallest (image distance, value distance, id) among
// the K smallest (value distance, id). So a query collects every source row
// within a radius r of its value (r guessed from the previous query), and if
// it got at least K rows, the K nearest are among them: every row left out is
// farther than r, hence than each of those K. With fewer than K, r grows and
// the query is repeated; r only decides the speed, never the result. Among
// the collected rows, the one nearest in the image is taken if its (distance,
// id) ranks below K among them; otherwise the next nearest in the image, and
// so on (rarely more than two steps; after 16 the K-th pair is found with
// nth_element). No list is ever sorted.
//
// The source rows live in a bounding-box tree: sorted by the Morton code of
// their quantised values (8 bits per axis), split where the code's highest
// differing bit flips (an octree in binary form), leaves of at most kLeaf rows,
// values stored SoA in tree order. Queries run in Morton order of their
// values, so neighbours in that order have nearly the same K sets: a query
// gathers the rows within kReach * r of its value into a small contiguous
// group, and the queries that follow (or lie a little ahead) whose ball fits
// inside it scan only that group. Collecting is an AVX2 left-pack of the rows
// passing the distance test.
//
// Distances are computed in the order of features.hpp's squared_distance()
// and image distances by the faithful method's expression, so ties break as
// in matcher.cpp. Work is split into fixed blocks of the sorted queries (each
// starts afresh), so the result does not depend on the thread count.
#include "candidates.hpp"

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#if defined(__AVX2__)
#include <immintrin.h>
#endif

namespace veneer::match::fast {

namespace {

// Measured on bench_match's objects (21k and 174k px); the result never depends on them.
constexpr int kLeaf = 24;        // rows per tree leaf at most
constexpr int kBlock = 1024;     // sorted queries per work block
constexpr int kAhead = 64;       // queries looked ahead for one that fits a new group
constexpr float kSlack = 1e-5f;  // relative margin on radii (float rounding)
constexpr float kGuess = 1.15f;  // a query's first radius / the previous query's estimated K-th distance
constexpr float kReach = 1.6f;   // a group's radius / the radius of the query that gathers it
constexpr float kWaste = 1.5f;   // regather when the group is this much wider than a new one

uint32_t spread8(uint32_t v) {
  v &= 0xffu;
  v = (v | (v << 8)) & 0x0000f00fu;
  v = (v | (v << 4)) & 0x000c30c3u;
  v = (v | (v << 2)) & 0x00249249u;
  return v;
}

// Quantises 3-D values onto a 256^3 lattice over the source's box (values
// outside are clamped: the code only orders work, it never decides results).
struct Morton {
  float lo[3] = {0, 0, 0}, scale[3] = {0, 0, 0};
  uint32_t operator()(const float* p) const {
    uint32_t c = 0;
    for (int a = 0; a < 3; ++a) {
      const float t = std::clamp((p[a] - lo[a]) * scale[a], 0.0f, 255.0f);
      c |= spread8(static_cast<uint32_t>(t)) << a;
    }
    return c;
  }
};

// Stable LSD radix sort of (code << 32 | index) pairs by their 24-bit code.
void sort_by_code(std::vector<uint64_t>& a) {
  std::vector<uint64_t> tmp(a.size());
  std::vector<uint32_t> count(4097);
  for (int shift = 32; shift < 56; shift += 12) {
    std::fill(count.begin(), count.end(), 0u);
    for (uint64_t v : a) ++count[((v >> shift) & 4095u) + 1];
    for (int i = 0; i < 4096; ++i) count[i + 1] += count[i];
    for (uint64_t v : a) tmp[count[(v >> shift) & 4095u]++] = v;
    a.swap(tmp);
  }
}

struct Node {
  float lo[3], hi[3];
  int begin, end;  // rows in tree order
  int left = -1, right = -1;
};

struct Tree {
  std::vector<float> xs, ys, zs;  // values in tree order
  std::vector<uint32_t> ids;      // tree order -> source row
  std::vector<float> px, py;      // the source pixel of each, in tree order
  std::vector<int> at;            // 0, 1, 2, ...: tree indices, for packing
  std::vector<uint32_t> codes;
  std::vector<Node> nodes;

  int build(int b, int e) {
    const int me = static_cast<int>(nodes.size());
    nodes.push_back(Node{});
    Node n{};
    n.begin = b;
    n.end = e;
    if (e - b <= kLeaf) {
      for (int a = 0; a < 3; ++a) n.lo[a] = std::numeric_limits<float>::infinity(), n.hi[a] = -n.lo[a];
      for (int i = b; i < e; ++i) {
        const float v[3] = {xs[i], ys[i], zs[i]};
        for (int a = 0; a < 3; ++a) n.lo[a] = std::min(n.lo[a], v[a]), n.hi[a] = std::max(n.hi[a], v[a]);
      }
      nodes[me] = n;
      return me;
    }
    int m;
    const uint32_t cb = codes[b], ce = codes[e - 1];
    if (cb == ce) {
      m = b + (e - b) / 2;
    } else {
      const uint32_t bit = std::bit_floor(cb ^ ce);
      m = static_cast<int>(std::partition_point(codes.begin() + b, codes.begin() + e,
                                                [bit](uint32_t c) { return (c & bit) == 0; }) -
                           codes.begin());
    }
    n.left = build(b, m);
    n.right = build(m, e);
    const Node &l = nodes[n.left], &r = nodes[n.right];
    for (int a = 0; a < 3; ++a) n.lo[a] = std::min(l.lo[a], r.lo[a]), n.hi[a] = std::max(l.hi[a], r.hi[a]);
    nodes[me] = n;
    return me;
  }
};


#if defined(__AVX2__)
// Lane permutations that move the lanes set in an 8-bit mask to the front.
struct PackTable {
  alignas(32) int lanes[256][8];
  PackTable() {
    for (int m = 0; m < 256; ++m) {
      int c = 0;
      for (int j = 0; j < 8; ++j)
        if (m & (1 << j)) lanes[m][c++] = j;
      for (; c < 8; ++c) lanes[m][c] = 0;
    }
  }
};
const PackTable kPack;
#endif

// Packs the lanes of [0, n) with d[j] <= lim to the front of the outputs
// (outputs have room for n + 8); returns how many. `f` arrays are float,
// `i` arrays int; nf/ni of them.
template <int NF, int NI>
int pack(int n, const float* d, float lim, const float* const (&fin)[NF], float* const (&fout)[NF],
         const int* const (&iin)[NI], int* const (&iout)[NI]) {
  int c = 0, j = 0;
#if defined(__AVX2__)
  const __m256 limv = _mm256_set1_ps(lim);
  for (; j + 8 <= n; j += 8) {
    const int mask = _mm256_movemask_ps(_mm256_cmp_ps(_mm256_loadu_ps(d + j), limv, _CMP_LE_OQ));
    // no early exit on an empty mask: the branch mispredicts more than it saves
    const __m256i perm = _mm256_load_si256(reinterpret_cast<const __m256i*>(kPack.lanes[mask]));
    for (int a = 0; a < NF; ++a)
      _mm256_storeu_ps(fout[a] + c, _mm256_permutevar8x32_ps(_mm256_loadu_ps(fin[a] + j), perm));
    for (int a = 0; a < NI; ++a)
      _mm256_storeu_si256(reinterpret_cast<__m256i*>(iout[a] + c),
                          _mm256_permutevar8x32_epi32(
                              _mm256_loadu_si256(reinterpret_cast<const __m256i*>(iin[a] + j)), perm));
    c += __builtin_popcount(static_cast<unsigned>(mask));
  }
#endif
  for (; j < n; ++j) {
    for (int a = 0; a < NF; ++a) fout[a][c] = fin[a][j];
    for (int a = 0; a < NI; ++a) iout[a][c] = iin[a][j];
    c += d[j] <= lim;
  }
  return c;
}

// The source rows within a ball around a centre, copied out of the tree
// (SoA): the rows every query near the centre scans.
struct Group {
  float c[3] = {0, 0, 0};
  float radius = -1;  // < 0: empty
  std::vector<float> x, y, z, px, py, d;
  std::vector<int> at;  // tree index
  std::vector<int> iota;
  int size = 0;
  void reserve(size_t n) {
    n += 8;
    if (x.size() >= n) return;
    n *= 2;
    for (auto* v : {&x, &y, &z, &px, &py, &d}) v->resize(n);
    at.resize(n);
  }
};

// Fills g with every row within `radius` of q; returns the rows tested.
int gather(const Tree& t, const float* q, float radius, Group& g) {
  const float r2 = radius * radius * (1 + 8 * kSlack);
  const float box_r2 = r2 * (1 + 8 * kSlack);
  g.c[0] = q[0], g.c[1] = q[1], g.c[2] = q[2];
  g.radius = radius;
  g.size = 0;
  int stack[128];
  int top = 0, tested = 0;
  stack[top++] = 0;
  const float qx = q[0], qy = q[1], qz = q[2];
  while (top > 0) {
    const Node& n = t.nodes[stack[--top]];
    float lb = 0;
    for (int a = 0; a < 3; ++a) {
      const float e = std::max({0.0f, n.lo[a] - q[a], q[a] - n.hi[a]});
      lb += e * e;
    }
    if (lb > box_r2) continue;
    if (n.left >= 0) {
      stack[top++] = n.right;
      stack[top++] = n.left;
      continue;
    }
    const int b = n.begin, cnt = n.end - n.begin;
    tested += cnt;
    g.reserve(static_cast<size_t>(g.size + cnt));
    float* d = g.d.data() + g.size;  // scratch past the packed rows
    for (int i = 0; i < cnt; ++i) d[i] = sq3(t.xs[b + i], t.ys[b + i], t.zs[b + i], qx, qy, qz);
    const int s = g.size;
    g.size += pack<5, 1>(cnt, d, r2, {t.xs.data() + b, t.ys.data() + b, t.zs.data() + b, t.px.data() + b, t.py.data() + b},
                         {g.x.data() + s, g.y.data() + s, g.z.data() + s, g.px.data() + s, g.py.data() + s},
                         {t.at.data() + b}, {g.at.data() + s});
  }
  return tested;
}

// Per-thread scratch of one query.
struct Scratch {
  std::vector<float> d, im;  // per group row
  std::vector<float> sd, sim;  // collected: value and image distance
  std::vector<int> sat;        // collected: tree index
  void reserve(size_t n) {
    n += 8;
    if (d.size() >= n) return;
    n *= 2;
    for (auto* v : {&d, &im, &sd, &sim}) v->resize(n);
    sat.resize(n);
  }
};

// Collects the group's rows within squared distance r2 of q (value and image
// distances to `target`, tree indices); returns how many.
int scan(const Group& g, const float* q, float r2, cv::Point2f target, Scratch& s) {
  const int n = g.size;
  s.reserve(static_cast<size_t>(n));
  float* d = s.d.data();
  float* im = s.im.data();
  const float qx = q[0], qy = q[1], qz = q[2];
  const float* gx = g.x.data();
  const float* gy = g.y.data();
  const float* gz = g.z.data();
  for (int j = 0; j < n; ++j) d[j] = sq3(gx[j], gy[j], gz[j], qx, qy, qz);
  const float* px = g.px.data();
  const float* py = g.py.data();
  const float tx = target.x, ty = target.y;
  for (int j = 0; j < n; ++j) {
    const float dx = px[j] - tx, dy = py[j] - ty;
    im[j] = dx * dx + dy * dy;  // the faithful method's expression
  }
  return pack<2, 1>(n, d, r2, {d, im}, {s.sd.data(), s.sim.data()}, {g.at.data()}, {s.sat.data()});
}

// Among the kk nearest (distance, id) of the c collected, the index of the one
// with the smallest (image distance, distance, id). Walks the collected rows
// by image distance and takes the first whose (distance, id) ranks below kk.
// The collected arrays have room for 8 more entries (padding is written).
int select(const Tree& t, Scratch& s, int c, int kk) {
  float* sd = s.sd.data();
  float* sim = s.sim.data();
  const int* sat = s.sat.data();
  constexpr float inf = std::numeric_limits<float>::infinity();
  for (int j = c; j < c + 8; ++j) sd[j] = inf, sim[j] = inf;
  auto before = [&](int a, int b) {  // (distance, id) order
    return sd[a] < sd[b] || (sd[a] == sd[b] && t.ids[sat[a]] < t.ids[sat[b]]);
  };
  [[maybe_unused]] const int blocks = (c + 7) / 8;  // vectors of 8 (AVX2 paths)
  for (int round = 0; round < 16; ++round) {
    float v = inf;
#if defined(__AVX2__)
    {
      __m256 mv = _mm256_set1_ps(inf);
      for (int b = 0; b < blocks; ++b) mv = _mm256_min_ps(mv, _mm256_loadu_ps(sim + 8 * b));
      alignas(32) float lanes[8];
      _mm256_store_ps(lanes, mv);
      for (float x : lanes) v = std::min(v, x);
    }
#else
    for (int j = 0; j < c; ++j) v = std::min(v, sim[j]);
#endif
    if (v == inf) break;
    int best = -1;
#if defined(__AVX2__)
    {
      const __m256 vv = _mm256_set1_ps(v);
      for (int b = 0; b < blocks; ++b) {
        unsigned mask = static_cast<unsigned>(_mm256_movemask_ps(_mm256_cmp_ps(_mm256_loadu_ps(sim + 8 * b), vv, _CMP_EQ_OQ)));
        while (mask) {
          const int j = 8 * b + std::countr_zero(mask);
          mask &= mask - 1;
          if (best < 0 || before(j, best)) best = j;
        }
      }
    }
#else
    for (int j = 0; j < c; ++j)
      if (sim[j] == v && (best < 0 || before(j, best))) best = j;
#endif
    if (c == kk) return best;
    // rank of best in (distance, id) order
    const float db = sd[best];
    int rank = 0, ties = 0;
#if defined(__AVX2__)
    {
      const __m256 dbv = _mm256_set1_ps(db);
      for (int b = 0; b < blocks; ++b) {
        const __m256 x = _mm256_loadu_ps(sd + 8 * b);
        rank += std::popcount(static_cast<unsigned>(_mm256_movemask_ps(_mm256_cmp_ps(x, dbv, _CMP_LT_OQ))));
        ties += std::popcount(static_cast<unsigned>(_mm256_movemask_ps(_mm256_cmp_ps(x, dbv, _CMP_EQ_OQ))));
      }
    }
#else
    for (int j = 0; j < c; ++j) rank += sd[j] < db, ties += sd[j] == db;
#endif
    if (ties > 1) {
      const uint32_t ib = t.ids[sat[best]];
      for (int j = 0; j < c; ++j) rank += sd[j] == db && t.ids[sat[j]] < ib;
    }
    if (rank < kk) return best;
    // every other row at this image distance comes later: none is in the set
    for (int j = 0; j < c; ++j)
      if (sim[j] == v) sim[j] = inf;
  }
  // many near rows outside the set: find the set's bound and scan it
  std::vector<int> order(c);
  for (int j = 0; j < c; ++j) order[j] = j;
  std::nth_element(order.begin(), order.begin() + (kk - 1), order.end(), before);
  const int tau = order[kk - 1];
  int best = -1;
  for (int j = 0; j < c; ++j) {
    if (before(tau, j)) continue;
    if (sim[j] == inf) continue;  // taken out above: not in the set
    if (best < 0 || sim[j] < sim[best] || (sim[j] == sim[best] && before(j, best))) best = j;
  }
  return best;
}

}  // namespace

bool candidates3_applies(const Object& dst, const Object& src) {
  if (dst.channels != 3 || src.channels != 3 || dst.patch != 1 || src.patch != 1) return false;
  auto finite = [](const std::vector<float>& v) {
    return std::all_of(v.begin(), v.end(), [](float x) { return std::isfinite(x); });
  };
  return finite(src.flat) && finite(dst.flat);
}

Status choose_candidates3(const Object& dst, const Object& src, int k, const std::vector<cv::Point2f>& targets,
                          int threads, const Progress& progress, std::vector<int>& chosen,
                          std::vector<float>& chosen_sq, double* tested) {
  const int n = src.rows(), m = dst.rows();
  chosen.assign(m, -1);
  chosen_sq.assign(m, std::numeric_limits<float>::infinity());
  if (n == 0 || m == 0 || k <= 0) return {};
  const int kk = std::min(k, n);
  const float* sv = src.flat.data();
  const float* dv = dst.flat.data();

  // quantisation over the source's box
  Morton code;
  float lo[3], hi[3];
  for (int a = 0; a < 3; ++a) lo[a] = hi[a] = sv[a];
  for (int i = 0; i < n; ++i)
    for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], sv[3 * i + a]), hi[a] = std::max(hi[a], sv[3 * i + a]);
  float extent = 0;
  for (int a = 0; a < 3; ++a) {
    code.lo[a] = lo[a];
    code.scale[a] = hi[a] > lo[a] ? 255.0f / (hi[a] - lo[a]) : 0.0f;
    extent = std::max(extent, hi[a] - lo[a]);
  }

  // the tree over the source and the queries in Morton order, side by side
  Tree t;
  std::vector<uint64_t> queries(m);
  auto build_tree = [&] {
    std::vector<uint64_t> order(n);
    parallel_rows(n, threads, 8192, [&](int b, int e) {
      for (int i = b; i < e; ++i) order[i] = (static_cast<uint64_t>(code(sv + 3 * i)) << 32) | static_cast<uint32_t>(i);
    });
    sort_by_code(order);
    t.xs.resize(n), t.ys.resize(n), t.zs.resize(n), t.ids.resize(n), t.codes.resize(n);
    t.px.resize(n), t.py.resize(n), t.at.resize(n);
    parallel_rows(n, threads, 8192, [&](int b, int e) {
      for (int i = b; i < e; ++i) {
        const uint32_t id = static_cast<uint32_t>(order[i]);
        t.ids[i] = id;
        t.codes[i] = static_cast<uint32_t>(order[i] >> 32);
        t.xs[i] = sv[3 * id], t.ys[i] = sv[3 * id + 1], t.zs[i] = sv[3 * id + 2];
        t.px[i] = static_cast<float>(src.pixels[id].x), t.py[i] = static_cast<float>(src.pixels[id].y);
        t.at[i] = i;
      }
    });
    t.nodes.reserve(4 * (n / kLeaf + 1));
    t.build(0, n);
  };
  auto sort_queries = [&] {
    parallel_rows(m, threads, 8192, [&](int b, int e) {
      for (int i = b; i < e; ++i) queries[i] = (static_cast<uint64_t>(code(dv + 3 * i)) << 32) | static_cast<uint32_t>(i);
    });
    sort_by_code(queries);
  };
  parallel_rows(2, threads, 1, [&](int b, int e) {
    for (int i = b; i < e; ++i) i == 0 ? build_tree() : sort_queries();
  });
  // a first radius: K of n values spread over a surface of the box's size
  const float r_first = std::max(extent * std::sqrt(static_cast<float>(kk) / static_cast<float>(n)), 1e-6f);
  const float r_floor = std::max(extent * 1e-4f, 1e-7f);
  const int blocks = (m + kBlock - 1) / kBlock;
  std::atomic<bool> stop{false};
  std::atomic<long long> computed{0};
  parallel_rows(blocks, threads, 1, [&](int bb, int be) {
    Group g;
    Scratch sc;
    std::vector<char> done;
    long long local = 0;
    for (int blk = bb; blk < be && !stop; ++blk) {
      if (progress.cancelled()) {
        stop = true;
        break;
      }
      const int qb = blk * kBlock, qe = std::min(m, qb + kBlock);
      g.radius = -1;  // each block starts afresh: results do not depend on the split
      float r_est = r_first;
      done.assign(static_cast<size_t>(qe - qb), 0);
      // one query: returns whether it gathered a new group
      auto run = [&](int qi) {
        bool regathered = false;
        const int d = static_cast<int>(static_cast<uint32_t>(queries[qi]));
        const float* q = dv + 3 * d;
        float r = std::max(r_est * kGuess, r_floor);
        int c;
        for (;;) {
          // the group must hold the whole ball of radius r around q
          float dqc = 0;
          if (g.radius >= 0) {
            const float dx = q[0] - g.c[0], dy = q[1] - g.c[1], dz = q[2] - g.c[2];
            dqc = std::sqrt(dx * dx + dy * dy + dz * dz);
          }
          // regather when the ball is not inside the group, or the group is much wider than needed
          if (g.radius < 0 || r * (1 + 8 * kSlack) > (g.radius - dqc) * (1 - 8 * kSlack) ||
              g.radius > kWaste * kReach * r) {
            regathered = true;
            local += gather(t, q, r * kReach, g);
          }
          local += g.size;
          c = scan(g, q, r * r, targets[d], sc);
          if (c >= kk) break;
          const float grow = c > 0 ? std::sqrt(static_cast<float>(kk) / static_cast<float>(c)) * 1.1f : 2.0f;
          r = std::max(r * std::clamp(grow, 1.25f, 4.0f), r_floor);
          if (!std::isfinite(r * r * kReach * kReach)) r = std::numeric_limits<float>::infinity();
        }
        const int j = select(t, sc, c, kk);
        chosen[d] = static_cast<int>(t.ids[sc.sat[j]]);
        chosen_sq[d] = sc.sd[j];
        // the K-th distance, estimated from the count (values on a surface: count ~ r^2)
        r_est = r * std::sqrt(static_cast<float>(kk) / static_cast<float>(c));
        done[qi - qb] = 1;
        return regathered;
      };
      for (int qi = qb; qi < qe; ++qi) {
        if (done[qi - qb]) continue;
        if (!run(qi)) continue;
        // a new group: serve the queries a little ahead that fall well inside it
        const int ahead = std::min(qe, qi + kAhead);
        for (int qj = qi + 1; qj < ahead; ++qj) {
          if (done[qj - qb]) continue;
          const float* q = dv + 3 * static_cast<uint32_t>(queries[qj]);
          const float dx = q[0] - g.c[0], dy = q[1] - g.c[1], dz = q[2] - g.c[2];
          const float need = std::max(r_est * kGuess, r_floor) * (1 + 8 * kSlack);
          if (need + std::sqrt(dx * dx + dy * dy + dz * dz) < g.radius * (1 - 8 * kSlack)) run(qj);
        }
      }
    }
    computed += local;
  });
  if (stop) return make_error("cancelled during candidate lists");
  if (tested) *tested = static_cast<double>(computed.load()) / m;
  return {};
}

}  // namespace veneer::match::fast
