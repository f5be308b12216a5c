// Quality figures and transfer pictures on hand-made maps with known answers.
#include <gtest/gtest.h>

#include <filesystem>

#include "scenes.hpp"
#include "veneer/eval/metrics.hpp"
#include "veneer/pipeline/transfer.hpp"

namespace veneer::match {
namespace {

using namespace veneer::eval;
using namespace veneer::pipeline;
using namespace veneer::repaint;

using testing::ellipsoid;

Map identity_map(const cv::Mat& mask) {
  Map m;
  m.xy = cv::Mat(mask.size(), CV_32FC2, cv::Scalar(-1, -1));
  m.distance = cv::Mat(mask.size(), CV_32F, cv::Scalar(0));
  for (int y = 0; y < mask.rows; ++y)
    for (int x = 0; x < mask.cols; ++x)
      if (mask.at<uchar>(y, x)) m.xy.at<cv::Vec2f>(y, x) = cv::Vec2f(float(x), float(y));
  return m;
}

cv::Mat rotate_normals(const cv::Mat& n, double degrees) {
  const double a = degrees * M_PI / 180;
  cv::Mat out = n.clone();
  for (auto it = out.begin<cv::Vec3f>(); it != out.end<cv::Vec3f>(); ++it) {
    const cv::Vec3f v = *it;
    *it = cv::Vec3f(float(v[0] * std::cos(a) + v[2] * std::sin(a)), v[1], float(-v[0] * std::sin(a) + v[2] * std::cos(a)));
  }
  return out;
}

TEST(Metrics, IdentityMapIsPerfect) {
  const ObjectView v = ellipsoid({64, 48}, {31.f, 23.f}, 24.f, 18.f);
  const Quality q = evaluate(identity_map(v.mask), v.mask, v.mask, v.normals, v.normals);
  EXPECT_EQ(q.destination_pixels, cv::countNonZero(v.mask));
  EXPECT_DOUBLE_EQ(q.coverage, 1.0);
  EXPECT_EQ(q.background_hits, 0);
  ASSERT_TRUE(q.normal_mean_deg.has_value());
  EXPECT_NEAR(*q.normal_mean_deg, 0.0, 0.05);
  EXPECT_DOUBLE_EQ(q.coherence, 1.0);
  EXPECT_EQ(q.reuse_max, 1);
  EXPECT_DOUBLE_EQ(q.source_used, 1.0);
}

TEST(Metrics, KnownDefects) {
  const ObjectView v = ellipsoid({64, 48}, {31.f, 23.f}, 24.f, 18.f);
  const int n = cv::countNonZero(v.mask);
  Map m = identity_map(v.mask);
  // flat normals against the same rotated by 10 degrees: every pair disagrees by 10 degrees
  cv::Mat flat(v.mask.size(), CV_32FC3, cv::Scalar(0, 0, 1));
  Quality q = evaluate(m, v.mask, v.mask, flat, rotate_normals(flat, 10));
  EXPECT_NEAR(*q.normal_mean_deg, 10.0, 0.05);
  EXPECT_NEAR(*q.normal_p95_deg, 10.0, 0.05);
  // one pixel unmapped, one mapped into the source's background (corner 0,0)
  m.xy.at<cv::Vec2f>(23, 31) = cv::Vec2f(-1, -1);
  m.xy.at<cv::Vec2f>(23, 32) = cv::Vec2f(0, 0);
  q = evaluate(m, v.mask, v.mask);
  EXPECT_EQ(q.mapped_pixels, n - 2);
  EXPECT_EQ(q.background_hits, 1);
  EXPECT_NEAR(q.coverage, double(n - 2) / n, 1e-12);
  EXPECT_FALSE(q.normal_mean_deg.has_value());
  // everything onto one source pixel: reuse max n, one source pixel used
  Map one = identity_map(v.mask);
  one.xy.setTo(cv::Scalar(31, 23), v.mask);
  q = evaluate(one, v.mask, v.mask);
  EXPECT_EQ(q.reuse_max, n);
  EXPECT_NEAR(q.source_used, 1.0 / n, 1e-12);
  // a checkerboard of two far-apart source pixels: no coherent neighbour pair
  Map speckle = identity_map(v.mask);
  for (int y = 0; y < v.mask.rows; ++y)
    for (int x = 0; x < v.mask.cols; ++x)
      if (v.mask.at<uchar>(y, x)) speckle.xy.at<cv::Vec2f>(y, x) = (x + y) % 2 ? cv::Vec2f(31, 23) : cv::Vec2f(36, 23);
  EXPECT_DOUBLE_EQ(evaluate(speckle, v.mask, v.mask).coherence, 0.0);
}

TEST(Metrics, Psnr) {
  cv::Mat a(10, 10, CV_32FC3, cv::Scalar::all(0.5)), b(10, 10, CV_32FC3, cv::Scalar::all(0.6));
  cv::Mat mask(10, 10, CV_8UC1, cv::Scalar(255));
  EXPECT_NEAR(psnr(a, b, mask), 20.0, 1e-4);  // MSE 0.01
  EXPECT_GT(psnr(a, a, mask), 100.0);
}

TEST(Transfer, MapFileRoundTripAndPictures) {
  const ObjectView v = ellipsoid({64, 48}, {31.f, 23.f}, 24.f, 18.f);
  Map m = identity_map(v.mask);
  m.distance.setTo(0.25, v.mask);
  const auto dir = std::filesystem::temp_directory_path() / ("veneer-match-test-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  ASSERT_TRUE(write_map(dir / "map.pfm", m).ok());
  auto back = read_map(dir / "map.pfm");
  ASSERT_TRUE(back.ok()) << back.message();
  cv::Mat diff;
  cv::absdiff(back->xy.reshape(1), m.xy.reshape(1), diff);
  EXPECT_EQ(cv::countNonZero(diff), 0);
  EXPECT_FLOAT_EQ(back->distance.at<float>(23, 31), 0.25f);
  EXPECT_EQ(back->xy.at<cv::Vec2f>(0, 0), cv::Vec2f(-1, -1));
  std::filesystem::remove_all(dir);

  // map picture: B = 1, G = y / height, R = x / width; black unmapped
  const cv::Mat pic = map_picture(m, {64, 48});
  EXPECT_EQ(pic.at<cv::Vec3b>(23, 32), cv::Vec3b(255, cv::saturate_cast<uchar>(255.0 * 23 / 48), 128));
  EXPECT_EQ(pic.at<cv::Vec3b>(0, 0), cv::Vec3b(0, 0, 0));

  // repaint pastes the source photo through the map over the backdrop
  cv::Mat photo(48, 64, CV_32FC3, cv::Scalar(0.1f, 0.2f, 0.3f)), backdrop(48, 64, CV_32FC3, cv::Scalar::all(0.9f));
  Map shifted = identity_map(v.mask);
  shifted.xy.at<cv::Vec2f>(23, 31) = cv::Vec2f(5, 6);
  photo.at<cv::Vec3f>(6, 5) = cv::Vec3f(1, 0, 0);
  const cv::Mat painted = repaint::repaint(shifted, photo, backdrop);
  EXPECT_EQ(painted.at<cv::Vec3f>(23, 31), cv::Vec3f(1, 0, 0));
  EXPECT_EQ(painted.at<cv::Vec3f>(23, 30), cv::Vec3f(0.1f, 0.2f, 0.3f));
  EXPECT_EQ(painted.at<cv::Vec3f>(0, 0), cv::Vec3f(0.9f, 0.9f, 0.9f));

  // reuse counts and the origin picture
  const cv::Mat counts = reuse_counts(shifted, {64, 48});
  EXPECT_EQ(counts.at<int>(6, 5), 1);
  EXPECT_EQ(counts.at<int>(23, 31), 0);
  const cv::Mat heat = reuse_picture(counts, photo);
  EXPECT_EQ(heat.size(), photo.size());
  const auto points = spread_points(m, 9);
  EXPECT_GE(points.size(), 5u);
  for (auto p : points) EXPECT_TRUE(m.valid(p.x, p.y));
  const cv::Mat origin = origin_picture(m, photo, photo(cv::Rect(0, 0, 40, 30)), points);
  EXPECT_EQ(origin.cols, 104);
  EXPECT_EQ(origin.rows, 48);
}

TEST(Transfer, MedianPhoto) {
  std::vector<cv::Mat> photos;
  for (float v : {0.9f, 0.1f, 0.5f, 0.3f, 0.7f}) photos.emplace_back(4, 4, CV_32FC3, cv::Scalar::all(v));
  const cv::Mat m = median_photo(photos);
  EXPECT_FLOAT_EQ(m.at<cv::Vec3f>(2, 2)[1], 0.5f);
}

}  // namespace
}  // namespace veneer::match
