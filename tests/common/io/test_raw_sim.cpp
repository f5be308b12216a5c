// The RAW path on the simulator's renders: a set written with DNG files
// (add_dng_raw_files) reads back through LibRaw to within 1 % of the linear
// render, and photometric stereo gets the truth's normals from it as well as
// from the render itself (issue 29's "what must show").
#include <cmath>
#include <cstdio>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "test_util.hpp"
#include "veneer/io/dng.hpp"
#include "veneer/io/imageset.hpp"
#include "veneer/ps/photometric_stereo.hpp"
#include "veneer/sim/simulator.hpp"

namespace veneer {
namespace {

using test::Scratch;

io::ImageSet simulated(const std::string& scene, double noise, cv::Size size = {512, 340}) {
  sim::RenderOptions o;
  o.size = size;
  o.noise_sigma = noise;
  o.seed = 3;
  o.scale = 2.5;  // the object fills the frame
  o.camera_optics();  // as the rig's camera twin renders
  auto set = sim::simulate_set(scene, o, io::Role::destination);
  EXPECT_TRUE(set) << set.message();
  return set ? std::move(set).value() : io::ImageSet{};
}

// Over `mask`: sum |a - b| / sum |b| counting, per pixel, only the channel the
// RGGB mosaic measured there (what a RAW file holds; the other two are interpolated).
double measured_channel_error(const cv::Mat& a, const cv::Mat& b, const cv::Mat& mask) {
  double diff = 0, sum = 0;
  for (int y = 0; y < a.rows; ++y)
    for (int x = 0; x < a.cols; ++x) {
      if (!mask.at<uchar>(y, x)) continue;
      const int c = (y % 2 == 0) ? (x % 2 == 0 ? 2 : 1) : (x % 2 == 0 ? 1 : 0);  // BGR index
      diff += std::abs(a.at<cv::Vec3f>(y, x)[c] - b.at<cv::Vec3f>(y, x)[c]);
      sum += std::abs(b.at<cv::Vec3f>(y, x)[c]);
    }
  return diff / sum;
}

// sum |a - b| / sum |b| over `mask` (all channels).
double relative_error(const cv::Mat& a, const cv::Mat& b, const cv::Mat& mask) {
  return cv::norm(a, b, cv::NORM_L1, mask) / cv::norm(b, cv::NORM_L1, mask);
}

// Mean angle between normals and the truth over the truth mask, degrees.
double mean_angle_deg(const cv::Mat& normals, const io::Truth& truth) {
  double sum = 0;
  int n = 0;
  for (int y = 0; y < normals.rows; ++y)
    for (int x = 0; x < normals.cols; ++x) {
      if (!truth.mask.at<uchar>(y, x)) continue;
      const cv::Vec3f a = normals.at<cv::Vec3f>(y, x), b = truth.normals.at<cv::Vec3f>(y, x);
      const double d = std::clamp(static_cast<double>(a.dot(b)) / (cv::norm(a) * cv::norm(b) + 1e-12), -1.0, 1.0);
      sum += std::acos(d) * 180.0 / CV_PI;
      ++n;
    }
  return n ? sum / n : 180.0;
}

// Every photo of a DNG set decodes to the render within 1 %: exactly (to the
// 14-bit quantization) at the channel each pixel measured, and in full RGB
// too (1.5 % with the default MHC, 1 % with LibRaw's DCB): the simulator's camera optics (sim::RenderOptions::camera_optics)
// band-limit the image as a real sensor's filter does, so demosaicing can
// interpolate the missing colours. (Point-sampled, the orange's pixel-scale
// texture left them 3.2 % off.)
TEST(RawSim, DngSetDecodesToTheLinearRender) {
  for (const std::string scene : {"bull", "orange"}) {
    SCOPED_TRACE(scene);
    io::ImageSet rendered = simulated(scene, 0.0);
    ASSERT_FALSE(rendered.images.empty());
    io::ImageSet with_raw = rendered;
    ASSERT_TRUE(io::add_dng_raw_files(with_raw));
    Scratch dir;
    ASSERT_TRUE(io::write_set(with_raw, dir / "set"));
    auto raw = io::read_set(dir / "set");
    ASSERT_TRUE(raw) << raw.message();
    EXPECT_EQ(raw->photos_from, "raw");
    ASSERT_EQ(raw->size, rendered.size);
    const cv::Mat object = rendered.truth.mask;
    double worst_measured = 0, worst_rgb = 0;
    for (size_t i = 0; i < rendered.images.size(); ++i) {
      worst_measured = std::max(worst_measured, measured_channel_error(raw->images[i], rendered.images[i], object));
      worst_rgb = std::max(worst_rgb, relative_error(raw->images[i], rendered.images[i], object));
    }
    worst_measured = std::max(worst_measured, measured_channel_error(raw->ambient, rendered.ambient, object));
    std::printf("%s: DNG -> RAW path (%s) vs the render, worst photo: %.3f %% measured channel, %.2f %% full RGB\n",
                scene.c_str(), io::demosaic_name(io::RawOptions{}.demosaic), 100 * worst_measured, 100 * worst_rgb);
    EXPECT_LT(worst_measured, 0.01);
    // the default (MHC, issue 42) measured 0.67 % (bull) and 1.30 % (orange: its pixel-scale texture);
    // LibRaw's DCB, the default before, stays within 1 %
    EXPECT_LT(worst_rgb, 0.015);
    io::ReadOptions dcb;
    dcb.raw.demosaic = io::Demosaic::dcb;
    auto by_dcb = io::read_set(dir / "set", dcb);
    ASSERT_TRUE(by_dcb) << by_dcb.message();
    for (size_t i = 0; i < rendered.images.size(); ++i)
      EXPECT_LT(relative_error(by_dcb->images[i], rendered.images[i], object), 0.01) << "DCB, photo " << i;

    // The developed photos (PNG) when asked, and a set without RAW files.
    io::ReadOptions developed;
    developed.photos = io::PhotoSource::developed;
    auto png = io::read_set(dir / "set", developed);
    ASSERT_TRUE(png) << png.message();
    EXPECT_EQ(png->photos_from, "png");
    EXPECT_LT(relative_error(png->images[0], rendered.images[0], object), 1e-3);
    ASSERT_TRUE(io::write_set(rendered, dir / "plain"));
    auto plain = io::read_set(dir / "plain");
    ASSERT_TRUE(plain) << plain.message();
    EXPECT_EQ(plain->photos_from, "png");
    io::ReadOptions want_raw;
    want_raw.photos = io::PhotoSource::raw;
    auto refused = io::read_set(dir / "plain", want_raw);
    ASSERT_FALSE(refused);
    EXPECT_NE(refused.message().find("RAW"), std::string::npos) << refused.message();
  }
}

// Read in half floats (ReadOptions::half_floats, issue 42), every photo and
// the ambient frame is the float read rounded to half floats, bit for bit:
// RAW through our MHC (each row narrowed as it is demosaiced), RAW through
// LibRaw's own pipeline (DCB), and the developed PNGs. The oracle is the
// float read, converted whole by OpenCV.
TEST(RawSim, HalfFloatReadIsTheFloatReadRounded) {
  io::ImageSet rendered = simulated("orange", 0.002, {256, 170});
  ASSERT_FALSE(rendered.images.empty());
  ASSERT_FALSE(rendered.ambient.empty());
  ASSERT_TRUE(io::add_dng_raw_files(rendered));
  Scratch dir;
  ASSERT_TRUE(io::write_set(rendered, dir / "set"));
  io::ReadOptions dcb, developed;
  dcb.raw.demosaic = io::Demosaic::dcb;
  developed.photos = io::PhotoSource::developed;
  for (const auto& [name, options] : {std::pair{"mhc", io::ReadOptions{}}, {"dcb", dcb}, {"png", developed}}) {
    SCOPED_TRACE(name);
    auto as_float = io::read_set(dir / "set", options);
    ASSERT_TRUE(as_float) << as_float.message();
    io::ReadOptions half = options;
    half.half_floats = true;
    auto as_half = io::read_set(dir / "set", half);
    ASSERT_TRUE(as_half) << as_half.message();
    ASSERT_EQ(as_half->images.size(), as_float->images.size());
    std::vector<std::pair<cv::Mat, cv::Mat>> frames{{as_half->ambient, as_float->ambient}};
    for (size_t i = 0; i < as_half->images.size(); ++i) frames.emplace_back(as_half->images[i], as_float->images[i]);
    for (const auto& [h, f] : frames) {
      ASSERT_EQ(h.type(), CV_16FC3);
      ASSERT_EQ(f.type(), CV_32FC3);
      cv::Mat rounded, wide_h, wide_rounded;
      f.convertTo(rounded, CV_16FC3);
      h.convertTo(wide_h, CV_32F);
      rounded.convertTo(wide_rounded, CV_32F);
      EXPECT_EQ(cv::norm(wide_h, wide_rounded, cv::NORM_INF), 0.0);
    }
  }
}

// Normals from the RAW path against the truth, next to normals from the
// render itself (photometric stereo called as it is). Measured (noise 0.002,
// DCB): orange 2.09 deg from the render, 2.58 from the full-size RAW; bull
// 5.56 / 5.63. The orange's gap is its pixel-scale texture that demosaicing
// must still interpolate (0.16 deg at 1024x680, bench_raw); point-sampled
// renders with AHD gave 0.93 here. The half-size read (the user's fast
// option) is compared with the render at that size.
TEST(RawSim, NormalsFromDngMatchTheTruthAsFromTheRender) {
  for (const std::string scene : {"orange", "bull"}) {
    SCOPED_TRACE(scene);
    const double noise = 0.002;  // the rig twin's
    io::ImageSet rendered = simulated(scene, noise);
    io::ImageSet with_raw = rendered;
    ASSERT_TRUE(io::add_dng_raw_files(with_raw));
    Scratch dir;
    ASSERT_TRUE(io::write_set(with_raw, dir / "set"));
    auto raw = io::read_set(dir / "set");
    ASSERT_TRUE(raw) << raw.message();
    EXPECT_EQ(raw->photos_from, "raw");
    auto from_raw = ps::photometric_stereo(*raw, raw->truth.mask);
    auto from_render = ps::photometric_stereo(rendered, rendered.truth.mask);
    ASSERT_TRUE(from_raw) << from_raw.message();
    ASSERT_TRUE(from_render) << from_render.message();
    const double e_raw = mean_angle_deg(from_raw->normals, raw->truth);
    const double e_render = mean_angle_deg(from_render->normals, rendered.truth);

    io::ReadOptions half;
    half.raw.half_size = true;
    auto small = io::read_set(dir / "set", half);
    ASSERT_TRUE(small) << small.message();
    EXPECT_EQ(small->photos_from, "raw-half");
    io::ImageSet small_render = simulated(scene, noise, small->size);
    EXPECT_NEAR(small->camera.focal_px, small_render.camera.focal_px, 1e-6);
    auto from_small = ps::photometric_stereo(*small, small->truth.mask);
    auto from_small_render = ps::photometric_stereo(small_render, small_render.truth.mask);
    ASSERT_TRUE(from_small) << from_small.message();
    ASSERT_TRUE(from_small_render) << from_small_render.message();
    const double e_small = mean_angle_deg(from_small->normals, small->truth);
    const double e_small_render = mean_angle_deg(from_small_render->normals, small_render.truth);
    std::printf("%s normals, mean angle to the truth: %dx%d render %.2f deg, full-size RAW (%s) %.2f deg; "
                "%dx%d render %.2f deg, half-size RAW %.2f deg\n",
                scene.c_str(), rendered.size.width, rendered.size.height, e_render,
                io::demosaic_name(io::RawOptions{}.demosaic), e_raw, small->size.width, small->size.height, e_small_render,
                e_small);
    EXPECT_LT(e_raw - e_render, 0.6);
    EXPECT_LT(e_small - e_small_render, 1.0);
  }
}

}  // namespace
}  // namespace veneer
