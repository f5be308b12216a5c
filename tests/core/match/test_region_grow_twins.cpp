// core/RegionGrowTwins.*: region growing is written twice, on purpose: the
// faithful thesis method (match/matcher.cpp, brute-force direct matches) and
// the fast engine's (match/fast/engine.cpp, nearest search over the fast
// layout, neighbour distances precomputed on all cores). Growth decisions
// chain, so the two only stay twins if every distance agrees bit for bit;
// these tests pin them to the same maps on simulated thesis pairs (rendered
// by the simulator, as the quality table does) at several thresholds, so that
// a change to either one alone fails here. (When first written they found the
// twins apart on up to 351 pixels of ~2,000: under -mfma the compiler fused
// matcher.cpp's growth sums, s += d * d, into fused multiply-adds the fast
// engine does not make; they are summed unfused now.)
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
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

// The sanitizer build (make asan) instruments and inlines differently, and
// GCC then fuses other multiply-adds than in the product's build, so a few
// growth decisions tip the other way and cascade (11-109 of ~2,000 pixels
// measured): there the twins must agree on all but 10 % of the pixels; in
// the product's build (what make test runs), to the bit.
#if defined(__SANITIZE_ADDRESS__)
constexpr double kAllowedDiffering = 0.10;
#else
constexpr double kAllowedDiffering = 0.0;
#endif

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
        EXPECT_LE(differing(grow(p, f, 1, t, true, 1), faithful), kAllowedDiffering * faithful.xy.total());
        EXPECT_LE(differing(grow(p, f, 1, t, true, 0), faithful), kAllowedDiffering * faithful.xy.total());
        if (t >= 0.05) {
          // pixels taken from a neighbour, not their direct match: the
          // threshold grew regions, so more than direct matching was compared
          EXPECT_GT(moved(faithful, direct), 0) << "the threshold grew nothing";
        }
      }
    }
  }
}

// Largest relative difference of the maps' distances.
double max_relative_distance(const Map& a, const Map& b) {
  double worst = 0;
  for (int y = 0; y < a.distance.rows; ++y)
    for (int x = 0; x < a.distance.cols; ++x) {
      const double u = a.distance.at<float>(y, x), v = b.distance.at<float>(y, x);
      if (u != v) worst = std::max(worst, std::abs(u - v) / std::max(std::abs(u), std::abs(v)));
    }
  return worst;
}

// 3x3 patches of intensities (9 pixels x 7 lamps x 3 channels = 189 squared
// terms a distance): the fast engine's direct matches are exact there too, so
// every pixel must take the same source pixel. The distances may differ by
// rounding: the faithful direct matching (index.cpp's brute force) sums a
// patch's terms in another order than the fast engine. Each sum of n
// non-negative terms is within (n - 1) 2^-24 of the exact one, so the two
// within 2.2e-5 of each other, and the square root of the map's distance
// halves that: 1.2e-5 relative. No growth decision may fall on it here.
// (Patches of normals are not pinned: there the fast engine's direct matches
// come from its approximate patch search -- test_fast_engine.cpp states that
// tolerance -- and growth chains from different seeds.)
TEST(RegionGrowTwins, SameMapsOnPatchesOfIntensities) {
  ASSERT_EQ(pairs().size(), 3u);
  int grew = 0;
  for (const Pair& p : pairs()) {
    const Map direct = grow(p, Feature::intensities, 3, 0.0, false, 1);
    for (double t : {0.0, 0.05, 0.1}) {
      SCOPED_TRACE(p.name + ", threshold " + std::to_string(t));
      const Map faithful = t == 0.0 ? direct : grow(p, Feature::intensities, 3, t, false, 1);
      const Map fast = grow(p, Feature::intensities, 3, t, true, 0);
      EXPECT_EQ(moved(fast, faithful), 0);
      EXPECT_LE(max_relative_distance(fast, faithful), 1.2e-5);
      grew += moved(faithful, direct);
    }
  }
  EXPECT_GT(grew, 0) << "no threshold grew anything: only direct matching was compared";
}

}  // namespace
}  // namespace veneer::match
