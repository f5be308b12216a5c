// core/CombinedPhotos.*: `combined` reads the photos as they come (float or
// half floats, io::ReadOptions::half_floats) and reduces only the part of them
// under the object (issue 48), giving the map it gives the photos widened
// first, to the bit.
#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include "scenes.hpp"
#include "veneer/match/matcher.hpp"

namespace veneer::match {
namespace {

// `v` resized by f (area average), as a camera farther away sees it.
ObjectView resized(const ObjectView& v, double f) {
  ObjectView out = v;
  const cv::Size size(static_cast<int>(std::lround(v.mask.cols * f)), static_cast<int>(std::lround(v.mask.rows * f)));
  cv::resize(v.normals, out.normals, size, 0, 0, cv::INTER_AREA);
  cv::resize(v.mask, out.mask, size, 0, 0, cv::INTER_NEAREST);
  out.normals.forEach<cv::Vec3f>([&](cv::Vec3f& n, const int* at) {
    const float l = static_cast<float>(cv::norm(n));
    n = out.mask.at<uchar>(at[0], at[1]) && l > 1e-6f ? n / l : cv::Vec3f(0, 0, 0);
  });
  for (auto& im : out.images) cv::resize(im, im, size, 0, 0, cv::INTER_AREA);
  return out;
}

// The view with its photos rounded to half floats, and the same widened back.
std::pair<ObjectView, ObjectView> half_and_widened(const ObjectView& v) {
  ObjectView half = v, wide = v;
  for (size_t i = 0; i < v.images.size(); ++i) {
    v.images[i].convertTo(half.images[i], CV_16F);
    half.images[i].convertTo(wide.images[i], CV_32F);
  }
  return {half, wide};
}

void expect_same_map(const Map& a, const Map& b, const std::string& what) {
  ASSERT_EQ(a.xy.size(), b.xy.size()) << what;
  EXPECT_EQ(cv::countNonZero(cv::Mat(a.xy != b.xy).reshape(1)), 0) << what;
  EXPECT_EQ(cv::countNonZero(a.distance != b.distance), 0) << what;
  EXPECT_EQ(a.motion.found, b.motion.found) << what;
  EXPECT_EQ(a.motion.note, b.motion.note) << what;
  for (int i = 0; i < 6; ++i) EXPECT_EQ(a.motion.affine.val[i], b.motion.affine.val[i]) << what;
}

TEST(CombinedPhotos, HalfFloatPhotosGiveTheWidenedPhotosMapToTheBit) {
  MatchOptions o;
  o.method = Method::combined;
  // Frames the levels divide (the photos reduced under the object only) and
  // frames they do not (reduced whole); the same object scaled (the motion
  // found: the full size is read too) and two objects (the coarsest only).
  for (const cv::Size size : {cv::Size(320, 240), cv::Size(322, 238)}) {
    const ObjectView src = testing::ellipsoid(size, {size.width * 0.5f, size.height * 0.5f}, 90, 70, 7, 1);
    const ObjectView same = resized(src, 0.8);
    const ObjectView other = testing::ellipsoid(size, {size.width * 0.45f, size.height * 0.55f}, 60, 80, 7, 5);
    for (const auto& [what, dst] : {std::pair<std::string, const ObjectView&>{"the same object", same},
                                    std::pair<std::string, const ObjectView&>{"another object", other}}) {
      const std::string name = what + " at " + std::to_string(size.width) + "x" + std::to_string(size.height);
      const auto [dst_half, dst_wide] = half_and_widened(dst);
      const auto [src_half, src_wide] = half_and_widened(src);
      auto from_half = compute_map(dst_half, src_half, o);
      auto from_wide = compute_map(dst_wide, src_wide, o);
      ASSERT_TRUE(from_half.ok()) << name << ": " << from_half.message();
      ASSERT_TRUE(from_wide.ok()) << name << ": " << from_wide.message();
      if (what == "the same object") {
        EXPECT_TRUE(from_wide->motion.found) << name << ": " << from_wide->motion.note;
      }
      expect_same_map(*from_half, *from_wide, name);
    }
  }
}

// What downscaled() relies on: OpenCV's area reduction by an integer factor
// of a block-aligned part of a 3-channel frame is the whole frame's reduction
// there, to the bit (each reduced pixel the mean of its own block).
TEST(CombinedPhotos, AreaReducedPartsAreTheWholeFramesToTheBit) {
  cv::RNG rng(48);
  for (const int f : {2, 4, 8, 16, 32}) {
    for (int t = 0; t < 20; ++t) {
      const int w = f * rng.uniform(8, 60), h = f * rng.uniform(8, 40);
      cv::Mat frame(h, w, CV_32FC3);
      rng.fill(frame, cv::RNG::UNIFORM, 0.0, 1.0);
      cv::Mat whole;
      cv::resize(frame, whole, {w / f, h / f}, 0, 0, cv::INTER_AREA);
      const int bw = rng.uniform(1, w / f + 1), bh = rng.uniform(1, h / f + 1);
      const cv::Rect box(rng.uniform(0, w / f - bw + 1), rng.uniform(0, h / f - bh + 1), bw, bh);
      cv::Mat part;
      cv::resize(frame(cv::Rect(box.x * f, box.y * f, box.width * f, box.height * f)), part, box.size(), 0, 0,
                 cv::INTER_AREA);
      EXPECT_EQ(cv::countNonZero(cv::Mat(part != whole(box)).reshape(1)), 0) << "factor " << f << ", box " << box;
    }
  }
}

TEST(CombinedPhotos, PhotosOfAnotherTypeAreRefusedNamingThem) {
  const cv::Size size(160, 120);
  ObjectView src = testing::ellipsoid(size, {80, 60}, 50, 40);
  ObjectView dst = testing::ellipsoid(size, {80, 60}, 40, 45, 7, 3);
  for (auto& im : dst.images) im.convertTo(im, CV_8UC3, 255);
  MatchOptions o;
  o.method = Method::combined;
  auto map = compute_map(dst, src, o);
  ASSERT_FALSE(map.ok());
  EXPECT_NE(map.message().find("destination's photos must be CV_32FC3 or CV_16FC3"), std::string::npos)
      << map.message();
}

}  // namespace
}  // namespace veneer::match
