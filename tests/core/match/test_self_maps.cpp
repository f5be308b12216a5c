// core/SelfMaps.*: the default correspondence finds an object's motion on
// itself, on every real object (../shared/data/real/) and on simulated ones
// seen through the camera's optics: the object against a copy of itself
// scaled 0.8x, shifted (with noise), turned, and scaled + turned + cropped by
// the frame, where the true map is known.
#include <gtest/gtest.h>

#include <cstdio>
#include <algorithm>
#include <filesystem>
#include <functional>

#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include "veneer/io/imageset.hpp"
#include "veneer/eval/metrics.hpp"
#include "veneer/match/object.hpp"
#include "veneer/pipeline/transfer.hpp"
#include "veneer/sim/simulator.hpp"

namespace veneer::match {
namespace {

const std::filesystem::path kReal = std::filesystem::path(VENEER_SHARED_DATA) / "real";

// A copy of `set` seen through the affine `a` (destination pixel = a * source
// pixel, pixel centres at integers), in a frame of `size`, with Gaussian noise
// of `sigma` added to the photos. The copy has no truth: its mask is the
// source's mask carried along when it has one, else it is segmented anew.
io::ImageSet warped_copy(const io::ImageSet& set, const cv::Matx23d& a, cv::Size size, double sigma, unsigned seed) {
  io::ImageSet out = set;
  out.size = size;
  out.truth = {};
  cv::RNG rng(seed);
  auto warp = [&](const cv::Mat& m) {
    cv::Mat t;
    cv::warpAffine(m, t, cv::Mat(a), size, cv::INTER_LINEAR, cv::BORDER_REPLICATE);
    return t;
  };
  for (auto& im : out.images) {
    im = warp(im);
    if (sigma > 0) {
      cv::Mat noise(im.size(), im.type());
      rng.fill(noise, cv::RNG::NORMAL, 0, sigma);
      im += noise;
    }
  }
  if (!out.ambient.empty()) out.ambient = warp(out.ambient);
  if (!set.mask.empty()) {
    cv::Mat m;
    cv::warpAffine(set.mask, m, cv::Mat(a), size, cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar(0));
    out.mask = cv::Mat(m > 127);  // a new buffer: assigning the expression would write into set.mask's
  }
  return out;
}

struct Score {
  double within = 0;     // share of destination pixels (whose truth lies on the source object) within tolerance
  double median_px = 0;  // median error over them
  double coverage = 0;
};

Score score(const Map& map, const cv::Mat& dst_mask, const cv::Mat& src_mask,
            const std::function<cv::Point2d(int, int)>& truth, double tolerance) {
  long n = 0, ok = 0;
  std::vector<double> errors;
  for (int y = 0; y < map.xy.rows; ++y)
    for (int x = 0; x < map.xy.cols; ++x) {
      if (!dst_mask.at<uchar>(y, x)) continue;
      const cv::Point2d t = truth(x, y);
      const int tx = static_cast<int>(std::lround(t.x)), ty = static_cast<int>(std::lround(t.y));
      if (tx < 0 || ty < 0 || tx >= src_mask.cols || ty >= src_mask.rows || !src_mask.at<uchar>(ty, tx)) continue;
      ++n;
      const cv::Vec2f m = map.xy.at<cv::Vec2f>(y, x);
      const double e = m[0] >= 0 ? std::hypot(m[0] - t.x, m[1] - t.y) : 1e9;
      errors.push_back(e);
      if (e <= tolerance) ++ok;
    }
  Score s;
  if (!errors.empty()) {
    std::nth_element(errors.begin(), errors.begin() + errors.size() / 2, errors.end());
    s.median_px = errors[errors.size() / 2];
  }
  s.within = n ? static_cast<double>(ok) / n : 0.0;
  s.coverage = eval::evaluate(map, dst_mask, src_mask).coverage;
  return s;
}

// The object's centre (its mask's centroid).
cv::Point2d centre_of(const cv::Mat& mask) {
  const cv::Moments m = cv::moments(mask, true);
  return {m.m10 / m.m00, m.m01 / m.m00};
}

// Rotation by `deg` and scale `s` about `c`, then a shift: destination = a * source.
cv::Matx23d similarity(cv::Point2d c, double deg, double s, cv::Point2d shift) {
  const cv::Mat r = cv::getRotationMatrix2D(c, deg, s);
  cv::Matx23d a(r);
  a(0, 2) += shift.x;
  a(1, 2) += shift.y;
  return a;
}

cv::Point2d inverse_at(const cv::Matx23d& a, int x, int y) {
  cv::Matx23d inv;
  cv::invertAffineTransform(a, inv);
  return {inv(0, 0) * x + inv(0, 1) * y + inv(0, 2), inv(1, 0) * x + inv(1, 1) * y + inv(1, 2)};
}

// Real objects as they are; simulated ones through the camera's optics (box
// aperture at outlines, low-pass filter) with sensor noise, the size of the
// real photos.
Expected<io::ImageSet> object_set(const std::string& name) {
  if (name.rfind("sim-", 0) == 0) {
    sim::RenderOptions ro;
    ro.size = {512, 340};
    ro.scale = 1.6;
    ro.noise_sigma = 0.005;
    ro.camera_optics();
    auto set = sim::simulate_set(name.substr(4), ro);
    // Distant lights: a copy moved in the picture is not the object moved
    // under near lamps (whose light at a pixel depends on where it is).
    if (set)
      for (auto& l : set->lights) l.position_m.reset();
    return set;
  }
  return io::read_set(kReal / name);
}

class SelfMaps : public ::testing::TestWithParam<std::string> {};

// The chrome sphere is a mirror: its photos are dark but for the lamps'
// highlights and a dim reflection of the room, and photometric stereo gives
// it no meaningful normals; the motion search does not find its motion (2-7 %
// of the matches follow one) -- and says so.
bool motion_expected(const std::string& name) { return name != "chrome"; }

TEST_P(SelfMaps, FindTheMotionScaledShiftedTurnedAndCropped) {
  const std::string name = GetParam();
  if (name.rfind("sim-", 0) != 0 && !std::filesystem::exists(kReal / name / "filenames.txt"))
    GTEST_SKIP() << "no " << (kReal / name);
  auto set = object_set(name);
  ASSERT_TRUE(set.ok()) << set.message();
  auto src = prepare_object(*set, false);
  ASSERT_TRUE(src.ok()) << src.message();
  const cv::Mat& src_mask = src->view.mask;
  const cv::Point2d c = centre_of(src_mask);
  const cv::Rect box = cv::boundingRect(src_mask);
  MatchOptions o;
  o.method = Method::combined;

  struct Case {
    std::string what;
    double tolerance, goal;
  };
  auto run = [&](const Case& k, const io::ImageSet& moved, const std::function<cv::Point2d(int, int)>& truth) {
    auto dst = prepare_object(moved, false);
    ASSERT_TRUE(dst.ok()) << dst.message();
    auto map = compute_map(dst->view, src->view, o);
    ASSERT_TRUE(map.ok()) << map.message();
    const Score s = score(*map, dst->view.mask, src_mask, truth, k.tolerance);
    std::printf("| %s | %s | %.1f %% within %.1f px | median %.2f px | coverage %.1f %% | %s |\n", name.c_str(),
                k.what.c_str(), 100 * s.within, k.tolerance, s.median_px, 100 * s.coverage,
                map->motion.found ? ("motion on " + std::to_string(static_cast<int>(100 * map->motion.share)) + " %").c_str()
                                  : map->motion.note.c_str());
    EXPECT_GE(s.coverage, 0.995) << name << ", " << k.what;
    if (motion_expected(name)) {
      EXPECT_TRUE(map->motion.found) << name << ", " << k.what << ": " << map->motion.note;
      EXPECT_GE(s.within, k.goal) << name << ", " << k.what;
    } else {
      // Where it is not found, the map says so and why.
      EXPECT_TRUE(map->motion.searched);
      if (map->motion.found) {
        EXPECT_GE(s.within, k.goal) << name << ", " << k.what;
      } else {
        EXPECT_FALSE(map->motion.note.empty());
      }
    }
  };

  {  // 0.8x, as scale_set resizes (area average): source = (x + 0.5) / 0.8 - 0.5
    io::ImageSet small = *set;
    small.truth = {};
    scale_set(small, 0.8);
    const double sx = static_cast<double>(set->size.width) / small.size.width;
    const double sy = static_cast<double>(set->size.height) / small.size.height;
    run({"0.8x", 2.0, 0.90}, small, [&](int x, int y) { return cv::Point2d((x + 0.5) * sx - 0.5, (y + 0.5) * sy - 0.5); });
  }
  {  // shifted (3, -2) px, noise 2/255
    const cv::Matx23d a(1, 0, 3, 0, 1, -2);
    run({"shifted (3, -2) + noise", 1.5, 0.97}, warped_copy(*set, a, set->size, 2.0 / 255, 7),
        [&](int x, int y) { return inverse_at(a, x, y); });
  }
  {  // turned 7 degrees about the object's centre
    const cv::Matx23d a = similarity(c, 7.0, 1.0, {0, 0});
    run({"turned 7 deg", 2.0, 0.90}, warped_copy(*set, a, set->size, 1.0 / 255, 8),
        [&](int x, int y) { return inverse_at(a, x, y); });
  }
  {  // the frame cutting off the object's left fifth
    const cv::Matx23d a(1, 0, -(box.x + 0.2 * box.width), 0, 1, 0);
    run({"cropped", 1.5, 0.97}, warped_copy(*set, a, set->size, 1.0 / 255, 10),
        [&](int x, int y) { return inverse_at(a, x, y); });
  }
  {  // 0.8x and turned -6 degrees
    const cv::Matx23d a = similarity(c, -6.0, 0.8, {0, 0});
    run({"0.8x, turned -6 deg", 2.0, 0.90}, warped_copy(*set, a, set->size, 1.0 / 255, 11),
        [&](int x, int y) { return inverse_at(a, x, y); });
  }
  {  // 0.8x and turned -6 degrees, the frame cutting off the object's left fifth
    cv::Matx23d a = similarity(c, -6.0, 0.8, {0, 0});
    // where the object's left edge lands, then moved so a fifth of its width is off the frame
    const double left = a(0, 0) * box.x + a(0, 1) * c.y + a(0, 2);
    a(0, 2) -= left + 0.2 * 0.8 * box.width;
    run({"0.8x, turned -6 deg, cropped", 2.0, 0.90}, warped_copy(*set, a, set->size, 1.0 / 255, 9),
        [&](int x, int y) { return inverse_at(a, x, y); });
  }
}

// metrics.json says whether the motion was found: on the cat moved, with the
// motion; from the buddha onto the cat (two objects), not, and why.
TEST(SelfMapsMetrics, TransferSaysWhetherTheMotionWasFound) {
  for (const char* name : {"cat", "buddha"})
    if (!std::filesystem::exists(kReal / name / "filenames.txt")) GTEST_SKIP() << "no " << (kReal / name);
  auto cat = io::read_set(kReal / "cat");
  auto buddha = io::read_set(kReal / "buddha");
  ASSERT_TRUE(cat.ok() && buddha.ok());
  pipeline::TransferOptions o;
  o.match.method = Method::combined;
  const cv::Matx23d a(1, 0, 4, 0, 1, 3);
  auto moved = pipeline::transfer(warped_copy(*cat, a, cat->size, 1.0 / 255, 1), *cat, o);
  ASSERT_TRUE(moved.ok()) << moved.message();
  auto m = nlohmann::json::parse(moved->metrics_json);
  ASSERT_TRUE(m.contains("motion"));
  ASSERT_TRUE(m["motion"]["found"].get<bool>()) << m["motion"].dump();
  // source = affine x destination: the shift back by (-4, -3)
  EXPECT_NEAR(m["motion"]["affine"][0][2].get<double>(), -4.0, 0.5);
  EXPECT_NEAR(m["motion"]["affine"][1][2].get<double>(), -3.0, 0.5);
  EXPECT_GT(m["motion"]["share_of_pixels"].get<double>(), 0.5);

  auto other = pipeline::transfer(*cat, *buddha, o);
  ASSERT_TRUE(other.ok()) << other.message();
  m = nlohmann::json::parse(other->metrics_json);
  ASSERT_TRUE(m.contains("motion"));
  EXPECT_FALSE(m["motion"]["found"].get<bool>());
  ASSERT_TRUE(m["motion"].contains("why_not")) << m["motion"].dump();
  EXPECT_FALSE(m["motion"]["why_not"].get<std::string>().empty());
}

// sim-orange is left out: nearly a sphere, a turn about its centre keeps its
// shape, and the motion found keeps the normals but misses the turn (7-12 %
// within 2 px turned; 100 % scaled, shifted or cropped).
INSTANTIATE_TEST_SUITE_P(Objects, SelfMaps,
                         ::testing::Values("cat", "buddha", "chrome", "sim-bull", "sim-cup-dots"),
                         [](const auto& info) {
                           std::string n = info.param;
                           std::replace(n.begin(), n.end(), '-', '_');
                           return n;
                         });

}  // namespace
}  // namespace veneer::match
