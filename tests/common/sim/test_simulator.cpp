// The scene simulator: analytic shading, shadows, falloff, truth, placement,
// determinism, and that every scene renders a plausible object.
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <numeric>
#include <set>
#include <tuple>

#include <unistd.h>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "veneer/io/image_io.hpp"
#include "veneer/io/imageset.hpp"
#include "veneer/sim/simulator.hpp"

namespace veneer::sim {
namespace {

// Odd sizes put the principal point on a pixel centre: (128, 85).
const cv::Size kSmall{257, 171};
const double kRigIntensity = 1.0 + 0.47 * 0.47;  // a rig lamp's radiant intensity (irradiance 1 at the origin)

RenderOptions small_options() {
  RenderOptions o;
  o.size = kSmall;
  o.noise_sigma = 0;
  return o;
}

std::shared_ptr<const Scene> scene_or_die(const std::string& name, const RenderOptions& o) {
  auto s = make_scene(name, o);
  EXPECT_TRUE(s.ok()) << (s.ok() ? "" : s.message());
  return s.ok() ? *s : nullptr;
}

bool same_bytes(const cv::Mat& a, const cv::Mat& b) {
  if (a.size() != b.size() || a.type() != b.type()) return false;
  cv::Mat ca = a.clone(), cb = b.clone();
  return std::memcmp(ca.data, cb.data, ca.total() * ca.elemSize()) == 0;
}

Lamp lamp_at(cv::Vec3d p) {
  Lamp l;
  l.position_m = p;
  return l;
}

// The camera ray through pixel (x, y) for the default framing (focal = 2 x width).
cv::Vec3d pixel_ray(const cv::Size& size, double x, double y) {
  double f = 2.0 * size.width, cx = (size.width - 1) * 0.5, cy = (size.height - 1) * 0.5;
  return cv::normalize(cv::Vec3d((x - cx) / f, -(y - cy) / f, -1.0));
}

TEST(Simulator, ThesisRigHasSevenLampsOnTheRing) {
  auto lamps = thesis_rig();
  ASSERT_EQ(lamps.size(), 7u);
  for (const auto& l : lamps) {
    EXPECT_NEAR(l.position_m[2], 1.0, 1e-12);
    EXPECT_NEAR(std::hypot(l.position_m[0], l.position_m[1]), 0.47, 1e-12);
    EXPECT_FALSE(std::abs(l.position_m[0]) < 1e-9 && l.position_m[1] < 0) << "the bottom socket is empty";
  }
  // documented order: top, then clockwise as seen in the picture (top-right, right, ...)
  EXPECT_NEAR(lamps[0].position_m[0], 0.0, 1e-12);
  EXPECT_GT(lamps[0].position_m[1], 0.4);
  EXPECT_GT(lamps[1].position_m[0], 0.3);
  EXPECT_GT(lamps[1].position_m[1], 0.3);
  EXPECT_NEAR(lamps[2].position_m[0], 0.47, 1e-12);
  EXPECT_NEAR(lamps[5].position_m[0], -0.47, 1e-12);
}

TEST(Simulator, OptionsAreChecked) {
  RenderOptions o = small_options();
  EXPECT_TRUE(o.check().ok());
  o.exposure = 0;
  EXPECT_FALSE(o.check().ok());
  o = small_options();
  o.noise_sigma = -1;
  EXPECT_FALSE(o.check().ok());
  o = small_options();
  o.size = {0, 10};
  EXPECT_FALSE(o.check().ok());
  o = small_options();
  o.scale = 0;
  EXPECT_FALSE(o.check().ok());
  auto s = make_scene("teapot", small_options());
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("teapot"), std::string::npos);
  EXPECT_NE(s.message().find("sphere-gray"), std::string::npos) << "the error lists the known scenes";
}

TEST(Simulator, LambertShadingMatchesTheAnalyticValue) {
  RenderOptions o = small_options();
  auto scene = scene_or_die("sphere-gray", o);
  ASSERT_TRUE(scene);
  for (int li : {0, 2, 5}) {
    Lamp lamp = thesis_rig()[static_cast<size_t>(li)];
    cv::Mat img = render(*scene, {lamp}, o);
    ASSERT_EQ(img.type(), CV_32FC3);
    int checked = 0;
    for (auto [px, py] : {std::pair{128, 85}, {120, 75}, {140, 92}, {112, 85}, {144, 80}, {128, 68}, {118, 98}}) {
      // the documented sphere-gray: radius 4 cm at the origin, albedo 0.6, matte
      cv::Vec3d d = pixel_ray(kSmall, px, py), o3(0, 0, 1);
      double b = o3.dot(d), c = o3.dot(o3) - 0.04 * 0.04, disc = b * b - c;
      ASSERT_GT(disc, 0) << "pixel " << px << "," << py << " should see the sphere";
      cv::Vec3d p = o3 + d * (-b - std::sqrt(disc));
      cv::Vec3d n = p / 0.04;
      cv::Vec3d L = lamp.position_m - p;
      double r2 = L.dot(L);
      double ndl = n.dot(L / std::sqrt(r2));
      double expected = ndl > 0 ? 0.6 * kRigIntensity / r2 * ndl : 0.0;
      cv::Vec3f v = img.at<cv::Vec3f>(py, px);
      for (int ch = 0; ch < 3; ++ch) EXPECT_NEAR(v[ch], expected, 2e-4 + 1e-3 * expected) << "lamp " << li << " pixel " << px << "," << py;
      ++checked;
    }
    EXPECT_EQ(checked, 7);
  }
}

TEST(Simulator, FalloffIsInverseSquare) {
  RenderOptions o = small_options();
  o.exposure = 0.1;  // the near lamp must not clip
  auto scene = scene_or_die("sphere-gray", o);
  ASSERT_TRUE(scene);
  // the pixel at the principal point sees the sphere's front pole p = (0, 0, 0.04), n = +z;
  // lamps on the axis at 0.46 m and 0.92 m from it: same direction, twice the distance
  cv::Mat near_img = render(*scene, {lamp_at({0, 0, 0.50})}, o);
  cv::Mat far_img = render(*scene, {lamp_at({0, 0, 0.96})}, o);
  double near_v = near_img.at<cv::Vec3f>(85, 128)[1], far_v = far_img.at<cv::Vec3f>(85, 128)[1];
  ASSERT_GT(far_v, 0.05);
  ASSERT_LT(near_v, 0.9);
  EXPECT_NEAR(near_v / far_v, 4.0, 4e-3);
  // and the brightness channel of the lamp scales it linearly
  Lamp dim = lamp_at({0, 0, 0.96});
  dim.brightness = 0.5;
  EXPECT_NEAR(render(*scene, {dim}, o).at<cv::Vec3f>(85, 128)[1] / far_v, 0.5, 1e-4);
}

TEST(Simulator, CastAndAttachedShadows) {
  RenderOptions o = small_options();
  auto scene = scene_or_die("sphere-gray", o);
  ASSERT_TRUE(scene);
  const auto rig = thesis_rig();
  cv::Mat right = render(*scene, {rig[2]}, o), left = render(*scene, {rig[5]}, o);
  io::Truth truth = render_truth(*scene, o);
  // the table just left of the silhouette (x ~ -4.8 cm): in the sphere's shadow
  // under the right lamp, lit under the left one
  const int tx = 104, ty = 85;
  ASSERT_EQ(truth.mask.at<uint8_t>(ty, tx), 0);
  float lit = left.at<cv::Vec3f>(ty, tx)[1], shadowed = right.at<cv::Vec3f>(ty, tx)[1];
  EXPECT_GT(lit, 0.01f) << "the table is dark but not black";
  EXPECT_LT(shadowed, 0.05f * lit);
  // the far side of the table (right of the sphere) is lit by the right lamp
  EXPECT_GT(right.at<cv::Vec3f>(ty, 257 - 1 - 4)[1], 0.01f);
  // attached shadow: the sphere's left limb faces away from the right lamp
  const int ax = 108;  // inside the silhouette (radius ~20.6 px), left limb
  ASSERT_EQ(truth.mask.at<uint8_t>(ty, ax), 255);
  EXPECT_LT(truth.normals.at<cv::Vec3f>(ty, ax)[0], -0.9f);
  EXPECT_EQ(right.at<cv::Vec3f>(ty, ax)[1], 0.0f);
  EXPECT_GT(left.at<cv::Vec3f>(ty, ax)[1], 0.2f);
  // without cast shadows the table point is lit by the right lamp as the left
  // one lights it (mirror images), the sphere's limb stays in its attached shadow,
  // and nothing the lamp reached before changes
  o.cast_shadows = false;
  const cv::Mat unblocked = render(*scene, {rig[2]}, o);
  EXPECT_GT(unblocked.at<cv::Vec3f>(ty, tx)[1], 0.5f * lit);
  EXPECT_EQ(unblocked.at<cv::Vec3f>(ty, ax)[1], 0.0f);
  int changed = 0, darker = 0, lit_changed = 0;
  for (int y = 0; y < right.rows; ++y)
    for (int x = 0; x < right.cols; ++x) {
      const float a = right.at<cv::Vec3f>(y, x)[1], b = unblocked.at<cv::Vec3f>(y, x)[1];
      changed += a != b;
      darker += b < a;
      lit_changed += a > 0 && a != b;
    }
  EXPECT_GT(changed, 50) << "the sphere's shadow on the table";
  EXPECT_EQ(darker, 0);
  EXPECT_EQ(lit_changed, 0);
}

TEST(Simulator, ConcaveSceneCastsShadowsOnItself) {
  // the bull: some object pixels lit (n.l > 0) by a lamp are nevertheless dark
  // under it because another part of the statue blocks the lamp
  RenderOptions o = small_options();
  auto scene = scene_or_die("bull", o);
  ASSERT_TRUE(scene);
  io::Truth truth = render_truth(*scene, o);
  int cast = 0;
  for (size_t li = 0; li < 7; ++li) {
    Lamp lamp = thesis_rig()[li];
    cv::Mat img = render(*scene, {lamp}, o);
    for (int y = 0; y < kSmall.height; ++y)
      for (int x = 0; x < kSmall.width; ++x) {
        if (!truth.mask.at<uint8_t>(y, x)) continue;
        cv::Vec3f n = truth.normals.at<cv::Vec3f>(y, x);
        // approximate the lamp direction from the object centre; require a clear margin
        cv::Vec3d l = cv::normalize(lamp.position_m);
        if (n.dot(cv::Vec3f(l)) > 0.4 && img.at<cv::Vec3f>(y, x)[1] == 0.0f) ++cast;
      }
  }
  EXPECT_GT(cast, 20) << "no cast shadows in the bull";
}

TEST(Simulator, SpecularHighlightSaturatesOnTheGlossySphere) {
  RenderOptions o = small_options();
  auto scene = scene_or_die("sphere-red-gloss", o);
  ASSERT_TRUE(scene);
  cv::Mat img = render(*scene, {thesis_rig()[0]}, o);  // lamp at the top
  std::vector<cv::Mat> ch;
  cv::split(img, ch);
  double maxv;
  cv::Point at;
  cv::minMaxLoc(ch[1], nullptr, &maxv, nullptr, &at);  // green: only the white lobe makes it bright
  EXPECT_GT(maxv, 0.3);
  EXPECT_LT(at.y, 85) << "the highlight of the top lamp is on the upper half";
  EXPECT_EQ(cv::countNonZero(ch[2] >= 1.0f) > 0, true) << "red clips at full scale like a sensor";
  // the matte grey sphere has no lobe: its green maximum is the Lambert value
  auto gray = scene_or_die("sphere-gray", o);
  cv::Mat g = render(*gray, {thesis_rig()[0]}, o);
  cv::split(g, ch);
  cv::minMaxLoc(ch[1], nullptr, &maxv);
  EXPECT_LT(maxv, 0.6 * kRigIntensity / (0.9 * 0.9) + 1e-3);
}

// The scenes are what their names promise (the properties the thesis chose them for).
TEST(Simulator, ScenesHaveTheirCharacter) {
  RenderOptions o = small_options();
  auto truth_of = [&](const std::string& name) {
    auto scene = scene_or_die(name, o);
    return scene ? render_truth(*scene, o) : io::Truth{};
  };
  auto distinct_albedos = [](const io::Truth& t) {
    std::set<std::tuple<int, int, int>> colours;
    for (int y = 0; y < t.mask.rows; ++y)
      for (int x = 0; x < t.mask.cols; ++x)
        if (t.mask.at<uint8_t>(y, x)) {
          cv::Vec3f a = t.albedo.at<cv::Vec3f>(y, x);
          colours.insert({static_cast<int>(a[0] * 8), static_cast<int>(a[1] * 8), static_cast<int>(a[2] * 8)});
        }
    return colours.size();
  };
  // blocks: few normal orientations (each brick shows the same three faces)
  {
    io::Truth t = truth_of("blocks");
    std::vector<cv::Vec3f> dirs;
    int pixels = 0, explained = 0;
    for (int y = 0; y < t.mask.rows; ++y)
      for (int x = 0; x < t.mask.cols; ++x) {
        if (!t.mask.at<uint8_t>(y, x)) continue;
        ++pixels;
        cv::Vec3f n = t.normals.at<cv::Vec3f>(y, x);
        bool known = false;
        for (const auto& d : dirs) known = known || n.dot(d) > 0.999f;
        if (known) ++explained;
        else if (dirs.size() < 3) dirs.push_back(n), ++explained;
      }
    EXPECT_EQ(explained, pixels) << "every block pixel faces one of three directions";
    EXPECT_EQ(dirs.size(), 3u);
    EXPECT_GE(distinct_albedos(t), 4u) << "bricks of four colours";
  }
  // two-spheres: two separate objects of different colours
  {
    io::Truth t = truth_of("two-spheres");
    cv::Mat labels;
    EXPECT_EQ(cv::connectedComponents(t.mask, labels) - 1, 2);
    EXPECT_EQ(distinct_albedos(t), 2u);
  }
  // the cups: the same shape; one plain, one dotted in four colours
  {
    io::Truth white = truth_of("cup-white"), dots = truth_of("cup-dots");
    EXPECT_EQ(cv::countNonZero(white.mask != dots.mask), 0);
    EXPECT_EQ(distinct_albedos(white), 1u);
    EXPECT_GE(distinct_albedos(dots), 5u);
  }
  // uniform spheres for measuring; textured fruit and stone
  EXPECT_EQ(distinct_albedos(truth_of("sphere-gray")), 1u);
  EXPECT_EQ(distinct_albedos(truth_of("sphere-red-gloss")), 1u);
  for (const char* name : {"orange", "apple", "banana", "stone"}) EXPECT_GE(distinct_albedos(truth_of(name)), 4u) << name;
  // the stone is rough: its normals deviate from a smoothed version of themselves
  {
    io::Truth t = truth_of("stone"), s = truth_of("sphere-gray");
    auto roughness = [](const io::Truth& tr) {
      cv::Mat blurred;
      cv::GaussianBlur(tr.normals, blurred, cv::Size(7, 7), 0);
      cv::Mat inner;
      cv::erode(tr.mask, inner, cv::Mat(), cv::Point(-1, -1), 4);
      double sum = 0;
      int n = 0;
      for (int y = 0; y < tr.mask.rows; ++y)
        for (int x = 0; x < tr.mask.cols; ++x)
          if (inner.at<uint8_t>(y, x)) {
            cv::Vec3f a = tr.normals.at<cv::Vec3f>(y, x), b = blurred.at<cv::Vec3f>(y, x);
            sum += std::acos(std::clamp(static_cast<double>(a.dot(b) / cv::norm(b)), -1.0, 1.0));
            ++n;
          }
      return sum / n * 180 / CV_PI;
    };
    EXPECT_GT(roughness(t), 3 * roughness(s));
  }
}

TEST(Simulator, TruthNormalsAreUnitInsideAndZeroOutside) {
  RenderOptions o = small_options();
  for (const auto& name : scene_names()) {
    EXPECT_FALSE(scene_description(name).empty()) << name;
    auto scene = scene_or_die(name, o);
    ASSERT_TRUE(scene);
    io::Truth t = render_truth(*scene, o);
    ASSERT_EQ(t.normals.type(), CV_32FC3);
    ASSERT_EQ(t.mask.type(), CV_8UC1);
    ASSERT_EQ(t.albedo.type(), CV_32FC3);
    ASSERT_EQ(t.depth.type(), CV_32FC1);
    int bad = 0;
    for (int y = 0; y < kSmall.height; ++y)
      for (int x = 0; x < kSmall.width; ++x) {
        cv::Vec3f n = t.normals.at<cv::Vec3f>(y, x);
        float depth = t.depth.at<float>(y, x);
        if (t.mask.at<uint8_t>(y, x)) {
          cv::Vec3d d = pixel_ray(kSmall, x, y);
          if (std::abs(cv::norm(n) - 1.0) > 1e-4 || cv::Vec3d(n).dot(d) >= 0 || depth < 0.8 || depth > 1.2) ++bad;
        } else if (n != cv::Vec3f(0, 0, 0) || depth != 0.0f || t.albedo.at<cv::Vec3f>(y, x) != cv::Vec3f(0, 0, 0)) {
          ++bad;
        }
      }
    EXPECT_EQ(bad, 0) << name;
  }
}

TEST(Simulator, EverySceneRendersAPlausibleObject) {
  RenderOptions o = small_options();
  o.noise_sigma = 0.005;
  const double area = kSmall.area();
  for (const auto& name : scene_names()) {
    auto set = simulate_set(name, o, io::Role::destination);
    ASSERT_TRUE(set.ok()) << name << ": " << (set.ok() ? "" : set.message());
    EXPECT_TRUE(io::validate(*set).ok()) << name;
    const cv::Mat& mask = set->truth.mask;
    int pixels = cv::countNonZero(mask);
    EXPECT_GT(pixels, 0.02 * area) << name;
    EXPECT_LT(pixels, 0.40 * area) << name;
    // summed over lamps, the object is far brighter than the dark table around it
    cv::Mat sum = cv::Mat::zeros(kSmall, CV_32FC3);
    for (const auto& im : set->images) sum += im;
    cv::Mat grey;
    cv::cvtColor(sum, grey, cv::COLOR_BGR2GRAY);
    double obj = cv::mean(grey, mask)[0], bg = cv::mean(grey, mask == 0)[0];
    EXPECT_GT(bg, 0.02) << name << ": background must not be black";
    EXPECT_GT(obj, 3.0 * bg) << name;
    for (const auto& im : set->images) {
      double lo, hi;
      cv::minMaxLoc(im.reshape(1), &lo, &hi);
      EXPECT_GE(lo, 0.0);
      EXPECT_LE(hi, 1.0);
      EXPECT_TRUE(cv::checkRange(im)) << name;
    }
  }
}

TEST(Simulator, SameSeedSameBytesAcrossThreadCounts) {
  RenderOptions o = small_options();
  o.noise_sigma = 0.01;
  o.seed = 42;
  o.threads = 1;
  auto a = simulate_set("orange", o);
  o.threads = 2;
  auto b = simulate_set("orange", o);
  ASSERT_TRUE(a.ok() && b.ok());
  ASSERT_EQ(a->images.size(), b->images.size());
  for (size_t i = 0; i < a->images.size(); ++i) EXPECT_TRUE(same_bytes(a->images[i], b->images[i])) << "image " << i;
  EXPECT_TRUE(same_bytes(a->ambient, b->ambient));
  EXPECT_TRUE(same_bytes(a->truth.normals, b->truth.normals));

  o.seed = 43;
  auto c = simulate_set("orange", o);
  ASSERT_TRUE(c.ok());
  EXPECT_FALSE(same_bytes(a->images[0], c->images[0]));
  // different shots of one set get independent noise
  auto scene = scene_or_die("sphere-gray", o);
  RenderOptions s0 = o, s1 = o;
  s1.shot = 1;
  EXPECT_FALSE(same_bytes(render(*scene, {}, s0), render(*scene, {}, s1)));
}

TEST(Simulator, NoiseHasTheRequestedSpread) {
  RenderOptions o = small_options();
  o.noise_sigma = 0.02;
  o.ambient = 0.5;  // the sphere at 0.3: far from clipping at 0 or 1
  auto scene = scene_or_die("sphere-gray", o);
  ASSERT_TRUE(scene);
  cv::Mat noisy = render(*scene, {}, o);
  RenderOptions clean = o;
  clean.noise_sigma = 0;
  cv::Mat diff = noisy - render(*scene, {}, clean);
  cv::Mat mask = render_truth(*scene, o).mask;
  std::vector<cv::Mat> ch;
  cv::split(diff, ch);
  cv::Scalar mean, stddev;
  cv::meanStdDev(ch[1], mean, stddev, mask);
  EXPECT_NEAR(mean[0], 0.0, 0.001);
  EXPECT_NEAR(stddev[0], 0.02, 0.001);
}

cv::Point2d centroid(const cv::Mat& mask) {
  cv::Moments m = cv::moments(mask, true);
  return {m.m10 / m.m00, m.m01 / m.m00};
}

TEST(Simulator, OffsetMovesTheObject) {
  RenderOptions o = small_options();
  auto centred = scene_or_die("sphere-gray", o);
  ASSERT_TRUE(centred);
  cv::Point2d c0 = centroid(render_truth(*centred, o).mask);
  EXPECT_NEAR(c0.x, 128, 0.5);
  EXPECT_NEAR(c0.y, 85, 0.5);
  o.offset_m = {0.10, 0, 0};
  auto moved = scene_or_die("sphere-gray", o);
  ASSERT_TRUE(moved);
  io::Truth t = render_truth(*moved, o);
  cv::Point2d c1 = centroid(t.mask);
  // 10 cm at 1 m with f = 2 x 257 px: about 51 px to the right
  EXPECT_NEAR(c1.x - c0.x, 0.10 * 2 * 257, 2.0);
  EXPECT_NEAR(c1.y, c0.y, 0.5);
  o.offset_m = {0, 0.05, 0};
  auto up = scene_or_die("sphere-gray", o);
  EXPECT_LT(centroid(render_truth(*up, o).mask).y, c0.y - 20) << "up in the rig frame is up in the picture";
}

TEST(Simulator, ScaleGrowsTheObject) {
  RenderOptions o = small_options();
  auto base = scene_or_die("orange", o);
  ASSERT_TRUE(base);
  int n1 = cv::countNonZero(render_truth(*base, o).mask);
  o.scale = 2.0;
  auto big = scene_or_die("orange", o);
  ASSERT_TRUE(big);
  int n2 = cv::countNonZero(render_truth(*big, o).mask);
  EXPECT_GT(n2, 3.8 * n1);
  EXPECT_LT(n2, 5.0 * n1);  // scaled about its back, it also comes nearer the camera
}

TEST(Simulator, SimulatedSetDescribesTheRig) {
  RenderOptions o = small_options();
  o.exposure = 0.8;
  auto set = simulate_set("sphere-gray", o, io::Role::source);
  ASSERT_TRUE(set.ok());
  EXPECT_EQ(set->role, io::Role::source);
  EXPECT_EQ(set->scene, "sphere-gray");
  ASSERT_EQ(set->lights.size(), 7u);
  ASSERT_FALSE(set->ambient.empty());
  EXPECT_NEAR(set->camera.focal_px, 2.0 * 257, 1e-9);
  EXPECT_NEAR(set->camera.cx, 128, 1e-9);
  EXPECT_NEAR(set->camera.cy, 85, 1e-9);
  for (size_t i = 0; i < 7; ++i) {
    const io::Light& l = set->lights[i];
    ASSERT_TRUE(l.position_m.has_value());
    EXPECT_NEAR(cv::norm(l.direction), 1.0, 1e-12);
    EXPECT_NEAR(cv::norm(l.direction - *l.position_m / cv::norm(*l.position_m)), 0.0, 1e-12);
    // irradiance at the origin in image units: the exposure is folded in
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(l.intensity[c], 0.8, 1e-6);
  }
  // the recorded intensity predicts the pixel: near-light model at the front pole
  const io::Light& l0 = set->lights[0];
  cv::Vec3d p(0, 0, 0.04), L = *l0.position_m - p;
  double expected = 0.6 * l0.intensity[1] * l0.position_m->dot(*l0.position_m) / L.dot(L) * (L[2] / cv::norm(L));
  EXPECT_NEAR(set->images[0].at<cv::Vec3f>(85, 128)[1], expected, 1e-4);
  // truth albedo is the material's, in BGR
  cv::Vec3f a = set->truth.albedo.at<cv::Vec3f>(85, 128);
  EXPECT_NEAR(a[0], 0.6f, 1e-6);
  EXPECT_NEAR(a[2], 0.6f, 1e-6);
}

TEST(Simulator, RedIsRedInBgr) {
  RenderOptions o = small_options();
  auto scene = scene_or_die("sphere-red-gloss", o);
  ASSERT_TRUE(scene);
  cv::Vec3f v = render(*scene, {thesis_rig()[3]}, o).at<cv::Vec3f>(85, 128);
  EXPECT_GT(v[2], 5 * v[0]);  // channel 2 (R) far above channel 0 (B)
  cv::Vec3f a = render_truth(*scene, o).albedo.at<cv::Vec3f>(85, 128);
  EXPECT_NEAR(a[2], 0.70f, 1e-6);
  EXPECT_NEAR(a[0], 0.05f, 1e-6);
}

TEST(Simulator, ShapeInAnotherMaterialKeepsItsNormals) {
  RenderOptions o = small_options();
  auto bull = scene_or_die("bull", o);
  auto red_bull = make_scene_with_material("bull", "sphere-red-gloss", o);
  ASSERT_TRUE(bull && red_bull.ok());
  io::Truth a = render_truth(*bull, o), b = render_truth(**red_bull, o);
  EXPECT_EQ(cv::countNonZero(a.mask != b.mask), 0);
  EXPECT_EQ(cv::norm(a.normals, b.normals, cv::NORM_INF), 0.0);
  cv::Scalar mean = cv::mean(b.albedo, b.mask);
  EXPECT_NEAR(mean[2], 0.70, 1e-6);  // R
  EXPECT_NEAR(mean[0], 0.05, 1e-6);  // B
  EXPECT_FALSE(make_scene_with_material("bull", "teapot", o).ok());
  EXPECT_FALSE(make_scene_with_material("teapot", "bull", o).ok());
}

TEST(Simulator, ASetInAnotherMaterialIsTheShapeInThatMaterialUnderTheSameLamps) {
  RenderOptions o = small_options();
  auto bull = simulate_set("bull", o);
  auto red_bull = simulate_set_with_material("bull", "sphere-red-gloss", o);
  ASSERT_TRUE(bull.ok() && red_bull.ok());
  // the shape's outline, normals, lamps and pose
  EXPECT_EQ(cv::countNonZero(bull->truth.mask != red_bull->truth.mask), 0);
  EXPECT_EQ(cv::norm(bull->truth.normals, red_bull->truth.normals, cv::NORM_INF), 0.0);
  ASSERT_EQ(red_bull->lights.size(), bull->lights.size());
  for (size_t i = 0; i < bull->lights.size(); ++i)
    EXPECT_EQ(red_bull->lights[i].position_m, bull->lights[i].position_m);
  EXPECT_EQ(red_bull->scene, "bull");
  EXPECT_EQ(red_bull->object, "bull-in-sphere-red-gloss");
  // the material's albedo, in the truth and in the photos: red, where the bull's hide is brown
  const cv::Scalar albedo = cv::mean(red_bull->truth.albedo, red_bull->truth.mask);
  EXPECT_NEAR(albedo[2], 0.70, 1e-6);
  EXPECT_NEAR(albedo[0], 0.05, 1e-6);
  const cv::Scalar lit = cv::mean(red_bull->images[0], red_bull->truth.mask);
  const cv::Scalar own = cv::mean(bull->images[0], bull->truth.mask);
  EXPECT_GT(lit[2], 4 * lit[0]);
  EXPECT_LT(own[2], 4 * own[0]);
  // rendered as the material scene's own set is, same bytes for the same options
  auto again = simulate_set_with_material("bull", "sphere-red-gloss", o);
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(cv::norm(again->images[3], red_bull->images[3], cv::NORM_INF), 0.0);
  EXPECT_FALSE(simulate_set_with_material("bull", "teapot", o).ok());
  EXPECT_FALSE(simulate_set_with_material("teapot", "orange", o).ok());
}

TEST(Simulator, ProgressIsReportedAndCancelStops) {
  RenderOptions o = small_options();
  std::vector<double> fractions;
  Progress progress;
  progress.on_progress = [&](double f, const std::string&) { fractions.push_back(f); };
  ASSERT_TRUE(simulate_set("orange", o, io::Role::destination, progress).ok());
  ASSERT_GE(fractions.size(), 8u);
  EXPECT_TRUE(std::is_sorted(fractions.begin(), fractions.end()));
  EXPECT_EQ(fractions.back(), 1.0);
  std::atomic<bool> cancel{true};
  Progress cancelled;
  cancelled.cancel = &cancel;
  auto set = simulate_set("orange", o, io::Role::destination, cancelled);
  ASSERT_FALSE(set.ok());
  EXPECT_NE(set.message().find("cancelled"), std::string::npos);
}

TEST(Simulator, WrittenSetReadsBackWithItsTruth) {
  RenderOptions o = small_options();
  o.noise_sigma = 0.005;
  auto set = simulate_set("cup-dots", o, io::Role::destination);
  ASSERT_TRUE(set.ok());
  auto dir = std::filesystem::temp_directory_path() / ("veneer-sim-test-" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  ASSERT_TRUE(io::write_set(*set, dir).ok());
  auto back = io::read_set(dir);
  ASSERT_TRUE(back.ok()) << (back.ok() ? "" : back.message());
  EXPECT_EQ(back->lights.size(), 7u);
  ASSERT_TRUE(back->truth.present());
  EXPECT_EQ(cv::countNonZero(back->truth.mask != set->truth.mask), 0);
  EXPECT_LT(cv::norm(back->truth.normals, set->truth.normals, cv::NORM_INF), 1e-6);
  EXPECT_LT(cv::norm(back->images[3], set->images[3], cv::NORM_INF), 1.0 / 65535 + 1e-6);
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace veneer::sim
