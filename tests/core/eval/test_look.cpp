// The look of a transfer (eval/look.hpp): figures worked out by hand, on
// constructed cases with known answers, and against the checks' own
// ../shared/tools/look.py on a small simulated transfer.
#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <random>

#include "veneer/eval/look.hpp"
#include "veneer/io/imageset.hpp"
#include "veneer/pipeline/transfer.hpp"
#include "veneer/sim/simulator.hpp"

namespace veneer::eval {
namespace {
namespace fs = std::filesystem;

std::vector<cv::Mat> constant_photos(cv::Size size, const std::vector<float>& values) {
  std::vector<cv::Mat> out;
  for (float v : values) out.emplace_back(size, CV_32FC1, cv::Scalar(v));
  return out;
}

TEST(Look, ShadingFiguresByHand) {
  // One pixel, four lamps: reference 1, 2, 4, 8 (median 3), result flat (each
  // ratio 1): |d_l| = ln 3, ln 1.5, ln 4/3, ln 8/3.
  const auto ref = constant_photos({1, 1}, {1, 2, 4, 8});
  const auto res = constant_photos({1, 1}, {5, 5, 5, 5});
  auto s = shading_error(res, ref);
  ASSERT_TRUE(s.ok()) << s.message();
  std::vector<double> e = {std::log(3.0), std::log(1.5), std::log(4.0 / 3), std::log(8.0 / 3)};
  std::sort(e.begin(), e.end());
  EXPECT_EQ(s->samples, 4);
  EXPECT_NEAR(s->mean, (e[0] + e[1] + e[2] + e[3]) / 4, 1e-5);
  EXPECT_NEAR(s->median, (e[1] + e[2]) / 2, 1e-5);            // numpy: halfway between the middle two
  EXPECT_NEAR(s->p90, e[2] + 0.7 * (e[3] - e[2]), 1e-5);       // rank 0.9 * 3 = 2.7
}

TEST(Look, OnlyLitPixelsInTheMaskCount) {
  // Lamp 0 lights the pixel at 1 % of its brightest sample: left out. A second
  // pixel with a wild result is outside the mask.
  std::vector<cv::Mat> ref = constant_photos({2, 1}, {0.01f, 1, 1}), res = constant_photos({2, 1}, {1, 1, 1});
  ref[0].at<float>(0, 1) = 1;
  res[0].at<float>(0, 1) = 100;  // result 100, 20, 20 where the reference is flat: d = ln 5, 0, 0
  res[1].at<float>(0, 1) = 20;
  res[2].at<float>(0, 1) = 20;
  cv::Mat mask(1, 2, CV_8UC1, cv::Scalar(0));
  mask.at<uchar>(0, 0) = 255;
  auto s = shading_error(res, ref, mask);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_EQ(s->samples, 2);  // lamps 1 and 2 at pixel 0
  EXPECT_NEAR(s->mean, 0.0, 1e-6);
  auto all = shading_error(res, ref);  // without the mask the wild pixel counts
  ASSERT_TRUE(all.ok());
  EXPECT_EQ(all->samples, 5);
  EXPECT_NEAR(all->mean, std::log(5.0) / 5, 1e-5);
}

// A simulated set's photos (bull, 7 lamps) as the reference of the constructed cases.
const io::ImageSet& bull() {
  static const io::ImageSet set = [] {
    sim::RenderOptions o;
    o.size = {96, 64};
    auto s = sim::simulate_set("bull", o, io::Role::destination);
    EXPECT_TRUE(s.ok()) << (s.ok() ? "" : s.message());
    return s.ok() ? *s : io::ImageSet{};
  }();
  return set;
}

cv::Mat noise_texture(cv::Size size, unsigned seed, double spread = 0.5) {
  cv::Mat t(size, CV_32FC1);
  cv::RNG rng(seed);
  rng.fill(t, cv::RNG::NORMAL, 0.0, spread);
  cv::exp(t, t);  // positive, log-normal: a texture of fine detail
  return t;
}

TEST(Look, ResultEqualToTheReferenceScoresZero) {
  const io::ImageSet& set = bull();
  ASSERT_FALSE(set.images.empty());
  auto s = shading_error(set.images, set.images, set.truth.mask);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_GT(s->samples, 1000);
  EXPECT_DOUBLE_EQ(s->mean, 0.0);
  EXPECT_DOUBLE_EQ(s->p90, 0.0);
}

TEST(Look, TintedScaledAndTexturedResultScoresZero) {
  // Grey reference; the result is it times a tint, a scale and a texture
  // (per pixel, the same under every lamp): each cancels in the ratios.
  const io::ImageSet& set = bull();
  ASSERT_FALSE(set.images.empty());
  const cv::Mat texture = noise_texture(set.size, 7);
  std::vector<cv::Mat> ref, res;
  for (const cv::Mat& im : set.images) {
    cv::Mat g = look_gray(im), g3, t3, r;
    cv::merge(std::vector<cv::Mat>{g, g, g}, g3);
    ref.push_back(g3);
    cv::merge(std::vector<cv::Mat>{texture, texture, texture}, t3);
    cv::multiply(g3, t3, r);
    res.push_back(r.mul(cv::Scalar(0.3, 0.9, 2.0)) * 3.7);
  }
  auto s = shading_error(res, ref, set.truth.mask);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_GT(s->samples, 1000);
  EXPECT_LT(s->mean, 1e-3);  // eps = 1e-6 against values ~1e-2 leaves ~1e-4 in the darkest lit pixels
  EXPECT_LT(s->p90, 1e-3);
  // and shading from the wrong lamps is no look at all
  std::vector<cv::Mat> shifted(res.begin() + 1, res.end());
  shifted.push_back(res.front());
  auto wrong = shading_error(shifted, ref, set.truth.mask);
  ASSERT_TRUE(wrong.ok());
  EXPECT_GT(wrong->mean, 0.2);
}

TEST(Look, TextureCorrelationTellsTheSourceFromATint) {
  const cv::Size size(120, 90);
  const cv::Mat source = noise_texture(size, 11);
  // A map shifting by (5, 3) over a disc, -1 elsewhere.
  cv::Mat map(size, CV_32FC2, cv::Scalar(-1, -1)), mask(size, CV_8UC1, cv::Scalar(0));
  cv::circle(mask, {60, 45}, 35, cv::Scalar(255), cv::FILLED);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x)
      if (mask.at<uchar>(y, x)) map.at<cv::Vec2f>(y, x) = cv::Vec2f(float(x + 5), float(y + 3));
  // Smooth shading on top of the texture: the high-pass leaves it out.
  cv::Mat shading(size, CV_32FC1);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) shading.at<float>(y, x) = 0.2f + 0.8f * float(x) / float(size.width);
  cv::Mat carried(size, CV_32FC1, cv::Scalar(0));
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x)
      if (mask.at<uchar>(y, x))
        carried.at<float>(y, x) = source.at<float>(std::min(y + 3, size.height - 1), std::min(x + 5, size.width - 1));
  auto good = texture_corr(carried.mul(shading), source, map, mask);
  ASSERT_TRUE(good.ok()) << good.message();
  EXPECT_GT(*good, 0.95);
  // The destination merely tinted: its own texture, nothing of the source's.
  const cv::Mat own = noise_texture(size, 12);
  cv::Mat tinted;
  cv::merge(std::vector<cv::Mat>{own.mul(shading) * 0.5, own.mul(shading) * 0.8, own.mul(shading)}, tinted);
  auto tint = texture_corr(tinted, source, map, mask);
  ASSERT_TRUE(tint.ok()) << tint.message();
  EXPECT_LT(std::abs(*tint), 0.1);
  // A map off by a few pixels carries the texture to the wrong places.
  cv::Mat off = map.clone();
  off.forEach<cv::Vec2f>([](cv::Vec2f& m, const int*) {
    if (m[0] >= 0) m += cv::Vec2f(4, 0);
  });
  auto moved = texture_corr(carried.mul(shading), source, off, mask);
  ASSERT_TRUE(moved.ok());
  EXPECT_LT(std::abs(*moved), 0.1);
}

TEST(Look, BadInputIsRefusedWithTheReason) {
  const auto two = constant_photos({4, 4}, {1, 2}), three = constant_photos({4, 4}, {1, 2, 3});
  auto s = shading_error(two, three);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("2 result pictures for 3 lamps"), std::string::npos) << s.message();
  const auto dark = constant_photos({4, 4}, {0, 0});
  EXPECT_FALSE(shading_error(dark, dark).ok());
  const auto small = constant_photos({3, 4}, {1, 2});
  EXPECT_FALSE(shading_error(small, two).ok());
  auto t = texture_corr(two[0], two[0], cv::Mat(5, 5, CV_32FC2, cv::Scalar(0, 0)));
  EXPECT_FALSE(t.ok());
  auto f = look_folders("/nonexistent/transfer", "/nonexistent/set");
  EXPECT_FALSE(f.ok());
}

// --- against look.py ---

std::string run(const std::string& cmd, int* status) {
  std::string out;
  FILE* p = ::popen(cmd.c_str(), "r");
  if (!p) return out;
  char buf[4096];
  while (size_t n = std::fread(buf, 1, sizeof buf, p)) out.append(buf, n);
  *status = ::pclose(p);
  return out;
}

double json_number(const std::string& json, const std::string& key) {
  const size_t at = json.find("\"" + key + "\":");
  if (at == std::string::npos) return std::nan("");
  return std::strtod(json.c_str() + at + key.size() + 3, nullptr);
}

TEST(Look, EqualsLookPyOnASimulatedTransfer) {
  const fs::path look_py = fs::path(VENEER_SHARED_DATA).parent_path() / "tools" / "look.py";
  if (!fs::exists(look_py)) GTEST_SKIP() << look_py << " not found";
  // Debian's python3 (python3-numpy, python3-opencv): look.py's #! line, not whatever python3 is first on PATH
  const std::string python = fs::exists("/usr/bin/python3") ? "/usr/bin/python3" : "python3";
  int status = -1;
  run(python + " -c 'import numpy, cv2' 2>/dev/null", &status);
  if (status != 0) GTEST_SKIP() << "python3 with numpy and cv2 not available (python3-numpy, python3-opencv)";

  sim::RenderOptions o;
  o.size = {128, 85};
  auto dst = sim::simulate_set("bull", o, io::Role::destination);
  auto src = sim::simulate_set("orange", o, io::Role::source);
  auto truth = sim::simulate_set_with_material("bull", "orange", o, io::Role::destination);
  ASSERT_TRUE(dst.ok() && src.ok() && truth.ok());
  // mask.png: the object only (the background is the destination's own photo in the result)
  truth->mask = truth->truth.mask.clone();
  dst->mask = dst->truth.mask.clone();
  pipeline::TransferOptions options;
  options.truth_normals = true;
  auto r = pipeline::transfer(*dst, *src, options);
  ASSERT_TRUE(r.ok()) << r.message();

  const fs::path dir = fs::temp_directory_path() / ("veneer-look-test-" + std::to_string(::getpid()));
  fs::remove_all(dir);
  ASSERT_TRUE(pipeline::write_transfer(*r, dir / "out").ok());
  ASSERT_TRUE(io::write_set(*src, dir / "source").ok());
  ASSERT_TRUE(io::write_set(*truth, dir / "truth").ok());
  ASSERT_TRUE(io::write_set(*dst, dir / "destination").ok());

  for (const char* reference : {"truth", "destination"}) {
    SCOPED_TRACE(reference);
    auto mine = look_folders(dir / "out", dir / reference, dir / "source");
    ASSERT_TRUE(mine.ok()) << mine.message();
    const std::string theirs = run(python + " " + look_py.string() + " " + (dir / "out").string() + " " +
                                       (dir / reference).string() + " " + (dir / "source").string(),
                                   &status);
    ASSERT_EQ(status, 0) << theirs;
    EXPECT_NEAR(mine->shading.mean, json_number(theirs, "shading_mean"), 1e-3) << theirs;
    EXPECT_NEAR(mine->shading.median, json_number(theirs, "shading_median"), 1e-3) << theirs;
    EXPECT_NEAR(mine->shading.p90, json_number(theirs, "shading_p90"), 1e-3) << theirs;
    EXPECT_NEAR(double(mine->shading.samples), json_number(theirs, "samples"), 0.001 * mine->shading.samples);
    ASSERT_TRUE(mine->texture_corr.has_value());
    EXPECT_NEAR(*mine->texture_corr, json_number(theirs, "texture_corr"), 1e-3) << theirs;
    EXPECT_GT(mine->shading.mean, 0.0);  // a transfer is not perfect: the comparison is not of zeros
  }
  // The in-memory figures agree with the files' (16-bit pictures).
  std::vector<cv::Mat> source_grey;
  for (const cv::Mat& im : src->images) source_grey.push_back(look_gray(im));
  auto files = look_folders(dir / "out", dir / "truth", dir / "source");
  auto memory = shading_error(r->repainted, truth->images, truth->mask);  // the files' mask.png, if any
  auto corr = texture_corr(r->repainted_median, median_image(source_grey), r->map.xy, truth->mask);
  ASSERT_TRUE(files.ok() && memory.ok() && corr.ok());
  EXPECT_NEAR(memory->mean, files->shading.mean, 1e-3);
  EXPECT_NEAR(*corr, *files->texture_corr, 1e-3);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace veneer::eval
