// Reduced decodes (io/reduced.hpp) against the full ones: the binned Bayer
// mosaic of a simulated DNG equals LibRaw's full decode area-averaged, a JPEG
// decoded small in the DCT is linear, and a set read at the live size keeps
// its truth, mask and intrinsics in step with its photos.
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "veneer/io/dng.hpp"
#include "veneer/io/imageset.hpp"
#include "veneer/io/raw.hpp"
#include "veneer/io/reduced.hpp"
#include "veneer/sim/simulator.hpp"

namespace veneer {
namespace {
namespace fs = std::filesystem;

struct Scratch {
  fs::path dir;
  Scratch() {
    dir = fs::temp_directory_path() / ("veneer-test-reduced-" + std::to_string(::getpid()) + "-" +
                                       ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir);
    fs::create_directories(dir);
  }
  ~Scratch() { fs::remove_all(dir); }
};

io::ImageSet simulated(const std::string& scene, cv::Size size, double noise = 0.0) {
  sim::RenderOptions o;
  o.size = size;
  o.noise_sigma = noise;
  o.seed = 5;
  o.scale = 2.5;
  o.camera_optics();
  auto set = sim::simulate_set(scene, o, io::Role::destination);
  EXPECT_TRUE(set) << set.message();
  return set ? std::move(set).value() : io::ImageSet{};
}

// sum |a - b| / sum |b| per channel over `mask` (CV_8UC1, nonzero = counted).
cv::Vec3d relative_error(const cv::Mat& a, const cv::Mat& b, const cv::Mat& mask) {
  cv::Vec3d diff(0, 0, 0), sum(0, 0, 0);
  for (int y = 0; y < a.rows; ++y)
    for (int x = 0; x < a.cols; ++x) {
      if (!mask.empty() && !mask.at<uchar>(y, x)) continue;
      const auto& p = a.at<cv::Vec3f>(y, x);
      const auto& q = b.at<cv::Vec3f>(y, x);
      for (int c = 0; c < 3; ++c) {
        diff[c] += std::abs(p[c] - q[c]);
        sum[c] += std::abs(q[c]);
      }
    }
  for (int c = 0; c < 3; ++c) diff[c] /= std::max(sum[c], 1e-12);
  return diff;
}

// A smooth linear photo (shading ramps, soft colour blobs): what LibRaw's
// demosaicing reconstructs exactly, so its full decode is the reference.
cv::Mat smooth_photo(cv::Size size) {
  cv::Mat m(size, CV_32FC3);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) {
      const float u = static_cast<float>(x) / size.width, v = static_cast<float>(y) / size.height;
      m.at<cv::Vec3f>(y, x) = cv::Vec3f(0.05f + 0.3f * u * v, 0.1f + 0.5f * v + 0.1f * std::sin(6 * u),
                                        0.08f + 0.6f * u * (1 - 0.5f * v) + 0.05f * std::cos(5 * v));
    }
  return m;
}

TEST(Reduced, BinnedMosaicEqualsTheFullDecodeAreaAveraged) {
  const cv::Mat photo = smooth_photo({512, 344});
  auto dng = io::encode_dng(photo);
  ASSERT_TRUE(dng) << dng.message();
  io::RawOptions full_options;
  full_options.demosaic = io::Demosaic::ahd;
  auto full = io::decode_raw_linear(*dng, full_options, "full");
  ASSERT_TRUE(full) << full.message();
  ASSERT_EQ(full->size(), photo.size());
  for (int factor : {2, 4, 8}) {
    SCOPED_TRACE("factor " + std::to_string(factor));
    auto binned = io::decode_raw_binned(*dng, factor, "binned");
    ASSERT_TRUE(binned) << binned.message();
    ASSERT_EQ(binned->size(), cv::Size(512 / factor, 344 / factor));
    cv::Mat averaged;
    cv::resize(*full, averaged, binned->size(), 0, 0, cv::INTER_AREA);
    const cv::Vec3d e = relative_error(*binned, averaged, {});
    for (int c = 0; c < 3; ++c) EXPECT_LT(e[c], 0.01) << "channel " << c;
    // the scale is the photo's (the DNG holds it: black, white, white balance, colour matrix undone)
    cv::Mat render;
    cv::resize(photo, render, binned->size(), 0, 0, cv::INTER_AREA);
    const cv::Vec3d r = relative_error(*binned, render, {});
    for (int c = 0; c < 3; ++c) EXPECT_LT(r[c], 0.01) << "channel " << c << " against the photo";
  }
  // the factor picked for a width: the largest even one still at least that wide
  int factor = 0;
  auto to_width = io::decode_raw_binned_to_width(*dng, 100, "to width", &factor);
  ASSERT_TRUE(to_width) << to_width.message();
  EXPECT_EQ(factor, 4);  // 512 / 4 = 128 >= 100, 512 / 6 = 85 < 100
  EXPECT_EQ(to_width->cols, 128);
}

TEST(Reduced, BinnedMosaicOfATexturedRenderIsTheRenderAreaAveraged) {
  // The simulator's orange (dimpled texture, an outline): no demosaicing
  // between, so the binned photo is the render's area average.
  io::ImageSet set = simulated("orange", {512, 344});
  ASSERT_FALSE(set.images.empty());
  const cv::Mat& photo = set.images[2];
  auto dng = io::encode_dng(photo);
  ASSERT_TRUE(dng) << dng.message();
  for (int factor : {2, 4}) {
    SCOPED_TRACE("factor " + std::to_string(factor));
    auto binned = io::decode_raw_binned(*dng, factor, "binned");
    ASSERT_TRUE(binned) << binned.message();
    cv::Mat render, mask;
    cv::resize(photo, render, binned->size(), 0, 0, cv::INTER_AREA);
    cv::resize(set.truth.mask, mask, binned->size(), 0, 0, cv::INTER_AREA);
    mask = mask == 255;
    cv::erode(mask, mask, cv::Mat());
    ASSERT_GT(cv::countNonZero(mask), 100);
    const cv::Vec3d r = relative_error(*binned, render, mask);
    for (int c = 0; c < 3; ++c) EXPECT_LT(r[c], 0.04) << "channel " << c;
  }
}

TEST(Reduced, BinningRefusesWhatIsNotABayerRaw) {
  auto odd = io::decode_raw_binned(std::string(100, 'x'), 3, "odd.dng");
  ASSERT_FALSE(odd);
  EXPECT_NE(odd.message().find("not even"), std::string::npos) << odd.message();
  auto junk = io::decode_raw_binned(std::string(4096, 'x'), 2, "junk.dng");
  ASSERT_FALSE(junk);
  EXPECT_NE(junk.message().find("junk.dng"), std::string::npos) << junk.message();
  // the simulated DNG has no preview: one clear error
  io::ImageSet set = simulated("orange", {128, 86});
  ASSERT_FALSE(set.images.empty());
  auto dng = io::encode_dng(set.images[0](cv::Rect(0, 0, 128, 86)).clone());
  ASSERT_TRUE(dng) << dng.message();
  auto preview = io::decode_raw_preview(*dng, "nopreview.dng");
  if (!preview) {
    EXPECT_NE(preview.message().find("nopreview.dng"), std::string::npos) << preview.message();
  }
}

TEST(Reduced, JpegDecodedSmallInTheDctIsLinear) {
  // A smooth linear picture, stored as a camera stores it: sRGB, 8 bits, JPEG.
  const cv::Size size(640, 480);
  cv::Mat linear(size, CV_32FC3);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x)
      linear.at<cv::Vec3f>(y, x) = cv::Vec3f(0.02f + 0.9f * x / size.width, 0.05f + 0.8f * y / size.height,
                                             0.3f + 0.2f * std::sin(x * 0.01f) * std::cos(y * 0.013f));
  cv::Mat srgb8(size, CV_8UC3);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x)
      for (int c = 0; c < 3; ++c) {
        const double v = linear.at<cv::Vec3f>(y, x)[c];
        const double e = v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1 / 2.4) - 0.055;
        srgb8.at<cv::Vec3b>(y, x)[c] = cv::saturate_cast<uchar>(e * 255.0 + 0.5);
      }
  std::vector<uchar> jpeg;
  ASSERT_TRUE(cv::imencode(".jpg", srgb8, jpeg, {cv::IMWRITE_JPEG_QUALITY, 95}));
  const std::string bytes(jpeg.begin(), jpeg.end());
  for (int factor : {1, 2, 4, 8}) {
    SCOPED_TRACE("factor " + std::to_string(factor));
    auto small = io::decode_jpeg_reduced(bytes, factor, "photo.jpg");
    ASSERT_TRUE(small) << small.message();
    ASSERT_EQ(small->size(), cv::Size(size.width / factor, size.height / factor));
    cv::Mat expect;
    cv::resize(linear, expect, small->size(), 0, 0, cv::INTER_AREA);
    const cv::Vec3d e = relative_error(*small, expect, {});
    for (int c = 0; c < 3; ++c) EXPECT_LT(e[c], 0.02) << "channel " << c;
    // linear, not sRGB: the sRGB code values would be far off
    cv::Mat code;
    srgb8.convertTo(code, CV_32FC3, 1 / 255.0);
    cv::resize(code, code, small->size(), 0, 0, cv::INTER_AREA);
    EXPECT_GT(relative_error(code, expect, {})[1], 0.2);
  }
  EXPECT_EQ(io::jpeg_reduction_for(5600, 1280), 4);
  EXPECT_EQ(io::jpeg_reduction_for(1024, 1280), 1);
  EXPECT_EQ(io::jpeg_reduction_for(6000, 700), 8);
  EXPECT_FALSE(io::decode_jpeg_reduced(bytes, 3, "photo.jpg"));
  EXPECT_FALSE(io::decode_jpeg_reduced(std::string(1000, 'x'), 2, "junk.jpg"));
}

TEST(Reduced, SetReadAtTheLiveSizeKeepsTruthAndMaskInStep) {
  Scratch scratch;
  io::ImageSet set = simulated("bull", {512, 340}, 0.005);
  ASSERT_TRUE(io::add_dng_raw_files(set));
  ASSERT_TRUE(io::write_set(set, scratch.dir / "set"));
  io::ReducedOptions o;
  o.width = 200;
  auto live = io::read_set_reduced(scratch.dir / "set", o);
  ASSERT_TRUE(live) << live.message();
  EXPECT_EQ(live->photos_from, "raw-binned-2");  // 512 / 2 = 256 >= 200, then area-resized to 200
  EXPECT_EQ(live->size, cv::Size(200, 133));
  ASSERT_EQ(live->images.size(), set.images.size());
  for (const auto& m : live->images) EXPECT_EQ(m.size(), live->size);
  EXPECT_EQ(live->truth.normals.size(), live->size);
  EXPECT_EQ(live->truth.mask.size(), live->size);
  EXPECT_NEAR(live->camera.focal_px, set.camera.focal_px * 200 / 512, 1e-6);
  // the photos are the set's, smaller: against the render area-averaged
  cv::Mat render, mask;
  cv::resize(set.images[0], render, live->size, 0, 0, cv::INTER_AREA);
  cv::erode(live->truth.mask, mask, cv::Mat());
  const cv::Vec3d e = relative_error(live->images[0], render, mask);
  for (int c = 0; c < 3; ++c) EXPECT_LT(e[c], 0.05) << "channel " << c;

  o.decode = io::ReducedDecode::developed;
  auto developed = io::read_set_reduced(scratch.dir / "set", o);
  ASSERT_TRUE(developed) << developed.message();
  EXPECT_EQ(developed->photos_from, "developed");
  EXPECT_EQ(developed->size, live->size);
  // a set no wider than the live width keeps its size: the developed photos
  o.decode = io::ReducedDecode::automatic;
  o.width = 1280;
  auto whole = io::read_set_reduced(scratch.dir / "set", o);
  ASSERT_TRUE(whole) << whole.message();
  EXPECT_EQ(whole->size, set.size);
  // asked for JPEGs the set does not have: one error naming the folder
  o.decode = io::ReducedDecode::jpeg_reduced;
  auto no_jpeg = io::read_set_reduced(scratch.dir / "set", o);
  ASSERT_FALSE(no_jpeg);
  EXPECT_NE(no_jpeg.message().find("not JPEGs"), std::string::npos) << no_jpeg.message();
  o.width = 10;
  EXPECT_FALSE(io::read_set_reduced(scratch.dir / "set", o));
}

TEST(Reduced, SetOfJpegPhotosIsReadSmallInTheDct) {
  Scratch scratch;
  io::ImageSet set = simulated("orange", {512, 340});
  ASSERT_TRUE(io::write_set(set, scratch.dir / "set"));
  // the developed photos replaced by camera JPEGs (sRGB, 8-bit), set.json renamed to them
  std::ifstream in(scratch.dir / "set" / "set.json");
  std::string manifest((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  for (size_t i = 0; i <= set.images.size(); ++i) {
    const bool ambient = i == set.images.size();
    if (ambient && set.ambient.empty()) break;
    const cv::Mat& photo = ambient ? set.ambient : set.images[i];
    const std::string png = ambient ? "ambient.png" : (i < 10 ? "light_0" : "light_") + std::to_string(i) + ".png";
    const std::string jpg = png.substr(0, png.size() - 4) + ".jpg";
    cv::Mat srgb(photo.size(), CV_8UC3);
    for (int y = 0; y < photo.rows; ++y)
      for (int x = 0; x < photo.cols; ++x)
        for (int c = 0; c < 3; ++c) {
          const double v = std::clamp<double>(photo.at<cv::Vec3f>(y, x)[c], 0, 1);
          const double e = v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1 / 2.4) - 0.055;
          srgb.at<cv::Vec3b>(y, x)[c] = cv::saturate_cast<uchar>(e * 255 + 0.5);
        }
    ASSERT_TRUE(cv::imwrite((scratch.dir / "set" / jpg).string(), srgb, {cv::IMWRITE_JPEG_QUALITY, 95}));
    fs::remove(scratch.dir / "set" / png);
    const size_t at = manifest.find("\"" + png + "\"");
    ASSERT_NE(at, std::string::npos) << png;
    manifest.replace(at + 1, png.size(), jpg);
  }
  std::ofstream(scratch.dir / "set" / "set.json") << manifest;
  io::ReducedOptions o;
  o.width = 128;
  auto live = io::read_set_reduced(scratch.dir / "set", o);
  ASSERT_TRUE(live) << live.message();
  EXPECT_EQ(live->photos_from, "jpeg-reduced-4");
  EXPECT_EQ(live->size, cv::Size(128, 85));
  cv::Mat render;
  cv::resize(set.images[0], render, live->size, 0, 0, cv::INTER_AREA);
  cv::Mat mask;
  cv::erode(live->truth.mask, mask, cv::Mat());
  const cv::Vec3d e = relative_error(live->images[0], render, mask);
  for (int c = 0; c < 3; ++c) EXPECT_LT(e[c], 0.08) << "channel " << c;
}

}  // namespace
}  // namespace veneer
