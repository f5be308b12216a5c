// match/refine: a full-resolution map refined from a coarse one, against the
// exact nearest-normal map (Method::linear, brute force) as the oracle.
#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "scenes.hpp"
#include "veneer/match/refine.hpp"

namespace veneer::match {
namespace {

ObjectView halved(const ObjectView& v) {
  ObjectView h;
  cv::resize(v.normals, h.normals, v.normals.size() / 2, 0, 0, cv::INTER_AREA);
  cv::resize(v.mask, h.mask, v.mask.size() / 2, 0, 0, cv::INTER_NEAREST);
  for (int y = 0; y < h.normals.rows; ++y)
    for (int x = 0; x < h.normals.cols; ++x) {
      cv::Vec3f& n = h.normals.at<cv::Vec3f>(y, x);
      const float len = static_cast<float>(cv::norm(n));
      n = len > 0 ? n / len : cv::Vec3f(0, 0, 0);
    }
  return h;
}

// Mean |n_d - n_s| over the mapped destination pixels, and how many are mapped.
std::pair<double, int> agreement(const Map& map, const ObjectView& d, const ObjectView& s) {
  double sum = 0;
  int n = 0;
  for (int y = 0; y < d.mask.rows; ++y)
    for (int x = 0; x < d.mask.cols; ++x) {
      if (!d.mask.at<uint8_t>(y, x)) continue;
      const cv::Vec2f m = map.xy.at<cv::Vec2f>(y, x);
      if (m[0] < 0) continue;
      sum += cv::norm(d.normals.at<cv::Vec3f>(y, x) - s.normals.at<cv::Vec3f>(int(m[1]), int(m[0])));
      ++n;
    }
  return {n ? sum / n : 1e9, n};
}

TEST(Refine, AMapRefinedFromHalfSizeComesNearTheExactOne) {
  const ObjectView dst = testing::ellipsoid({160, 120}, {80, 60}, 50, 40, 7, 1);
  const ObjectView src = testing::ellipsoid({160, 120}, {72, 64}, 44, 46, 7, 2);
  MatchOptions exact_options;
  exact_options.method = Method::linear;
  auto exact = compute_map(dst, src, exact_options);
  ASSERT_TRUE(exact) << exact.message();
  const ObjectView dh = halved(dst), sh = halved(src);
  auto coarse = compute_map(dh, sh, exact_options);
  ASSERT_TRUE(coarse) << coarse.message();
  RefineOptions none;
  none.radius = 0;
  auto continued = refine_map(*coarse, dst, src, none);
  auto refined = refine_map(*coarse, dst, src);
  ASSERT_TRUE(continued) << continued.message();
  ASSERT_TRUE(refined) << refined.message();
  ASSERT_EQ(refined->xy.size(), dst.mask.size());
  const auto [e_exact, n_exact] = agreement(*exact, dst, src);
  const auto [e_refined, n_refined] = agreement(*refined, dst, src);
  const auto [e_continued, n_continued] = agreement(*continued, dst, src);
  EXPECT_EQ(n_refined, cv::countNonZero(dst.mask));  // every object pixel mapped
  EXPECT_GE(e_refined, e_exact - 1e-6);              // the exact map is the best there is
  EXPECT_LT(e_refined, e_exact + 0.02);              // and the refined one within ~1 degree of it
  EXPECT_LT(e_refined, e_continued);                 // the search does something the scaling alone does not
  // outside the destination's object nothing is mapped
  for (int y = 0; y < dst.mask.rows; ++y)
    for (int x = 0; x < dst.mask.cols; ++x) {
      if (!dst.mask.at<uint8_t>(y, x)) {
        ASSERT_LT(refined->xy.at<cv::Vec2f>(y, x)[0], 0);
      }
    }
}

TEST(Refine, BadInputIsRefused) {
  const ObjectView dst = testing::ellipsoid({40, 30}, {20, 15}, 10, 8);
  Map big;
  big.xy = cv::Mat(60, 80, CV_32FC2, cv::Scalar::all(-1));
  auto r = refine_map(big, dst, dst);
  ASSERT_FALSE(r);
  EXPECT_NE(r.message().find("larger"), std::string::npos) << r.message();
  Map coarse;
  coarse.xy = cv::Mat(15, 20, CV_32FC2, cv::Scalar::all(-1));
  RefineOptions o;
  o.radius = 9;
  EXPECT_FALSE(refine_map(coarse, dst, dst, o));
  ObjectView no_normals = dst;
  no_normals.normals = cv::Mat();
  EXPECT_FALSE(refine_map(coarse, no_normals, dst));
}

}  // namespace
}  // namespace veneer::match
