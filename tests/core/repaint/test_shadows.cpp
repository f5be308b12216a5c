// core/repaint: cast shadows from the normals (issue 47, shadows.hpp) --
// heights against an analytic hill, horizons against the analytic shadow of
// a wall and a brute-force march over the hill, and the agreement with the
// simulator's own shadows at the rig's captured lamps.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include <gtest/gtest.h>

#include "veneer/match/object.hpp"
#include "veneer/repaint/shadows.hpp"
#include "veneer/sim/simulator.hpp"

using namespace veneer;

namespace {

// A light `off_axis_deg` from the camera's axis toward image azimuth `azimuth_deg` (image x right, y down).
cv::Vec3d light(double off_axis_deg, double azimuth_deg) {
  const double t = off_axis_deg * CV_PI / 180, a = azimuth_deg * CV_PI / 180;
  return {std::sin(t) * std::cos(a), -std::sin(t) * std::sin(a), std::cos(t)};
}

// A Gaussian hill of `amplitude` px and `sigma` px at (cx, cy): height and normals (rig frame, y up).
struct Hill {
  cv::Mat height, normals, mask;
};
Hill hill(cv::Size size, double amplitude, double sigma, double cx, double cy) {
  Hill h;
  h.height = cv::Mat(size, CV_32FC1);
  h.normals = cv::Mat(size, CV_32FC3);
  h.mask = cv::Mat(size, CV_8UC1, cv::Scalar(255));
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) {
      const double dx = x - cx, dy = y - cy, g = amplitude * std::exp(-(dx * dx + dy * dy) / (2 * sigma * sigma));
      const double gx = -dx / (sigma * sigma) * g, gy = -dy / (sigma * sigma) * g;  // dz/dx, dz/dy (image)
      cv::Vec3d n(-gx, gy, 1);  // the rig's y goes up
      n /= cv::norm(n);
      h.height.at<float>(y, x) = static_cast<float>(g);
      h.normals.at<cv::Vec3f>(y, x) = cv::Vec3f(static_cast<float>(n[0]), static_cast<float>(n[1]), static_cast<float>(n[2]));
    }
  return h;
}

// The oracle: marching from (x, y) toward the light over the analytic height field, in half-pixel steps.
bool marched_shadow(const cv::Mat& height, int x, int y, const cv::Vec3d& l) {
  const double r = std::hypot(l[0], l[1]);
  const double dx = l[0] / r, dy = -l[1] / r, rise = l[2] / r;  // height gained per pixel toward the light
  const double h0 = height.at<float>(y, x);
  for (double t = 2; ; t += 0.5) {
    const double px = x + dx * t, py = y + dy * t;
    if (px < 0 || py < 0 || px > height.cols - 1 || py > height.rows - 1) return false;
    if (height.at<float>(static_cast<int>(py + 0.5), static_cast<int>(px + 0.5)) > h0 + rise * t) return true;
  }
}

}  // namespace

// The heights integrated from a hill's normals are the hill (less a constant).
TEST(Shadows, HeightFromNormalsRecoversAnAnalyticHill) {
  const Hill h = hill({200, 160}, 30, 25, 100, 80);
  auto z = repaint::height_from_normals(h.normals, h.mask);
  ASSERT_TRUE(z) << z.message();
  const double offset = cv::mean(*z - h.height)[0];
  double worst = 0;
  for (int y = 0; y < 160; ++y)
    for (int x = 0; x < 200; ++x) worst = std::max(worst, std::abs(z->at<float>(y, x) - offset - h.height.at<float>(y, x)));
  std::printf("hill of 30 px: heights within %.3f px\n", worst);
  EXPECT_LT(worst, 0.05);  // measured 0.008
}

// A wall of height H px shadows the ground beside it over H / tan(elevation), on the side away from the light
// and nowhere on the side toward it.
TEST(Shadows, AWallCastsItsAnalyticShadow) {
  const cv::Size size(240, 60);
  cv::Mat height(size, CV_32FC1, cv::Scalar(0)), mask(size, CV_8UC1, cv::Scalar(255));
  const float H = 20;
  height.colRange(150, 160).setTo(H);
  repaint::ShadowOptions o;
  o.min_visibility = 0;
  auto map = repaint::ShadowMap::from_height(height, mask, 1, o);
  ASSERT_TRUE(map) << map.message();
  for (double elevation : {30.0, 45.0, 60.0}) {
    const cv::Mat v = map->visibility(light(90 - elevation, 0));  // the light to the wall's right: image +x
    const double length = H / std::tan(elevation * CV_PI / 180);
    for (int y : {10, 30, 50}) {
      for (int d = 1; d <= 100; ++d) {
        const int x = 150 - d;
        if (x < 0) break;
        // the ramp of the softness (4 deg) about the edge: 2 deg either way
        const double inside = H / std::tan((elevation + 2.5) * CV_PI / 180);
        const double outside = H / std::tan((elevation - 2.5) * CV_PI / 180);
        if (d < inside - 1) {
          EXPECT_LT(v.at<float>(y, x), 0.05f) << "elevation " << elevation << ", " << d << " px";
        }
        if (d > outside + 1) {
          EXPECT_GT(v.at<float>(y, x), 0.95f) << "elevation " << elevation << ", " << d << " px";
        }
      }
      // the other side, and the light from the left: no shadow beside the wall on its left
      for (int x = 161; x < size.width; ++x) EXPECT_GT(v.at<float>(y, x), 0.95f);
      const cv::Mat w = map->visibility(light(90 - elevation, 180));
      for (int x = 0; x < 150; ++x) EXPECT_GT(w.at<float>(y, x), 0.95f);
    }
    std::printf("elevation %.0f deg: shadow %.1f px long\n", elevation, length);
  }
}

// From the hill's normals alone (heights integrated, horizons swept), the cast shadow of a low light is the one
// a march over the true heights finds.
TEST(Shadows, AHillsShadowFromItsNormalsIsTheMarchedOne) {
  const Hill h = hill({240, 200}, 40, 22, 120, 100);
  repaint::ShadowOptions o;
  o.min_visibility = 0;
  auto map = repaint::ShadowMap::make(h.normals, h.mask, o);
  ASSERT_TRUE(map) << map.message();
  for (const auto& [off, az] : {std::pair{70.0, 0.0}, {65.0, 135.0}, {75.0, 250.0}}) {
    const cv::Vec3d l = light(off, az);
    const cv::Mat v = map->visibility(l);
    long both = 0, either = 0;
    for (int y = 0; y < 200; ++y)
      for (int x = 0; x < 240; ++x) {
        const cv::Vec3f n = h.normals.at<cv::Vec3f>(y, x);
        if (n.dot(cv::Vec3f(static_cast<float>(l[0]), static_cast<float>(l[1]), static_cast<float>(l[2]))) < 0.1f)
          continue;  // the attached shadow is the shading's
        const bool truth = marched_shadow(h.height, x, y, l), ours = v.at<float>(y, x) < 0.5f;
        both += truth && ours, either += truth || ours;
      }
    const double iou = static_cast<double>(both) / std::max<long>(1, either);
    std::printf("light %.0f deg off the axis, azimuth %.0f: IoU %.3f over %ld px\n", off, az, iou, either);
    EXPECT_GT(either, 300);
    EXPECT_GT(iou, 0.95);  // measured 0.979-0.991
  }
}

// On the simulated bull (as a transfer prepares it: segmentation, photometric stereo), at each of the rig's lamps
// the shadow map told the photos' shadows agrees with the simulator's cast shadows (rendered with and without
// them, noise-free; lightpath.py's test: facing the lamp, below 0.35 of the unoccluded light).
TEST(Shadows, AgreesWithTheSimulatorsShadowsAtTheCapturedLamps) {
  sim::RenderOptions o;
  o.size = {512, 340};
  o.noise_sigma = 0.005;
  auto set = sim::simulate_set("bull", o, io::Role::destination);
  ASSERT_TRUE(set) << set.message();
  auto object = match::prepare_object(*set, false);
  ASSERT_TRUE(object) << object.message();
  const cv::Mat& normals = object->view.normals;
  const cv::Mat& mask = object->view.mask;
  std::vector<cv::Vec3d> lamps;
  for (const io::Light& l : set->lights) lamps.push_back(l.direction);
  auto seen = repaint::photo_shadows(object->view.images, normals, mask, lamps);
  ASSERT_TRUE(seen) << seen.message();
  auto map = repaint::ShadowMap::make(normals, mask);
  ASSERT_TRUE(map) << map.message();
  repaint::ShadowMap told = *map;
  ASSERT_TRUE(told.observe(lamps, seen->shadowed, seen->lit));
  auto scene = sim::make_scene("bull", o);
  ASSERT_TRUE(scene);
  sim::RenderOptions clean = o, open = o;
  clean.noise_sigma = open.noise_sigma = 0;
  open.cast_shadows = false;
  const auto rig = sim::thesis_rig();
  long both = 0, told_only = 0, truth_only = 0, geo_both = 0, geo_only = 0;
  for (size_t k = 0; k < lamps.size(); ++k) {
    const cv::Mat lit = sim::render(**scene, {rig[k]}, clean), unoccluded = sim::render(**scene, {rig[k]}, open);
    const cv::Mat v = told.visibility(lamps[k]), g = map->visibility(lamps[k]);
    const cv::Vec3f l(static_cast<float>(lamps[k][0]), static_cast<float>(lamps[k][1]), static_cast<float>(lamps[k][2]));
    for (int y = 0; y < mask.rows; ++y)
      for (int x = 0; x < mask.cols; ++x) {
        if (!mask.at<uchar>(y, x) || !set->truth.mask.at<uchar>(y, x)) continue;
        if (set->truth.normals.at<cv::Vec3f>(y, x).dot(l) <= 0.2f || normals.at<cv::Vec3f>(y, x).dot(l) <= 0.2f) continue;
        const cv::Vec3f a = lit.at<cv::Vec3f>(y, x), b = unoccluded.at<cv::Vec3f>(y, x);
        const float ga = (a[0] + a[1] + a[2]) / 3, gb = (b[0] + b[1] + b[2]) / 3;
        if (gb <= 1e-4f) continue;
        const bool truth = ga < 0.35f * gb, ours = v.at<float>(y, x) < 0.5f, geo = g.at<float>(y, x) < 0.5f;
        both += truth && ours, told_only += ours && !truth, truth_only += truth && !ours;
        geo_both += truth && geo, geo_only += geo && !truth;
      }
  }
  const double iou = static_cast<double>(both) / std::max<long>(1, both + told_only + truth_only);
  const double precision = static_cast<double>(both) / std::max<long>(1, both + told_only);
  const double geo_precision = static_cast<double>(geo_both) / std::max<long>(1, geo_both + geo_only);
  std::printf("bull 512x340, the rig's 7 lamps: IoU %.3f, precision %.3f, recall %.3f (%ld px in the truth's shadows); "
              "the geometry alone: precision %.3f, recall %.3f\n",
              iou, precision, static_cast<double>(both) / std::max<long>(1, both + truth_only), both + truth_only,
              geo_precision, static_cast<double>(geo_both) / std::max<long>(1, both + truth_only));
  EXPECT_GT(both + truth_only, 1000);
  EXPECT_GT(iou, 0.85);            // measured 0.910
  EXPECT_GT(precision, 0.98);      // measured 0.999
  EXPECT_GT(geo_precision, 0.75);  // what the heights alone call shadow mostly is (measured 0.824)
}

TEST(Shadows, BadInputIsRefusedNamingIt) {
  const cv::Mat normals(10, 10, CV_32FC3, cv::Scalar(0, 0, 1)), mask(10, 10, CV_8UC1, cv::Scalar(255));
  auto wrong = repaint::ShadowMap::make(cv::Mat(10, 10, CV_32FC1), mask);
  ASSERT_FALSE(wrong);
  EXPECT_NE(wrong.message().find("normals"), std::string::npos) << wrong.message();
  auto empty = repaint::ShadowMap::make(normals, cv::Mat(10, 10, CV_8UC1, cv::Scalar(0)));
  ASSERT_FALSE(empty);
  EXPECT_NE(empty.message().find("empty"), std::string::npos) << empty.message();
  repaint::ShadowOptions o;
  o.azimuths = 3;
  auto bad = repaint::ShadowMap::make(normals, mask, o);
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.message().find("azimuths"), std::string::npos) << bad.message();
  auto map = repaint::ShadowMap::make(normals, mask);
  ASSERT_TRUE(map);
  EXPECT_FALSE(map->observe({{0, 0, 1}}, {}, {}));
}
