// core/RegionGrowTwins.*: region growing is written twice, on purpose: the
// faithful thesis method (match/matcher.cpp, brute-force direct matches) and
// the fast engine's (match/fast/engine.cpp, nearest search over the fast
// layout, neighbour distances precomputed on all cores). Growth decisions
// chain, so the two only stay twins if every distance agrees bit for bit;
// these tests pin them to the same maps on simulated thesis pairs (rendered
// by the simulator, as the quality table does) at several thresholds, so that
// a change to either one alone fails here.
#include <gtest/gtest.h>

#include <cstring>
#include <string>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/eval/table.hpp"
#include "veneer/match/matcher.hpp"

namespace veneer::match {
namespace {

struct Pair {
  ObjectView dst, src;
  std::string name;
};

// Three thesis pairs at 256x170 (each object ~1,500 px): a textured
// destination on a smooth source, two different shapes, and one object
// against its own moved, smaller second capture. Noise as `veneer simulate`.
const std::vector<Pair>& pairs() {
  static const std::vector<Pair> all = [] {
    eval::TableOptions o;
    o.size = {256, 170};
    o.truth_normals = true;  // normals are not what is tested: the truth's keep the run short
    std::vector<Pair> v;
    for (const auto& [d, s] : std::vector<std::pair<std::string, std::string>>{
             {"bull", "orange"}, {"cup-white", "cup-dots"}, {"blocks", "blocks"}}) {
      auto dst = eval::table_object(d, false, o);
      auto src = eval::table_object(s, d == s, o);
      EXPECT_TRUE(dst.ok() && src.ok()) << d << " -> " << s;
      if (!dst.ok() || !src.ok()) continue;
      v.push_back({dst->view, src->view, d + " -> " + s});
    }
    return v;
  }();
  return all;
}

Map grow(const Pair& p, Feature feature, int patch, double threshold, bool fast, int threads) {
  MatchOptions o;
  o.method = Method::regiongrow;
  o.feature = feature;
  o.patch = patch;
  o.threshold = threshold;
  o.fast = fast;
  o.threads = threads;
  auto m = compute_map(p.dst, p.src, o);
  EXPECT_TRUE(m.ok()) << (m.ok() ? "" : m.message());
  return m.ok() ? *m : Map{};
}

// Pixels where the maps' source positions differ.
int moved(const Map& a, const Map& b) {
  int n = 0;
  for (int y = 0; y < a.xy.rows; ++y)
    for (int x = 0; x < a.xy.cols; ++x) n += a.xy.at<cv::Vec2f>(y, x) != b.xy.at<cv::Vec2f>(y, x);
  return n;
}

// Pixels where the two maps differ (source position or distance, bit for bit).
int differing(const Map& a, const Map& b) {
  if (a.xy.size() != b.xy.size() || a.xy.empty()) return -1;
  int n = 0;
  for (int y = 0; y < a.xy.rows; ++y)
    for (int x = 0; x < a.xy.cols; ++x)
      n += a.xy.at<cv::Vec2f>(y, x) != b.xy.at<cv::Vec2f>(y, x) ||
           std::memcmp(&a.distance.at<float>(y, x), &b.distance.at<float>(y, x), sizeof(float)) != 0;
  return n;
}

// One pixel per neighbour (1x1 patches): both engines find the exact nearest
// seeds (ties to the lower source row), so the maps must be identical, pixel
// for pixel and distance for distance, at every threshold, on normals and on
// intensities, whatever the fast engine's thread count.
TEST(RegionGrowTwins, SameMapsOnOnePixelPatches) {
  ASSERT_EQ(pairs().size(), 3u);
  for (const Pair& p : pairs()) {
    for (Feature f : {Feature::normals, Feature::intensities}) {
      const Map direct = grow(p, f, 1, 0.0, false, 1);
      for (double t : {0.0, 0.02, 0.05, 0.1}) {
        SCOPED_TRACE(p.name + ", " + feature_name(f) + ", threshold " + std::to_string(t));
        const Map faithful = t == 0.0 ? direct : grow(p, f, 1, t, false, 1);
        EXPECT_EQ(differing(grow(p, f, 1, t, true, 1), faithful), 0);
        EXPECT_EQ(differing(grow(p, f, 1, t, true, 0), faithful), 0);
        if (t >= 0.05) {
          // pixels taken from a neighbour, not their direct match: the
          // threshold grew regions, so more than direct matching was compared
          EXPECT_GT(moved(faithful, direct), 0) << "the threshold grew nothing";
        }
      }
    }
  }
}

// 3x3 patches on normals: the distances the growth compares are summed in
// element order by both (engine.cpp: patch_sq_ordered), so here too the maps
// must be the same.
TEST(RegionGrowTwins, SameMapsOnPatches) {
  ASSERT_EQ(pairs().size(), 3u);
  for (const Pair& p : pairs()) {
    for (double t : {0.0, 0.05}) {
      SCOPED_TRACE(p.name + ", threshold " + std::to_string(t));
      EXPECT_EQ(differing(grow(p, Feature::normals, 3, t, true, 0), grow(p, Feature::normals, 3, t, false, 1)), 0);
    }
  }
}

}  // namespace
}  // namespace veneer::match
