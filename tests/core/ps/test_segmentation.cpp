// core/Segmentation.*: thresholds, rectangle, cleaning, supplied masks.
#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include "synth.hpp"
#include "veneer/ps/segmentation.hpp"

namespace veneer::ps {
namespace {

using test::SynthOptions;
using test::synth_sphere;

double iou(const cv::Mat& a, const cv::Mat& b) {
  cv::Mat i, u;
  cv::bitwise_and(a, b, i);
  cv::bitwise_or(a, b, u);
  return double(cv::countNonZero(i)) / std::max(1, cv::countNonZero(u));
}

// A sphere on a dim background with a few bright specks and a dark hole.
io::ImageSet speckled_sphere() {
  SynthOptions o;
  o.noise = 0.003;
  io::ImageSet set = synth_sphere(o);
  for (auto& im : set.images) {
    im += cv::Scalar::all(0.01);  // dim table
    cv::circle(im, {20, 20}, 1, cv::Scalar::all(0.8), cv::FILLED);    // speck
    cv::circle(im, {230, 150}, 1, cv::Scalar::all(0.8), cv::FILLED);  // speck
    cv::circle(im, {128, 85}, 2, cv::Scalar::all(0.0), cv::FILLED);   // dark hole in the sphere
  }
  return set;
}

TEST(Segmentation, OtsuFindsSphereAndCleans) {
  io::ImageSet set = speckled_sphere();
  SegmentOptions opt;
  opt.method = SegmentMethod::otsu;
  auto s = segment(set, opt);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_EQ(s->method_used, SegmentMethod::otsu);
  EXPECT_GT(s->threshold, 0.01);
  EXPECT_GT(iou(s->mask, set.truth.mask), 0.95);
  EXPECT_EQ(s->mask.at<uint8_t>(20, 20), 0);    // speck removed
  EXPECT_EQ(s->mask.at<uint8_t>(85, 128), 255);  // hole filled
  // Without cleaning both remain.
  opt.clean = false;
  s = segment(set, opt);
  ASSERT_TRUE(s.ok());
  EXPECT_EQ(s->mask.at<uint8_t>(20, 20), 255);
  EXPECT_EQ(s->mask.at<uint8_t>(85, 128), 0);
}

TEST(Segmentation, FixedThresholdIsTheThesisSummedIntensity) {
  io::ImageSet set = speckled_sphere();
  SegmentOptions opt;
  opt.method = SegmentMethod::threshold;
  opt.threshold = 0.05;
  auto s = segment(set, opt);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_DOUBLE_EQ(s->threshold, 0.05);
  EXPECT_GT(iou(s->mask, set.truth.mask), 0.9);
  // A threshold above every pixel leaves nothing: an error, not an empty mask.
  opt.threshold = 0.99;
  s = segment(set, opt);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("no object pixels"), std::string::npos) << s.message();
}

TEST(Segmentation, RectangleLimitsTheObject) {
  io::ImageSet set = speckled_sphere();
  SegmentOptions opt;
  opt.method = SegmentMethod::otsu;
  opt.rect = cv::Rect(0, 0, 128, 170);  // left half
  auto s = segment(set, opt);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_EQ(cv::countNonZero(s->mask(cv::Rect(128, 0, 128, 170))), 0);
  EXPECT_GT(cv::countNonZero(s->mask(cv::Rect(0, 0, 128, 170))), 1000);
  opt.rect = cv::Rect(1000, 1000, 10, 10);
  s = segment(set, opt);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("outside"), std::string::npos) << s.message();
}

TEST(Segmentation, SuppliedMaskIsTheDefault) {
  io::ImageSet set = speckled_sphere();
  set.mask = cv::Mat(set.images[0].size(), CV_8UC1, cv::Scalar(0));
  cv::rectangle(set.mask, cv::Rect(10, 10, 50, 40), cv::Scalar(255), cv::FILLED);
  auto s = segment(set, {});
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_EQ(s->method_used, SegmentMethod::supplied);
  EXPECT_EQ(cv::countNonZero(s->mask), 50 * 40);
  // Without one, automatic means contrast; `supplied` is an error.
  set.mask = cv::Mat();
  s = segment(set, {});
  ASSERT_TRUE(s.ok());
  EXPECT_EQ(s->method_used, SegmentMethod::contrast);
  SegmentOptions opt;
  opt.method = SegmentMethod::supplied;
  EXPECT_FALSE(segment(set, opt).ok());
}

TEST(Segmentation, AmbientIsSubtracted) {
  SynthOptions o;
  o.ambient = 0.2;  // a bright room: without subtraction everything is "object"
  io::ImageSet set = synth_sphere(o);
  SegmentOptions opt;
  opt.method = SegmentMethod::threshold;
  opt.threshold = 0.05;
  auto s = segment(set, opt);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_GT(iou(s->mask, set.truth.mask), 0.9);
  opt.subtract_ambient = false;
  s = segment(set, opt);
  ASSERT_TRUE(s.ok());
  EXPECT_EQ(s->object_pixels, int(set.images[0].total()));
}

TEST(Segmentation, BadInput) {
  io::ImageSet empty;
  EXPECT_FALSE(segment(empty, {}).ok());
  SegmentOptions opt;
  opt.threshold = -1;
  EXPECT_FALSE(opt.check().ok());
  opt = {};
  opt.rect = cv::Rect(0, 0, 0, 5);
  EXPECT_FALSE(opt.check().ok());
  EXPECT_EQ(parse_segment_method("otsu").value(), SegmentMethod::otsu);
  EXPECT_FALSE(parse_segment_method("magic").ok());
}

}  // namespace
}  // namespace veneer::ps
