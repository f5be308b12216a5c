// Candidate lists (candidates.hpp) without sorted K-nearest lists.
//
// The choice only needs the *set* of the K nearest source rows, not its order:
// with tau the K-th smallest (distance, id) pair, the answer is the minimum of
// (image distance, value distance, id) over the pairs <= tau. So each query
// collects every source row whose value distance is within a radius R (a ball
// query in a bounding-box tree over the source values), takes the K-th pair
// of what it collected with nth_element, and scans those K for the image
// distance. That is exact whenever at least K rows were collected: every row
// not collected is farther than R, hence than each of the K taken. Otherwise
// R grows and the query is repeated; R only decides the speed.
//
// R comes from the previous query: if the previous query's K-th distance was
// r and the two queries are delta apart, the previous K rows all lie within
// r + delta of this one (triangle inequality), so R = r + delta holds at
// least K rows (slack covers float rounding). Queries run in Morton order of
// their values, so delta is small and a query collects little more than K.
//
// The tree: source rows sorted by the Morton code of their quantised values
// (10 bits per axis), split where the code's highest differing bit flips (an
// octree in binary form), leaves of at most kLeaf rows, values stored SoA in
// tree order with tight boxes per node. Distances are computed in the order of
// features.hpp's squared_distance(), so they are bit-identical to the faithful
// method's and ties break alike.
//
// Work is split into fixed blocks of the sorted queries (each starts with its
// own radius estimate), so the result does not depend on the thread count.
#include "candidates.hpp"

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <chrono>
#include <cstdio>
#include <cstdlib>

namespace veneer::match::fast {

namespace {

constexpr int kLeaf = 24;        // rows per tree leaf at most
constexpr int kBlock = 1024;     // sorted queries per work block
constexpr float kSlack = 1e-5f;  // relative margin on radii (float rounding)

uint32_t spread10(uint32_t v) {
  v &= 0x3ffu;
  v = (v | (v << 16)) & 0x030000ffu;
  v = (v | (v << 8)) & 0x0300f00fu;
  v = (v | (v << 4)) & 0x030c30c3u;
  v = (v | (v << 2)) & 0x09249249u;
  return v;
}

// Quantises 3-D values onto a 1024^3 lattice over the source's box (values
// outside are clamped: the code only orders work, it never decides results).
struct Morton {
  float lo[3] = {0, 0, 0}, scale[3] = {0, 0, 0};
  uint32_t operator()(const float* p) const {
    uint32_t c = 0;
    for (int a = 0; a < 3; ++a) {
      const float t = std::clamp((p[a] - lo[a]) * scale[a], 0.0f, 1023.0f);
      c |= spread10(static_cast<uint32_t>(t)) << a;
    }
    return c;
  }
};

// Stable LSD radix sort of (code << 32 | index) pairs by their 30-bit code.
void sort_by_code(std::vector<uint64_t>& a) {
  std::vector<uint64_t> tmp(a.size());
  for (int shift = 32; shift < 62; shift += 10) {
    uint32_t count[1025] = {};
    for (uint64_t v : a) ++count[((v >> shift) & 1023u) + 1];
    for (int i = 0; i < 1024; ++i) count[i + 1] += count[i];
    for (uint64_t v : a) tmp[count[(v >> shift) & 1023u]++] = v;
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

// Same arithmetic, in the same order, as squared_distance() of features.hpp
// (source value minus query value, summed from 0).
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

inline uint64_t key_of(float d, uint32_t id) {
  uint32_t bits;
  std::memcpy(&bits, &d, sizeof bits);
  return (static_cast<uint64_t>(bits) << 32) | id;
}
inline float dist_of(uint64_t key) {
  const uint32_t bits = static_cast<uint32_t>(key >> 32);
  float d;
  std::memcpy(&d, &bits, sizeof d);
  return d;
}

// Appends the keys of every row within squared distance r2 of q to buf;
// returns the number of distances computed.
int ball(const Tree& t, const float* q, float r2, std::vector<uint64_t>& buf) {
  const float box_r2 = r2 * (1 + 4 * kSlack);
  int stack[128];
  int top = 0, tested = 0;
  stack[top++] = 0;
  const float qx = q[0], qy = q[1], qz = q[2];
  while (top > 0) {
    const Node& n = t.nodes[stack[--top]];
    float lb = 0;
    for (int a = 0; a < 3; ++a) {
      const float g = std::max({0.0f, n.lo[a] - q[a], q[a] - n.hi[a]});
      lb += g * g;
    }
    if (lb > box_r2) continue;
    if (n.left >= 0) {
      stack[top++] = n.right;
      stack[top++] = n.left;
      continue;
    }
    const int cnt = n.end - n.begin;
    tested += cnt;
    size_t at = buf.size();
    buf.resize(at + cnt);
    uint64_t* out = buf.data();
    for (int i = n.begin; i < n.end; ++i) {
      const float d = sq3(t.xs[i], t.ys[i], t.zs[i], qx, qy, qz);
      out[at] = key_of(d, t.ids[i]);
      at += d <= r2;
    }
    buf.resize(at);
  }
  return tested;
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

  using PClock = std::chrono::steady_clock;
  const bool prof = std::getenv("VENEER_CAND_PROFILE") != nullptr;
  auto pt0 = PClock::now();
  auto lap = [&](const char* what) {
    if (!prof) return;
    const auto now = PClock::now();
    std::fprintf(stderr, "  %s %.2f ms\n", what, std::chrono::duration<double, std::milli>(now - pt0).count());
    pt0 = now;
  };
  std::atomic<long long> retries{0}, collected{0};
  // quantisation over the source's box
  Morton code;
  float lo[3], hi[3];
  for (int a = 0; a < 3; ++a) lo[a] = hi[a] = sv[a];
  for (int i = 0; i < n; ++i)
    for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], sv[3 * i + a]), hi[a] = std::max(hi[a], sv[3 * i + a]);
  float extent = 0;
  for (int a = 0; a < 3; ++a) {
    code.lo[a] = lo[a];
    code.scale[a] = hi[a] > lo[a] ? 1023.0f / (hi[a] - lo[a]) : 0.0f;
    extent = std::max(extent, hi[a] - lo[a]);
  }

  Tree t;
  {
    std::vector<uint64_t> order(n);
    parallel_rows(n, threads, 8192, [&](int b, int e) {
      for (int i = b; i < e; ++i) order[i] = (static_cast<uint64_t>(code(sv + 3 * i)) << 32) | static_cast<uint32_t>(i);
    });
    sort_by_code(order);
    t.xs.resize(n), t.ys.resize(n), t.zs.resize(n), t.ids.resize(n), t.codes.resize(n);
    for (int i = 0; i < n; ++i) {
      const uint32_t id = static_cast<uint32_t>(order[i]);
      t.ids[i] = id;
      t.codes[i] = static_cast<uint32_t>(order[i] >> 32);
      t.xs[i] = sv[3 * id], t.ys[i] = sv[3 * id + 1], t.zs[i] = sv[3 * id + 2];
    }
    t.nodes.reserve(4 * (n / kLeaf + 1));
    t.build(0, n);
  }

  lap("tree");
  // queries in Morton order
  std::vector<uint64_t> queries(m);
  parallel_rows(m, threads, 8192, [&](int b, int e) {
    for (int i = b; i < e; ++i) queries[i] = (static_cast<uint64_t>(code(dv + 3 * i)) << 32) | static_cast<uint32_t>(i);
  });
  sort_by_code(queries);

  lap("query sort");
  // a first radius: K of n values spread over a surface of the box's size
  const float r_first = std::max(extent * std::sqrt(static_cast<float>(kk) / static_cast<float>(n)), 1e-6f);
  const float r_floor = std::max(extent * 1e-4f, 1e-7f);
  const int blocks = (m + kBlock - 1) / kBlock;
  std::atomic<bool> stop{false};
  std::atomic<long long> computed{0};
  parallel_rows(blocks, threads, 1, [&](int bb, int be) {
    std::vector<uint64_t> buf;
    buf.reserve(4096);
    long long local = 0;
    for (int blk = bb; blk < be && !stop; ++blk) {
      if (progress.cancelled()) {
        stop = true;
        break;
      }
      const int qb = blk * kBlock, qe = std::min(m, qb + kBlock);
      float prev_r = -1;  // previous query's K-th distance (not squared); < 0: none yet
      const float* prev_q = nullptr;
      for (int qi = qb; qi < qe; ++qi) {
        const int d = static_cast<int>(static_cast<uint32_t>(queries[qi]));
        const float* q = dv + 3 * d;
        float r;
        if (prev_r < 0) {
          r = r_first;
        } else {
          const float dx = q[0] - prev_q[0], dy = q[1] - prev_q[1], dz = q[2] - prev_q[2];
          const float delta = std::sqrt(dx * dx + dy * dy + dz * dz);
          // a far jump: guess the local radius is alike and grow if not
          r = prev_r + std::min(delta, std::max(prev_r, r_floor));
          r = r * (1 + kSlack) + 1e-12f;
        }
        for (;;) {
          buf.clear();
          local += ball(t, q, r * r, buf);
          if (static_cast<int>(buf.size()) >= kk) break;
          ++retries;
          r = std::max(2 * r, r_floor);
          if (!std::isfinite(r * r)) r = std::numeric_limits<float>::infinity();
        }
        collected += static_cast<long long>(buf.size());
        std::nth_element(buf.begin(), buf.begin() + (kk - 1), buf.end());
        // buf[0, kk) is the K set; choose by image distance, ties to the smaller key
        const cv::Point2f target = targets[d];
        float best = std::numeric_limits<float>::infinity();
        uint64_t best_key = std::numeric_limits<uint64_t>::max();
        for (int j = 0; j < kk; ++j) {
          const uint64_t key = buf[j];
          const cv::Point p = src.pixels[static_cast<uint32_t>(key)];
          const float dx = p.x - target.x, dy = p.y - target.y;
          const float image_d = dx * dx + dy * dy;
          if (image_d < best || (image_d == best && key < best_key)) best = image_d, best_key = key;
        }
        chosen[d] = static_cast<int>(static_cast<uint32_t>(best_key));
        chosen_sq[d] = dist_of(best_key);
        prev_r = std::sqrt(dist_of(buf[kk - 1]));
        prev_q = q;
      }
    }
    computed += local;
  });
  lap("queries");
  if (prof) std::fprintf(stderr, "  n=%d m=%d tested/q=%.1f collected/q=%.1f retries=%lld nodes=%zu\n", n, m,
                         double(computed.load()) / m, double(collected.load()) / m, retries.load(), t.nodes.size());
  if (stop) return make_error("cancelled during candidate lists");
  if (tested) *tested = static_cast<double>(computed.load()) / m;
  return {};
}

}  // namespace veneer::match::fast
