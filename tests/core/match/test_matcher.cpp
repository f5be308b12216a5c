// Every faithful method against the exact oracle, on small synthetic objects.
#include <gtest/gtest.h>

#include <atomic>
#include <limits>

#include "scenes.hpp"
#include "veneer/match/features.hpp"
#include "veneer/match/index.hpp"
#include "veneer/match/matcher.hpp"

namespace veneer::match {
namespace {

using testing::ellipsoid;

MatchOptions faithful(Method m, Feature f = Feature::normals, int patch = 1) {
  MatchOptions o;
  o.method = m;
  o.feature = f;
  o.patch = patch;
  o.fast = false;
  return o;
}

Map run(const ObjectView& d, const ObjectView& s, const MatchOptions& o) {
  auto map = compute_map(d, s, o);
  EXPECT_TRUE(map.ok()) << (map.ok() ? "" : map.message());
  return map.ok() ? *map : Map{};
}

// Exact nearest distance of each destination pixel, computed here by a plain
// double loop independent of the library's search.
cv::Mat oracle_distance(const ObjectView& d, const ObjectView& s, Feature f, int patch) {
  auto fd = make_features(d, f, patch);
  auto fs = make_features(s, f, patch);
  cv::Mat out(d.mask.size(), CV_32F, cv::Scalar(-1));
  for (int i = 0; i < fd->rows(); ++i) {
    double best = std::numeric_limits<double>::infinity();
    for (int j = 0; j < fs->rows(); ++j) {
      double sq = 0;
      for (int k = 0; k < fd->dims; ++k) {
        const double diff = double(fd->row(i)[k]) - fs->row(j)[k];
        sq += diff * diff;
      }
      best = std::min(best, sq);
    }
    out.at<float>(fd->pixels[i]) = static_cast<float>(std::sqrt(best / (patch * patch)));
  }
  return out;
}

// Every destination object pixel is mapped onto a source object pixel, and
// nothing outside the destination object is mapped.
void expect_object_to_object(const Map& map, const ObjectView& d, const ObjectView& s) {
  int bad = 0, unmapped = 0;
  for (int y = 0; y < d.mask.rows; ++y) {
    for (int x = 0; x < d.mask.cols; ++x) {
      const cv::Vec2f m = map.xy.at<cv::Vec2f>(y, x);
      if (!d.mask.at<uchar>(y, x)) {
        if (m[0] != -1 || m[1] != -1) ++bad;
        continue;
      }
      if (m[0] < 0) {
        ++unmapped;
        continue;
      }
      const int sx = static_cast<int>(m[0]), sy = static_cast<int>(m[1]);
      if (sx != m[0] || sy != m[1] || sx >= s.mask.cols || sy >= s.mask.rows || !s.mask.at<uchar>(sy, sx)) ++bad;
    }
  }
  EXPECT_EQ(bad, 0);
  EXPECT_EQ(unmapped, 0);
}

double mean_distance(const Map& map, const cv::Mat& mask) { return cv::mean(map.distance, mask)[0]; }

int differing_pixels(const Map& a, const Map& b) {
  cv::Mat diff;
  cv::absdiff(a.xy.reshape(1), b.xy.reshape(1), diff);
  return cv::countNonZero(diff);
}

struct Pair {
  ObjectView dst = ellipsoid({64, 48}, {30.f, 24.f}, 22.f, 17.f, 7, 1);
  ObjectView src = ellipsoid({56, 52}, {28.f, 27.f}, 19.f, 21.f, 7, 5);
};

TEST(Matcher, LinearIsTheExactNearest) {
  Pair p;
  for (auto f : {Feature::normals, Feature::intensities}) {
    for (int patch : {1, 3}) {
      const Map map = run(p.dst, p.src, faithful(Method::linear, f, patch));
      expect_object_to_object(map, p.dst, p.src);
      const cv::Mat truth = oracle_distance(p.dst, p.src, f, patch);
      double worst = 0;
      for (int y = 0; y < truth.rows; ++y)
        for (int x = 0; x < truth.cols; ++x)
          if (p.dst.mask.at<uchar>(y, x))
            worst = std::max(worst, std::abs(double(map.distance.at<float>(y, x)) - truth.at<float>(y, x)));
      EXPECT_LT(worst, 1e-5) << feature_name(f) << " patch " << patch;
    }
  }
}

TEST(Matcher, IdenticalObjectsMapOntoThemselves) {
  const ObjectView v = ellipsoid({64, 48}, {31.f, 23.f}, 24.f, 18.f);
  for (auto m : {Method::linear, Method::flann, Method::candidates, Method::regiongrow, Method::baseline}) {
    const Map map = run(v, v, faithful(m));
    int off = 0;
    for (int y = 0; y < v.mask.rows; ++y)
      for (int x = 0; x < v.mask.cols; ++x)
        if (v.mask.at<uchar>(y, x) && map.xy.at<cv::Vec2f>(y, x) != cv::Vec2f(float(x), float(y))) ++off;
    // the cap's normals are all distinct except a few rounding ties
    EXPECT_LE(off, 4) << method_name(m);
  }
}

TEST(Matcher, CandidatesWithKOneIsDirectMatching) {
  Pair p;
  for (int patch : {1, 3}) {
    auto o = faithful(Method::candidates, Feature::normals, patch);
    o.candidates = 1;
    EXPECT_EQ(differing_pixels(run(p.dst, p.src, o), run(p.dst, p.src, faithful(Method::linear, Feature::normals, patch))), 0);
  }
}

TEST(Matcher, CandidatesChooseTheImageClosestAmongTheK) {
  Pair p;
  auto o = faithful(Method::candidates);
  o.candidates = 30;
  const Map map = run(p.dst, p.src, o);
  expect_object_to_object(map, p.dst, p.src);
  // each choice is one of the 30 nearest by feature, and no other of those is
  // nearer to the bounding-box image of the destination pixel
  auto fd = make_features(p.dst, Feature::normals, 1);
  auto fs = make_features(p.src, Feature::normals, 1);
  auto index = make_index("linear");
  index->build(fs->data.data(), fs->rows(), fs->dims);
  const cv::Rect bd = fd->bbox, bs = fs->bbox;
  int wrong = 0;
  for (int i = 0; i < fd->rows(); ++i) {
    std::vector<int> ids(30);
    std::vector<float> sq(30);
    index->knn(fd->row(i), 30, ids.data(), sq.data());
    const cv::Point pt = fd->pixels[i];
    const float tx = bs.x + (pt.x - bd.x + 0.5f) * bs.width / float(bd.width) - 0.5f;
    const float ty = bs.y + (pt.y - bd.y + 0.5f) * bs.height / float(bd.height) - 0.5f;
    float best = std::numeric_limits<float>::infinity();
    for (int id : ids) {
      const cv::Point q = fs->pixels[id];
      best = std::min(best, (q.x - tx) * (q.x - tx) + (q.y - ty) * (q.y - ty));
    }
    const cv::Vec2f m = map.xy.at<cv::Vec2f>(pt);
    const float got = (m[0] - tx) * (m[0] - tx) + (m[1] - ty) * (m[1] - ty);
    if (got > best + 1e-4f) ++wrong;
  }
  EXPECT_EQ(wrong, 0);
  EXPECT_GE(mean_distance(map, p.dst.mask), mean_distance(run(p.dst, p.src, faithful(Method::linear)), p.dst.mask));
}

TEST(Matcher, RegionGrowingAtThresholdZeroIsDirectMatching) {
  Pair p;
  for (auto f : {Feature::normals, Feature::intensities}) {
    auto o = faithful(Method::regiongrow, f, 3);
    o.threshold = 0;
    EXPECT_EQ(differing_pixels(run(p.dst, p.src, o), run(p.dst, p.src, faithful(Method::linear, f, 3))), 0);
  }
}

TEST(Matcher, RegionGrowingKeepsItsConstraints) {
  Pair p;
  auto o = faithful(Method::regiongrow);
  o.threshold = 0.1;
  const Map grown = run(p.dst, p.src, o);
  expect_object_to_object(grown, p.dst, p.src);
  const Map direct = run(p.dst, p.src, faithful(Method::linear));
  // a grown pixel's distance is within the threshold of its direct match's
  int violations = 0, grown_pixels = 0;
  for (int y = 0; y < p.dst.mask.rows; ++y) {
    for (int x = 0; x < p.dst.mask.cols; ++x) {
      if (!p.dst.mask.at<uchar>(y, x)) continue;
      const float d = grown.distance.at<float>(y, x);
      const bool seed_like = grown.xy.at<cv::Vec2f>(y, x) == direct.xy.at<cv::Vec2f>(y, x);
      if (!seed_like) ++grown_pixels;
      if (!seed_like && !(d - direct.distance.at<float>(y, x) < 0.1f + 1e-6f)) ++violations;
      if (d < direct.distance.at<float>(y, x) - 1e-6f) ++violations;  // nothing beats the exact nearest
    }
  }
  EXPECT_EQ(violations, 0);
  EXPECT_GT(grown_pixels, 0);
  // growth copies neighbourhoods whole: far more coherent than direct matching
  auto coherent_pairs = [&](const Map& m) {
    int good = 0;
    for (int y = 0; y < p.dst.mask.rows; ++y)
      for (int x = 0; x + 1 < p.dst.mask.cols; ++x)
        if (p.dst.mask.at<uchar>(y, x) && p.dst.mask.at<uchar>(y, x + 1) &&
            cv::norm(m.xy.at<cv::Vec2f>(y, x + 1) - m.xy.at<cv::Vec2f>(y, x) - cv::Vec2f(1, 0)) < 0.5)
          ++good;
    return good;
  };
  EXPECT_GE(coherent_pairs(grown), coherent_pairs(direct));
}

// FLANN (4 randomized trees, 32 checks) is approximate: stated tolerance is a
// mean excess over the exact distance below 0.01 and at least 90 % of pixels
// within 1e-4 of it; never below the exact distance.
TEST(Matcher, FlannIsCloseToExact) {
  Pair p;
  for (auto f : {Feature::normals, Feature::intensities}) {
    for (int patch : {1, 5}) {
      const Map exact = run(p.dst, p.src, faithful(Method::linear, f, patch));
      const Map approx = run(p.dst, p.src, faithful(Method::flann, f, patch));
      expect_object_to_object(approx, p.dst, p.src);
      int close = 0, below = 0, total = 0;
      for (int y = 0; y < p.dst.mask.rows; ++y)
        for (int x = 0; x < p.dst.mask.cols; ++x) {
          if (!p.dst.mask.at<uchar>(y, x)) continue;
          ++total;
          const float a = approx.distance.at<float>(y, x), e = exact.distance.at<float>(y, x);
          if (a <= e + 1e-4f) ++close;
          if (a < e - 1e-5f) ++below;
        }
      EXPECT_EQ(below, 0);
      EXPECT_GE(close, 0.9 * total) << feature_name(f) << " " << patch;
      EXPECT_LT(mean_distance(approx, p.dst.mask) - mean_distance(exact, p.dst.mask), 0.01);
    }
  }
}

// PatchMatch is a randomized search: stated tolerance is a mean distance no
// more than 0.02 above the exact one after 5 iterations (for unit normals
// 0.02 is about 1.1 degrees).
TEST(Matcher, PatchMatchIsCloseToExact) {
  Pair p;
  for (int patch : {1, 3, 7}) {
    const Map exact = run(p.dst, p.src, faithful(Method::linear, Feature::normals, patch));
    const Map pm = run(p.dst, p.src, faithful(Method::patchmatch, Feature::normals, patch));
    expect_object_to_object(pm, p.dst, p.src);
    EXPECT_LT(mean_distance(pm, p.dst.mask) - mean_distance(exact, p.dst.mask), 0.02) << patch;
    EXPECT_GE(mean_distance(pm, p.dst.mask), mean_distance(exact, p.dst.mask) - 1e-6);
  }
}

TEST(Matcher, PatchMatchIsDeterministicPerSeed) {
  Pair p;
  auto o = faithful(Method::patchmatch, Feature::normals, 3);
  const Map a = run(p.dst, p.src, o), b = run(p.dst, p.src, o);
  EXPECT_EQ(differing_pixels(a, b), 0);
  o.seed = 7;
  EXPECT_GT(differing_pixels(a, run(p.dst, p.src, o)), 0);
}

TEST(Matcher, BaselineStretchesTheBoundingBox) {
  // a destination twice the source's size: pixel (2i, 2j) of the box lands near (i, j)
  ObjectView src = ellipsoid({40, 30}, {20.f, 15.f}, 15.f, 10.f);
  ObjectView dst = ellipsoid({80, 60}, {40.f, 30.f}, 30.f, 20.f);
  const Map map = run(dst, src, faithful(Method::baseline));
  expect_object_to_object(map, dst, src);
  const cv::Vec2f centre = map.xy.at<cv::Vec2f>(30, 40);
  EXPECT_NEAR(centre[0], 20, 1.0);
  EXPECT_NEAR(centre[1], 15, 1.0);
}

TEST(Matcher, SetsOfDifferentSizes) {
  ObjectView dst = ellipsoid({96, 40}, {50.f, 20.f}, 40.f, 15.f);
  ObjectView src = ellipsoid({30, 70}, {15.f, 35.f}, 12.f, 30.f);
  for (auto m : {Method::linear, Method::flann, Method::candidates, Method::patchmatch, Method::regiongrow,
                 Method::baseline}) {
    const Map map = run(dst, src, faithful(m, Feature::normals, 3));
    EXPECT_EQ(map.xy.size(), dst.mask.size());
    expect_object_to_object(map, dst, src);
  }
}

TEST(Matcher, NothingIsMappedIntoTheBackground) {
  Pair p;
  for (auto m : {Method::linear, Method::flann, Method::candidates, Method::patchmatch, Method::regiongrow,
                 Method::baseline})
    for (auto f : {Feature::normals, Feature::intensities})
      expect_object_to_object(run(p.dst, p.src, faithful(m, f, 5)), p.dst, p.src);
}

TEST(Features, IntensitiesAreNormalizedPerPixel) {
  Pair p;
  auto fs = make_features(p.dst, Feature::intensities, 1);
  ASSERT_TRUE(fs.ok());
  ASSERT_EQ(fs->dims, 7);
  for (int i = 0; i < fs->rows(); i += 17) {
    double sum = 0;
    for (int k = 0; k < 7; ++k) sum += fs->row(i)[k];
    EXPECT_NEAR(sum, 1.0, 1e-5);
  }
}

TEST(Features, PatchBordersAreMirrored) {
  // a 3-pixel-wide object strip: the patch of an edge pixel mirrors its inside neighbour
  ObjectView v;
  v.mask = cv::Mat(5, 6, CV_8UC1, cv::Scalar(0));
  v.normals = cv::Mat(5, 6, CV_32FC3, cv::Scalar::all(0));
  for (int y = 0; y < 5; ++y)
    for (int x = 0; x < 3; ++x) {
      v.mask.at<uchar>(y, x) = 255;
      v.normals.at<cv::Vec3f>(y, x) = cv::Vec3f(float(x), float(y), 1);
    }
  auto fs = make_features(v, Feature::normals, 3);
  ASSERT_TRUE(fs.ok());
  ASSERT_EQ(fs->dims, 27);
  const float* f = fs->row(fs->row_at(2, 0));  // top-right corner of the strip
  // patch offset (dx, dy) = (+1, -1) is off the object: mirrored to (-1, +1) -> pixel (1, 1)
  EXPECT_EQ(f[2 * 3 + 0], 1.f);
  EXPECT_EQ(f[2 * 3 + 1], 1.f);
  // centre
  EXPECT_EQ(f[4 * 3 + 0], 2.f);
  EXPECT_EQ(f[4 * 3 + 1], 0.f);
  // (+1, 0) -> (-1, 0) -> pixel (1, 0)
  EXPECT_EQ(f[5 * 3 + 0], 1.f);
  EXPECT_EQ(f[5 * 3 + 1], 0.f);
  // no background zeros anywhere in the patch
  for (int k = 0; k < 27; k += 3) EXPECT_EQ(f[k + 2], 1.f);
}

TEST(Matcher, RejectsBadInput) {
  Pair p;
  auto expect_error = [&](const ObjectView& d, const ObjectView& s, const MatchOptions& o, const std::string& word) {
    auto map = compute_map(d, s, o);
    ASSERT_FALSE(map.ok());
    EXPECT_NE(map.message().find(word), std::string::npos) << map.message();
  };
  // intensities over sets with different lamps
  ObjectView six = ellipsoid({56, 52}, {28.f, 27.f}, 19.f, 21.f, 6, 5);
  expect_error(p.dst, six, faithful(Method::linear, Feature::intensities), "same lamps");
  ObjectView renamed = p.src;
  renamed.lamps[3] = "hue-9";
  expect_error(p.dst, renamed, faithful(Method::linear, Feature::intensities), "same lamps");
  // normals do not care about lamps
  EXPECT_TRUE(compute_map(p.dst, six, faithful(Method::linear)).ok());
  // empty mask
  ObjectView empty = p.src;
  empty.mask = cv::Mat(empty.mask.size(), CV_8UC1, cv::Scalar(0));
  expect_error(p.dst, empty, faithful(Method::linear), "mask is empty");
  expect_error(empty, p.src, faithful(Method::patchmatch), "destination");
  // options
  auto o = faithful(Method::linear);
  o.patch = 4;
  expect_error(p.dst, p.src, o, "patch");
  o = faithful(Method::candidates);
  o.candidates = 0;
  expect_error(p.dst, p.src, o, "candidates");
  o.candidates = 101;
  expect_error(p.dst, p.src, o, "candidates");
  o = faithful(Method::regiongrow);
  o.threshold = -0.1;
  expect_error(p.dst, p.src, o, "threshold");
  o.threshold = std::numeric_limits<double>::quiet_NaN();
  expect_error(p.dst, p.src, o, "threshold");
  // mismatched sizes inside one view
  ObjectView bad = p.dst;
  bad.normals = cv::Mat(10, 10, CV_32FC3, cv::Scalar::all(0));
  expect_error(bad, p.src, faithful(Method::linear), "normals");
  EXPECT_FALSE(parse_method("bogus").ok());
  EXPECT_FALSE(parse_feature("colour").ok());
  EXPECT_EQ(*parse_method("regiongrow"), Method::regiongrow);
}

TEST(Matcher, CancelStopsWithAnError) {
  Pair p;
  std::atomic<bool> cancel{true};
  Progress progress;
  progress.cancel = &cancel;
  for (auto m : {Method::linear, Method::flann, Method::patchmatch, Method::regiongrow, Method::candidates}) {
    auto map = compute_map(p.dst, p.src, faithful(m), progress);
    ASSERT_FALSE(map.ok()) << method_name(m);
    EXPECT_NE(map.message().find("cancelled"), std::string::npos);
  }
}

TEST(Index, LinearKnnIsSortedAndExact) {
  std::vector<float> pts = {0, 0, 1, 0, 2, 0, 3, 0, 0.5f, 0};
  auto index = make_index("linear");
  index->build(pts.data(), 5, 2);
  const float q[2] = {0.6f, 0};
  int ids[7];
  float d[7];
  index->knn(q, 7, ids, d);
  EXPECT_EQ(ids[0], 4);
  EXPECT_EQ(ids[1], 1);
  EXPECT_EQ(ids[2], 0);
  EXPECT_EQ(ids[5], -1);
  EXPECT_NEAR(d[0], 0.01f, 1e-6);
  auto flann = make_index("flann");
  ASSERT_NE(flann, nullptr);
  flann->build(pts.data(), 5, 2);
  flann->knn(q, 1, ids, d);
  EXPECT_EQ(ids[0], 4);
  EXPECT_EQ(make_index("nonsense"), nullptr);
}

}  // namespace
}  // namespace veneer::match
