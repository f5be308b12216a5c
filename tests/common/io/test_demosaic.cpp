// io/demosaic: Veneer's own demosaicing (Demosaic::mhc) of DNGs written by
// encode_dng, with the photo the mosaic was made from as the oracle and
// LibRaw's AHD beside it.
#include <cmath>
#include <cstdio>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "veneer/io/dng.hpp"
#include "veneer/io/raw.hpp"

namespace veneer {
namespace {

// A band-limited colour photo: smooth shading times a texture of a few
// sinusoids (periods >= 13 px), what a camera behind its low-pass filter sees.
cv::Mat textured(cv::Size size) {
  cv::Mat m(size, CV_32FC3);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) {
      const float shade = 0.25f + 0.6f * float(x + y) / float(size.width + size.height);
      const float t1 = 0.5f + 0.5f * std::sin(x * 0.45f + y * 0.15f), t2 = 0.5f + 0.5f * std::cos(y * 0.35f - x * 0.1f);
      // shading and texture common to the channels (as an object's are),
      // a little colour of its own
      const float lum = shade * (0.4f + 0.6f * t1);
      m.at<cv::Vec3f>(y, x) = lum * cv::Vec3f(0.45f, 0.7f, 0.9f) + 0.05f * t2 * cv::Vec3f(1.f, 0.f, 0.5f);
    }
  return m;
}

double mean_relative_error(const cv::Mat& a, const cv::Mat& b, int border) {
  cv::Rect inner(border, border, a.cols - 2 * border, a.rows - 2 * border);
  return cv::norm(a(inner), b(inner), cv::NORM_L1) / cv::norm(b(inner), cv::NORM_L1);
}

Expected<cv::Mat> decode(const std::string& dng, io::Demosaic d) {
  io::RawOptions o;
  o.demosaic = d;
  return io::decode_raw_linear(dng, o, "photo.dng");
}

TEST(Demosaic, MhcRecoversATexturedPhotoNearlyAsWellAsAhdAndBetterThanBilinear) {
  const cv::Mat photo = textured({160, 120});
  io::DngOptions dng_options;
  dng_options.as_shot_neutral = {0.5, 1.0, 0.8};
  auto dng = io::encode_dng(photo, dng_options);
  ASSERT_TRUE(dng) << dng.message();
  auto mhc = decode(*dng, io::Demosaic::mhc);
  auto ahd = decode(*dng, io::Demosaic::ahd);
  auto bilinear = decode(*dng, io::Demosaic::bilinear);
  ASSERT_TRUE(mhc) << mhc.message();
  ASSERT_TRUE(ahd) << ahd.message();
  ASSERT_TRUE(bilinear) << bilinear.message();
  ASSERT_EQ(mhc->type(), CV_32FC3);
  ASSERT_EQ(mhc->size(), photo.size());
  const double e_mhc = mean_relative_error(*mhc, photo, 4), e_ahd = mean_relative_error(*ahd, photo, 4);
  const double e_bilinear = mean_relative_error(*bilinear, photo, 4);
  EXPECT_LT(e_mhc, 0.03);
  EXPECT_LT(e_mhc, 1.5 * e_ahd) << "AHD " << e_ahd;
  EXPECT_LT(e_mhc, 0.8 * e_bilinear) << "bilinear " << e_bilinear;  // the gradient correction pays
  std::printf("mean relative error: mhc %.4f, ahd %.4f, bilinear %.4f\n", e_mhc, e_ahd, e_bilinear);
  // The borders too (mirrored): no black or wild pixels along the edges.
  EXPECT_LT(mean_relative_error(*mhc, photo, 0), 1.2 * e_mhc);
}

TEST(Demosaic, MhcKeepsLibRawsLevelsWhiteBalanceAndClipping) {
  // Flat patches: any demosaic gives the patch's own value, so the levels
  // (black, white, as-shot white balance, clipping at white) must be LibRaw's.
  cv::Mat photo(64, 96, CV_32FC3);
  photo(cv::Rect(0, 0, 48, 64)).setTo(cv::Scalar(0.2, 0.5, 0.7));   // B, G, R
  photo(cv::Rect(48, 0, 48, 64)).setTo(cv::Scalar(1.0, 0.05, 1.0));  // clipped blue and red
  io::DngOptions dng_options;
  dng_options.as_shot_neutral = {0.6, 1.0, 0.7};
  dng_options.black_level = 1024;
  auto dng = io::encode_dng(photo, dng_options);
  ASSERT_TRUE(dng) << dng.message();
  auto mhc = decode(*dng, io::Demosaic::mhc);
  auto libraw = decode(*dng, io::Demosaic::bilinear);
  ASSERT_TRUE(mhc) << mhc.message();
  ASSERT_TRUE(libraw) << libraw.message();
  for (const cv::Rect patch : {cv::Rect(8, 8, 32, 48), cv::Rect(56, 8, 32, 48)}) {
    const cv::Scalar ours = cv::mean((*mhc)(patch)), theirs = cv::mean((*libraw)(patch)), truth = cv::mean(photo(patch));
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(ours[c], theirs[c], 2e-3) << "channel " << c;
      EXPECT_NEAR(ours[c], truth[c], 3e-3) << "channel " << c;
    }
  }
}

TEST(Demosaic, MhcIsParsedAndNamed) {
  auto d = io::parse_demosaic("mhc");
  ASSERT_TRUE(d);
  EXPECT_EQ(*d, io::Demosaic::mhc);
  EXPECT_STREQ(io::demosaic_name(io::Demosaic::mhc), "mhc");
}

}  // namespace
}  // namespace veneer
