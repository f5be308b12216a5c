// compute_map: the faithful thesis methods (ch. 4) and the dispatch to the
// fast engine.
#include "veneer/match/matcher.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <deque>
#include <limits>
#include <random>

#include <opencv2/imgproc.hpp>

#include "internal.hpp"
#include "veneer/match/fast.hpp"
#include "veneer/match/features.hpp"
#include "veneer/match/index.hpp"
#include "veneer/util/log.hpp"

namespace veneer::match {
namespace {

using detail::empty_map;
using detail::parallel_chunks;
using detail::set_match;

constexpr float kInf = std::numeric_limits<float>::infinity();

// Direct matching: every destination row to its nearest source row with the
// exact index, in parallel. `ids`/`sq` get one entry per destination row.
Status direct_exact(const FeatureSet& dst, const FeatureSet& src, const MatchOptions& o, const Progress& progress,
                    double from, double to, std::vector<int>& ids, std::vector<float>& sq) {
  ids.assign(dst.rows(), -1);
  sq.assign(dst.rows(), kInf);
  return parallel_chunks(dst.rows(), o.threads, progress, "linear search", from, to, [&](int b, int e) {
    for (int d = b; d < e; ++d) detail::exact_knn(src.data.data(), src.rows(), src.dims, dst.row(d), 1, &ids[d], &sq[d]);
  });
}

Expected<Map> run_linear(const FeatureSet& dst, const FeatureSet& src, const MatchOptions& o, const Progress& p) {
  std::vector<int> ids;
  std::vector<float> sq;
  if (auto s = direct_exact(dst, src, o, p, 0.0, 1.0, ids, sq); !s) return s.error();
  Map map = empty_map(dst.size);
  for (int d = 0; d < dst.rows(); ++d)
    if (ids[d] >= 0) set_match(map, dst, src, d, ids[d], sq[d]);
  return map;
}

// The thesis's FLANN search, single-threaded as it ran there.
Expected<Map> run_flann(const FeatureSet& dst, const FeatureSet& src, const MatchOptions& o, const Progress& p) {
  auto index = make_index("flann");
  p.report(0.0, "flann index");
  index->build(src.data.data(), src.rows(), src.dims);
  Map map = empty_map(dst.size);
  for (int d = 0; d < dst.rows(); ++d) {
    if ((d & 1023) == 0) {
      if (p.cancelled()) return detail::cancelled_error("flann search");
      p.report(static_cast<double>(d) / dst.rows(), "flann search");
    }
    int id = -1;
    float sq = kInf;
    index->knn(dst.row(d), 1, &id, &sq);
    if (id >= 0) set_match(map, dst, src, d, id, sq);
  }
  return map;
}

// Where a destination pixel lands in the source when the destination's
// bounding box is stretched onto the source's (thesis eq. 4.2).
struct BoxMapping {
  cv::Rect d, s;
  cv::Point2f operator()(cv::Point p) const {
    const float sx = static_cast<float>(s.width) / static_cast<float>(d.width);
    const float sy = static_cast<float>(s.height) / static_cast<float>(d.height);
    return {s.x + (p.x - d.x + 0.5f) * sx - 0.5f, s.y + (p.y - d.y + 0.5f) * sy - 0.5f};
  }
};

// Candidate lists (thesis eq. 4.2): the K nearest by feature, then the one
// nearest in the image to where the destination pixel lands in the source's
// bounding box. The lists come from the exact search, so K = 1 is exactly
// direct matching and the method's own effect is measured without FLANN's.
Expected<Map> run_candidates(const FeatureSet& dst, const FeatureSet& src, const MatchOptions& o,
                             const Progress& p) {
  const int k = o.candidates;
  const BoxMapping box{dst.bbox, src.bbox};
  std::vector<int> chosen(dst.rows(), -1);
  std::vector<float> chosen_sq(dst.rows(), kInf);
  auto s = parallel_chunks(dst.rows(), o.threads, p, "candidate lists", 0.0, 1.0, [&](int b, int e) {
    std::vector<int> ids(k);
    std::vector<float> sq(k);
    for (int d = b; d < e; ++d) {
      detail::exact_knn(src.data.data(), src.rows(), src.dims, dst.row(d), k, ids.data(), sq.data());
      const cv::Point2f target = box(dst.pixels[d]);
      float best = kInf;
      for (int j = 0; j < k && ids[j] >= 0; ++j) {
        const cv::Point q = src.pixels[ids[j]];
        const float dx = q.x - target.x, dy = q.y - target.y;
        const float image_d = dx * dx + dy * dy;
        if (image_d < best) best = image_d, chosen[d] = ids[j], chosen_sq[d] = sq[j];
      }
    }
  });
  if (!s) return s.error();
  Map map = empty_map(dst.size);
  for (int d = 0; d < dst.rows(); ++d)
    if (chosen[d] >= 0) set_match(map, dst, src, d, chosen[d], chosen_sq[d]);
  return map;
}

Expected<Map> run_patchmatch(const FeatureSet& dst, const FeatureSet& src, const MatchOptions& o,
                             const Progress& p) {
  std::mt19937 rng(o.seed);
  std::uniform_int_distribution<int> pick(0, src.rows() - 1);
  const int n = dst.rows();
  std::vector<int> match(n);
  std::vector<float> sq(n);
  // Random init over the source's object pixels only: never object-background.
  for (int d = 0; d < n; ++d) {
    match[d] = pick(rng);
    sq[d] = squared_distance(dst.row(d), src.row(match[d]), dst.dims);
  }
  // Background (or outside the image) costs the maximal distance.
  auto cost = [&](int d, int x, int y, int& row) {
    row = src.row_at(x, y);
    return row < 0 ? kInf : squared_distance(dst.row(d), src.row(row), dst.dims);
  };
  auto try_candidate = [&](int d, int x, int y) {
    int row;
    const float c = cost(d, x, y, row);
    if (c < sq[d]) sq[d] = c, match[d] = row;
  };
  const int max_radius = std::max(src.size.width, src.size.height);
  for (int it = 0; it < o.iterations; ++it) {
    const bool forward = it % 2 == 0;  // alternate the scan direction per iteration
    const int step = forward ? 1 : -1;
    for (int i = 0; i < n; ++i) {
      if ((i & 4095) == 0) {
        if (p.cancelled()) return detail::cancelled_error("patchmatch");
        p.report((it + static_cast<double>(i) / n) / o.iterations, "patchmatch");
      }
      const int d = forward ? i : n - 1 - i;
      const cv::Point pt = dst.pixels[d];
      // propagation from the neighbours already visited in this scan
      for (const cv::Point off : {cv::Point(-step, 0), cv::Point(0, -step)}) {
        const int nb = dst.row_at(pt.x + off.x, pt.y + off.y);
        if (nb < 0) continue;
        const cv::Point m = src.pixels[match[nb]];
        try_candidate(d, m.x - off.x, m.y - off.y);
      }
      // random search in windows halving around the current best
      const cv::Point best = src.pixels[match[d]];
      for (int r = max_radius; r >= 1; r /= 2) {
        std::uniform_int_distribution<int> off(-r, r);
        const int x = best.x + off(rng), y = best.y + off(rng);
        try_candidate(d, x, y);
      }
    }
  }
  Map map = empty_map(dst.size);
  for (int d = 0; d < n; ++d) set_match(map, dst, src, d, match[d], sq[d]);
  return map;
}

// Region growing (thesis sec. 4.2.2). Seeds are matched directly; from a
// matched pixel p -> p' a 4-neighbour q is offered q' = p' + (q - p) and takes
// it when all three constraints hold strictly under the threshold T (RMS
// feature distances, the map's scale):
//   1. the match is nearly as good as q's direct match:  D(q, q') - D(q, direct(q)) < T
//   2. smooth in the destination:                         D(F_dst(q), F_dst(p)) < T
//   3. smooth in the source:                              D(F_src(q'), F_src(p')) < T
// and q is empty or its current match is worse. A pixel the growth never
// reaches becomes the next seed (scan order). With T = 0 nothing grows (no
// match beats the direct one by a negative margin), so the result is direct
// matching.
// squared_distance summed as products then additions, never fused into
// multiply-adds (which -mfma lets the compiler do): as the fast engine's
// region growing sums (fast/object.cpp, patch_sq_ordered_pairs), so that the
// chained growth decisions of the two agree to the bit
// (tests/core/match/test_region_grow_twins.cpp).
#if defined(__clang__)
float unfused_squared_distance(const float* a, const float* b, int dims) {
#pragma clang fp contract(off)
#else
__attribute__((optimize("fp-contract=off"))) float unfused_squared_distance(const float* a, const float* b, int dims) {
#endif
  float s = 0;
  for (int i = 0; i < dims; ++i) {
    const float d = a[i] - b[i];
    s += d * d;
  }
  return s;
}

Expected<Map> run_regiongrow(const FeatureSet& dst, const FeatureSet& src, const MatchOptions& o,
                             const Progress& p) {
  std::vector<int> direct;
  std::vector<float> direct_sq;
  if (auto s = direct_exact(dst, src, o, p, 0.0, 0.8, direct, direct_sq); !s) return s.error();
  const int n = dst.rows();
  const float t = static_cast<float>(o.threshold);
  const int dims = dst.dims;
  auto rms = [&](float sq) { return map_distance(sq, dst.patch); };
  std::vector<int> match(n, -1);
  std::vector<float> sq(n, kInf);
  std::deque<int> queue;
  const cv::Point offsets[4] = {{1, 0}, {-1, 0}, {0, 1}, {0, -1}};
  for (int seed = 0; seed < n; ++seed) {
    if (match[seed] >= 0) continue;
    if ((seed & 1023) == 0) {
      if (p.cancelled()) return detail::cancelled_error("region growing");
      p.report(0.8 + 0.2 * seed / n, "region growing");
    }
    match[seed] = direct[seed];
    sq[seed] = direct_sq[seed];
    if (t <= 0) continue;
    queue.push_back(seed);
    while (!queue.empty()) {
      const int d = queue.front();
      queue.pop_front();
      const cv::Point pt = dst.pixels[d];
      const cv::Point m = src.pixels[match[d]];
      for (const cv::Point off : offsets) {
        const int q = dst.row_at(pt.x + off.x, pt.y + off.y);
        if (q < 0) continue;
        const int qs = src.row_at(m.x + off.x, m.y + off.y);
        if (qs < 0) continue;
        const float data = unfused_squared_distance(dst.row(q), src.row(qs), dims);
        if (!(data < sq[q])) continue;  // only a smaller distance overwrites
        if (!(rms(data) - rms(direct_sq[q]) < t)) continue;
        if (!(rms(unfused_squared_distance(dst.row(q), dst.row(d), dims)) < t)) continue;
        if (!(rms(unfused_squared_distance(src.row(qs), src.row(match[d]), dims)) < t)) continue;
        match[q] = qs;
        sq[q] = data;
        queue.push_back(q);
      }
    }
  }
  Map map = empty_map(dst.size);
  for (int d = 0; d < n; ++d) set_match(map, dst, src, d, match[d], sq[d]);
  return map;
}

// The thesis's comparison: the source's bounding box stretched onto the
// destination's. A pixel that lands on the source's background takes the
// nearest source object pixel, so nothing is mapped into the background.
Expected<Map> run_baseline(const FeatureSet& dst, const FeatureSet& src) {
  cv::Mat background(src.size, CV_8UC1);
  for (int y = 0; y < src.size.height; ++y)
    for (int x = 0; x < src.size.width; ++x) background.at<uchar>(y, x) = src.row_of.at<int>(y, x) < 0 ? 255 : 0;
  cv::Mat dist, labels;
  cv::distanceTransform(background, dist, labels, cv::DIST_L2, cv::DIST_MASK_5, cv::DIST_LABEL_PIXEL);
  std::vector<int> label_row(src.rows() + 1, -1);
  for (int s = 0; s < src.rows(); ++s) {
    const cv::Point q = src.pixels[s];
    label_row[labels.at<int>(q.y, q.x)] = s;
  }
  const BoxMapping box{dst.bbox, src.bbox};
  Map map = empty_map(dst.size);
  for (int d = 0; d < dst.rows(); ++d) {
    const cv::Point2f f = box(dst.pixels[d]);
    const int x = std::clamp(static_cast<int>(std::lround(f.x)), 0, src.size.width - 1);
    const int y = std::clamp(static_cast<int>(std::lround(f.y)), 0, src.size.height - 1);
    int s = src.row_at(x, y);
    if (s < 0) {
      const int label = labels.at<int>(y, x);
      s = label >= 0 && label < static_cast<int>(label_row.size()) ? label_row[label] : -1;
    }
    if (s >= 0) set_match(map, dst, src, d, s, squared_distance(dst.row(d), src.row(s), dst.dims));
  }
  return map;
}

}  // namespace

Expected<Map> compute_map(const ObjectView& destination, const ObjectView& source, const MatchOptions& options,
                          const Progress& progress) {
  if (auto s = options.check(); !s) return s.error();
  if (auto s = check_pair(destination, source, options.feature); !s) return s.error();
  // The fast engine serves what it supports (and `coherent`, which only it has).
  if (options.method == Method::coherent || options.method == Method::combined ||
      (options.fast && fast::supports(options)))
    return fast::compute_map(destination, source, options, progress);
  const auto t0 = std::chrono::steady_clock::now();
  auto dst = make_features(destination, options.feature, options.patch);
  if (!dst) return make_error("destination: " + dst.message());
  auto src = make_features(source, options.feature, options.patch);
  if (!src) return make_error("source: " + src.message());
  Expected<Map> map = make_error("unreachable");
  switch (options.method) {
    case Method::linear: map = run_linear(*dst, *src, options, progress); break;
    case Method::flann: map = run_flann(*dst, *src, options, progress); break;
    case Method::candidates: map = run_candidates(*dst, *src, options, progress); break;
    case Method::patchmatch: map = run_patchmatch(*dst, *src, options, progress); break;
    case Method::regiongrow: map = run_regiongrow(*dst, *src, options, progress); break;
    case Method::baseline: map = run_baseline(*dst, *src); break;
    case Method::coherent:
    case Method::combined: break;
  }
  if (map) {
    progress.report(1.0, "done");
    VLOG_DEBUG("Match", "{} {} {}x{}: {} -> {} pixels in {:.3f} s", method_name(options.method),
               feature_name(options.feature), options.patch, options.patch, dst->rows(), src->rows(),
               std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  }
  return map;
}

}  // namespace veneer::match
