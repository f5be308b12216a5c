// core/RealMaps.*: the default correspondence on real photos
// (../shared/data/real/): self-maps of an object onto its own copy scaled or
// moved, where the true map is known, and a cross-object pair.
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <random>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <nlohmann/json.hpp>
#include <unistd.h>

#include "veneer/eval/metrics.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/io/imageset.hpp"
#include "veneer/pipeline/transfer.hpp"

namespace veneer::match {
namespace {

using namespace veneer::eval;
using namespace veneer::pipeline;

const std::filesystem::path kReal = std::filesystem::path(VENEER_SHARED_DATA) / "real";

// A copy of `set` moved by (dx, dy) px (edges replicated) with Gaussian noise of `sigma` added to the photos.
io::ImageSet moved_copy(const io::ImageSet& set, double dx, double dy, double sigma, unsigned seed) {
  io::ImageSet out = set;
  cv::Mat shift = (cv::Mat_<double>(2, 3) << 1, 0, dx, 0, 1, dy);
  cv::RNG rng(seed);
  auto move = [&](cv::Mat& m, int interp) {
    cv::Mat t;
    cv::warpAffine(m, t, shift, m.size(), interp, cv::BORDER_REPLICATE);
    m = t;
  };
  for (auto& im : out.images) {
    move(im, cv::INTER_LINEAR);
    cv::Mat noise(im.size(), im.type());
    rng.fill(noise, cv::RNG::NORMAL, 0, sigma);
    im += noise;
  }
  if (!out.ambient.empty()) move(out.ambient, cv::INTER_LINEAR);
  if (!out.mask.empty()) move(out.mask, cv::INTER_NEAREST);
  return out;
}

struct SelfMapScore {
  double within = 0;  // share of mapped destination object pixels within `tolerance` px of the truth
  double coverage = 0;
  double coherence = 0;
};

// Destination pixel (x, y) truly shows source pixel truth(x, y).
SelfMapScore score(const Map& map, const cv::Mat& dst_mask, const cv::Mat& src_mask,
                   const std::function<cv::Point2d(int, int)>& truth, double tolerance) {
  long n = 0, ok = 0;
  for (int y = 0; y < map.xy.rows; ++y)
    for (int x = 0; x < map.xy.cols; ++x) {
      if (!dst_mask.at<uchar>(y, x)) continue;
      const cv::Point2d t = truth(x, y);
      // Pixels whose true partner is off the source object cannot be right.
      const int tx = static_cast<int>(std::lround(t.x)), ty = static_cast<int>(std::lround(t.y));
      if (tx < 0 || ty < 0 || tx >= src_mask.cols || ty >= src_mask.rows || !src_mask.at<uchar>(ty, tx)) continue;
      ++n;
      const cv::Vec2f m = map.xy.at<cv::Vec2f>(y, x);
      if (m[0] >= 0 && std::hypot(m[0] - t.x, m[1] - t.y) <= tolerance) ++ok;
    }
  if (const char* dir = std::getenv("VENEER_DEBUG_DIR")) {
    cv::Mat pic(map.xy.size(), CV_8UC3, cv::Scalar(0, 0, 0));
    for (int y = 0; y < map.xy.rows; ++y)
      for (int x = 0; x < map.xy.cols; ++x) {
        if (!dst_mask.at<uchar>(y, x)) continue;
        const cv::Point2d t = truth(x, y);
        const cv::Vec2f m = map.xy.at<cv::Vec2f>(y, x);
        double e = std::hypot(m[0] - t.x, m[1] - t.y);
        pic.at<cv::Vec3b>(y, x) = e <= tolerance ? cv::Vec3b(0, 160, 0) : e <= 4 * tolerance ? cv::Vec3b(0, 200, 255) : cv::Vec3b(0, 0, 255);
      }
    static int k = 0;
    cv::imwrite(std::string(dir) + "/selfmap_error_" + std::to_string(k++) + ".png", pic);
  }
  Quality q = evaluate(map, dst_mask, src_mask);
  return {n ? static_cast<double>(ok) / n : 0.0, q.coverage, q.coherence};
}

class RealMaps : public ::testing::TestWithParam<std::string> {};

TEST_P(RealMaps, ScaledAndMovedSelfMapsFindTheMotion) {
  const auto folder = kReal / GetParam();
  if (!std::filesystem::exists(folder / "filenames.txt")) GTEST_SKIP() << "no " << folder;
  auto set = io::read_set(folder);
  ASSERT_TRUE(set.ok()) << set.message();
  auto src = prepare_object(*set, false);
  ASSERT_TRUE(src.ok()) << src.message();
  MatchOptions o;
  o.method = Method::combined;

  // Scaled 0.8x: source pixel = (x + 0.5) / 0.8 - 0.5.
  {
    io::ImageSet small = *set;
    scale_set(small, 0.8);
    const double sx = static_cast<double>(set->size.width) / small.size.width;
    const double sy = static_cast<double>(set->size.height) / small.size.height;
    auto dst = prepare_object(small, false);
    ASSERT_TRUE(dst.ok()) << dst.message();
    auto t0 = std::chrono::steady_clock::now();
    auto map = compute_map(dst->view, src->view, o);
    double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    ASSERT_TRUE(map.ok()) << map.message();
    auto s = score(*map, dst->view.mask, src->view.mask,
                   [&](int x, int y) { return cv::Point2d((x + 0.5) * sx - 0.5, (y + 0.5) * sy - 0.5); }, 2.0);
    std::printf("%s scaled 0.8: within 2 px %.1f %%, coverage %.1f %%, coherence %.3f, %.0f ms\n", GetParam().c_str(),
                100 * s.within, 100 * s.coverage, s.coherence, ms);
    EXPECT_GE(s.within, 0.90);
    EXPECT_GE(s.coverage, 0.995);
  }
  // Moved by (3, -2) px with noise of 2/255.
  {
    io::ImageSet moved = moved_copy(*set, 3, -2, 2.0 / 255, 7);
    auto dst = prepare_object(moved, false);
    ASSERT_TRUE(dst.ok()) << dst.message();
    auto map = compute_map(dst->view, src->view, o);
    ASSERT_TRUE(map.ok()) << map.message();
    auto s = score(*map, dst->view.mask, src->view.mask, [&](int x, int y) { return cv::Point2d(x - 3, y + 2); }, 1.5);
    std::printf("%s moved (3, -2) + noise: within 1.5 px %.1f %%, coverage %.1f %%, coherence %.3f\n",
                GetParam().c_str(), 100 * s.within, 100 * s.coverage, s.coherence);
    EXPECT_GE(s.within, 0.97);
    EXPECT_GE(s.coverage, 0.995);
  }
}

// The repainted photos are written as the sets' photos are (linear, same
// scale): on a self-map each lamp's result averages what its source photo does.
TEST_P(RealMaps, RepaintedPhotosKeepTheInputsEncodingAndExposure) {
  const auto folder = kReal / GetParam();
  if (!std::filesystem::exists(folder / "filenames.txt")) GTEST_SKIP() << "no " << folder;
  auto set = io::read_set(folder);
  ASSERT_TRUE(set.ok()) << set.message();
  io::ImageSet moved = moved_copy(*set, 2, 1, 0.0, 3);
  TransferOptions o;
  o.match.method = Method::combined;
  auto r = transfer(moved, *set, o);
  ASSERT_TRUE(r.ok()) << r.message();
  const auto out = std::filesystem::temp_directory_path() / ("veneer-realmaps-" + std::to_string(::getpid()));
  ASSERT_TRUE(write_transfer(*r, out).ok());
  auto seg = prepare_object(*set, false);
  ASSERT_TRUE(seg.ok());
  for (size_t i : {size_t{0}, set->images.size() / 2}) {
    char name[64];
    std::snprintf(name, sizeof name, "result_light_%02zu.png", i);
    auto result = io::read_linear_image(out / name);
    ASSERT_TRUE(result.ok()) << result.message();
    const double src_mean = cv::mean(set->images[i], seg->view.mask)[1];
    cv::Mat moved_mask;
    const cv::Mat shift = (cv::Mat_<double>(2, 3) << 1, 0, 2, 0, 1, 1);
    cv::warpAffine(seg->view.mask, moved_mask, shift, seg->view.mask.size(),
                   cv::INTER_NEAREST);
    const double res_mean = cv::mean(*result, moved_mask)[1];
    EXPECT_NEAR(res_mean, src_mean, 0.05 * src_mean + 1.0 / 255) << name;
  }
  auto metrics = nlohmann::json::parse(r->metrics_json);
  EXPECT_NE(metrics["pictures"].dump().find("linear 16-bit"), std::string::npos);
  // Real sets get quality figures, measured without truth.
  ASSERT_TRUE(metrics.contains("quality"));
  EXPECT_GE(metrics["quality"]["coverage"].get<double>(), 0.995);
  EXPECT_NE(metrics["quality"]["measured_against"].get<std::string>().find("no truth"), std::string::npos);
  std::filesystem::remove_all(out);
}

// A textured Lambertian ellipsoid rendered under `like`'s own lamps
// (distant directions and intensities), the same size of frame, with its
// normals as the truth: a simulated object for a cross-object pair.
io::ImageSet ellipsoid_under(const io::ImageSet& like, unsigned seed) {
  io::ImageSet out;
  out.id = "ellipsoid";
  out.object = "ellipsoid";
  out.size = like.size;
  out.lights = like.lights;
  for (auto& l : out.lights) l.position_m.reset();
  const cv::Size size = like.size;
  const double cx = size.width * 0.5, cy = size.height * 0.52, ax = size.width * 0.22, ay = size.height * 0.38,
               az = std::min(ax, ay);
  cv::RNG rng(seed);
  out.truth.normals = cv::Mat(size, CV_32FC3, cv::Scalar::all(0));
  out.truth.mask = cv::Mat(size, CV_8UC1, cv::Scalar(0));
  for (size_t i = 0; i < out.lights.size(); ++i) out.images.emplace_back(size, CV_32FC3, cv::Scalar::all(0));
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) {
      const double u = (x - cx) / ax, v = -(y - cy) / ay, r2 = u * u + v * v;
      if (r2 >= 1) continue;
      const double w = std::sqrt(1 - r2);
      cv::Vec3d n(u / ax, v / ay, w / az);
      n /= cv::norm(n);
      out.truth.normals.at<cv::Vec3f>(y, x) = cv::Vec3f(n);
      out.truth.mask.at<uchar>(y, x) = 255;
      // Texture: blotches and stripes in two colours.
      const double t = 0.5 + 0.25 * std::sin(x * 0.21 + std::sin(y * 0.05) * 3) + 0.25 * std::sin(y * 0.17);
      const cv::Vec3f albedo(static_cast<float>(0.25 + 0.4 * t), static_cast<float>(0.35 + 0.2 * (1 - t)), 0.6f);
      for (size_t i = 0; i < out.lights.size(); ++i) {
        const double shade = std::max(0.0, n.dot(cv::normalize(out.lights[i].direction)));
        const cv::Vec3f e = out.lights[i].intensity;  // [r,g,b]
        cv::Vec3f& px = out.images[i].at<cv::Vec3f>(y, x);
        for (int c = 0; c < 3; ++c)
          px[c] = std::clamp(static_cast<float>(albedo[c] * shade * e[2 - c] * 0.8 + rng.gaussian(0.004)), 0.0f, 1.0f);
      }
    }
  out.mask = out.truth.mask.clone();
  return out;
}

// Between different objects: the real photos onto a simulated object lit by
// the same lamps (and the other way round). Measured with the photometric
// stereo normals (no truth on the real side).
TEST_P(RealMaps, ARealObjectAndASimulatedOneUnderItsLamps) {
  const auto folder = kReal / GetParam();
  if (!std::filesystem::exists(folder / "filenames.txt")) GTEST_SKIP() << "no " << folder;
  auto real = io::read_set(folder);
  ASSERT_TRUE(real.ok()) << real.message();
  const io::ImageSet sim = ellipsoid_under(*real, 5);
  auto a = prepare_object(*real, false);
  auto b = prepare_object(sim, false);
  ASSERT_TRUE(a.ok() && b.ok());
  MatchOptions o;
  o.method = Method::combined;
  for (int dir = 0; dir < 2; ++dir) {
    const ObjectView& dst = dir == 0 ? a->view : b->view;
    const ObjectView& src = dir == 0 ? b->view : a->view;
    auto map = compute_map(dst, src, o);
    ASSERT_TRUE(map.ok()) << map.message();
    Quality q = evaluate(*map, dst.mask, src.mask, dst.normals, src.normals);
    std::printf("%s %s: coverage %.1f %%, coherence %.3f, normal agreement %.2f deg mean / %.2f p95\n",
                dir == 0 ? GetParam().c_str() : "ellipsoid", dir == 0 ? "<- ellipsoid" : ("<- " + GetParam()).c_str(),
                100 * q.coverage, q.coherence, *q.normal_mean_deg, *q.normal_p95_deg);
    EXPECT_GE(q.coverage, 0.995);
    EXPECT_EQ(q.background_hits, 0);
    EXPECT_LE(*q.normal_mean_deg, 3.0);
    EXPECT_GE(q.coherence, 0.7);
  }
}

INSTANTIATE_TEST_SUITE_P(Objects, RealMaps, ::testing::Values("cat"));

}  // namespace
}  // namespace veneer::match
