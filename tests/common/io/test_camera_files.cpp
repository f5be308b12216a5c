// The rig's camera twin's files (camera_files.hpp, dng.hpp): a developed JPEG
// and a losslessly compressed DNG with an embedded preview per frame.
//  - the compressed DNG decodes (LibRaw) to exactly what the uncompressed one
//    did, at sizes that exercise the tile layout's edges;
//  - LibRaw's unpack_thumb and find_dng_preview find the same preview, a
//    reduced developed photo of the frame;
//  - the files' sizes per pixel are a camera's (checked at a test size;
//    the 24 Mpx numbers are in bench_raw);
//  - a set of them reads back: RAW by default, the JPEG linearised when asked.
#include <cstdio>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "test_util.hpp"
#include "veneer/io/camera_files.hpp"
#include "veneer/io/dng.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/io/imageset.hpp"
#include "veneer/io/raw.hpp"
#include "veneer/sim/simulator.hpp"

namespace veneer {
namespace {

using test::Scratch;

io::ImageSet rendered(cv::Size size, double noise = 0.002, const std::string& scene = "bull") {
  sim::RenderOptions o;
  o.size = size;
  o.noise_sigma = noise;
  o.seed = 7;
  o.camera_optics();  // as the rig's camera twin renders
  auto set = sim::simulate_set(scene, o, io::Role::destination);
  EXPECT_TRUE(set) << set.message();
  return set ? std::move(set).value() : io::ImageSet{};
}

// A frame that is neither flat nor dark: the brightest of the set.
const cv::Mat& brightest(const io::ImageSet& set) {
  size_t best = 0;
  for (size_t i = 1; i < set.images.size(); ++i) {
    if (cv::sum(set.images[i])[1] > cv::sum(set.images[best])[1]) best = i;
  }
  return set.images[best];
}

TEST(CameraFiles, CompressedDngDecodesExactlyAsTheUncompressed) {
  // 512 wide: twice the tile (LibRaw's other layout); 600x400: partial edge
  // tiles; 200x120: one strip; 96x64 the ramp size of Raw tests.
  for (cv::Size size : {cv::Size(512, 340), cv::Size(600, 400), cv::Size(200, 120), cv::Size(96, 64)}) {
    SCOPED_TRACE(std::to_string(size.width) + "x" + std::to_string(size.height));
    io::ImageSet set = rendered(size);
    ASSERT_FALSE(set.images.empty());
    const cv::Mat& photo = brightest(set);
    io::DngOptions plain;
    plain.compress = false;
    plain.preview_divisor = 0;
    auto uncompressed = io::encode_dng(photo, plain);
    auto compressed = io::encode_dng(photo);
    ASSERT_TRUE(uncompressed) << uncompressed.message();
    ASSERT_TRUE(compressed) << compressed.message();
    EXPECT_LT(compressed->size(), uncompressed->size());
    for (bool half : {false, true}) {
      io::RawOptions o;
      o.half_size = half;
      auto a = io::decode_raw_linear(*uncompressed, o, "plain.dng");
      auto b = io::decode_raw_linear(*compressed, o, "lj92.dng");
      ASSERT_TRUE(a) << a.message();
      ASSERT_TRUE(b) << b.message();
      ASSERT_EQ(a->size(), b->size());
      EXPECT_EQ(cv::norm(*a, *b, cv::NORM_INF), 0.0) << (half ? "half size" : "full size");
    }
  }
}

TEST(CameraFiles, LosslessJpegKeepsEveryCount) {
  // Extremes the rendered frames do not reach: black, the white level, a
  // full-scale checkerboard (differences of the largest magnitude) and noise.
  cv::Mat photo(64, 600, CV_32FC3);
  cv::RNG rng(5);
  for (int y = 0; y < photo.rows; ++y)
    for (int x = 0; x < photo.cols; ++x) {
      const float v = y < 16 ? 0.0f : y < 32 ? 1.0f : y < 48 ? static_cast<float>((x / 2 + y / 2) % 2) : rng.uniform(0.f, 1.f);
      photo.at<cv::Vec3f>(y, x) = cv::Vec3f(v, v, v);
    }
  io::DngOptions plain;
  plain.compress = false;
  for (int white : {16383, 65535}) {
    plain.white_level = white;
    io::DngOptions lj92;
    lj92.white_level = white;
    auto a = io::decode_raw_linear(*io::encode_dng(photo, plain), {io::RawOptions{true}}, "plain.dng");
    auto b = io::decode_raw_linear(*io::encode_dng(photo, lj92), {io::RawOptions{true}}, "lj92.dng");
    ASSERT_TRUE(a && b);
    EXPECT_EQ(cv::norm(*a, *b, cv::NORM_INF), 0.0) << "white level " << white;
  }
}

TEST(CameraFiles, DngPreviewIsFoundByLibRawAndWithoutIt) {
  io::ImageSet set = rendered({640, 420});
  ASSERT_FALSE(set.images.empty());
  const cv::Mat& photo = brightest(set);
  auto dng = io::encode_dng(photo);
  ASSERT_TRUE(dng) << dng.message();
  auto by_libraw = io::raw_preview_jpeg(*dng, "frame.dng");
  ASSERT_TRUE(by_libraw) << by_libraw.message();
  auto found = io::find_dng_preview(*dng, dng->size(), "frame.dng");
  ASSERT_TRUE(found) << found.message();
  EXPECT_EQ(found->size, cv::Size(160, 105));
  // LibRaw hands the stored JPEG out with an Exif block of its own after the
  // SOI: the same stream behind it, the same pixels.
  const std::string stored = dng->substr(static_cast<size_t>(found->offset), static_cast<size_t>(found->length));
  ASSERT_GT(by_libraw->size(), stored.size());
  EXPECT_EQ(by_libraw->substr(by_libraw->size() - (stored.size() - 2)), stored.substr(2));
  auto pixels = [](const std::string& jpeg) { return cv::imdecode(std::vector<uchar>(jpeg.begin(), jpeg.end()), cv::IMREAD_COLOR); };
  EXPECT_EQ(cv::norm(pixels(stored), pixels(*by_libraw), cv::NORM_INF), 0.0);
  Scratch dir;
  ASSERT_TRUE(io::write_file_synced(dir / "frame.dng", *dng));
  auto from_file = io::read_dng_preview(dir / "frame.dng");
  ASSERT_TRUE(from_file) << from_file.message();
  EXPECT_EQ(*from_file, stored);
  // The preview is the developed photo reduced: linearised, within JPEG's loss of an area-averaged frame.
  auto linear = io::decode_linear_image(*from_file, "preview.jpg");
  ASSERT_TRUE(linear) << linear.message();
  ASSERT_EQ(linear->size(), cv::Size(160, 105));
  cv::Mat expect;
  cv::resize(photo, expect, linear->size(), 0, 0, cv::INTER_AREA);
  const double rel = cv::norm(*linear, expect, cv::NORM_L1) / cv::norm(expect, cv::NORM_L1);
  EXPECT_LT(rel, 0.05);
  // No preview asked: none found, with the reason.
  io::DngOptions none;
  none.preview_divisor = 0;
  auto bare = io::encode_dng(photo, none);
  ASSERT_TRUE(bare);
  auto missing = io::find_dng_preview(*bare, bare->size(), "bare.dng");
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.message().find("no embedded JPEG preview"), std::string::npos) << missing.message();
  EXPECT_FALSE(io::find_dng_preview(std::string_view("II*\0\x08\0\0\0", 8), 8, "cut.dng"));
  EXPECT_FALSE(io::find_dng_preview(std::string_view("GIF89a.."), 8, "gif"));
}

// Bytes per pixel of the twin's files against a 24 Mpx body's: a JPEG of
// 3-12 MB (0.12-0.5 B/px) and a lossless DNG of 20-30 MB (0.8-1.25 B/px,
// 14-bit). Checked loosely at 1200x800 (the sensor noise, which dominates the
// DNG's entropy, is the rig twin's); bench_raw reports the full size.
TEST(CameraFiles, FileSizesAreACamerasPerPixel) {
  const cv::Size size(1200, 800);
  io::ImageSet set = rendered(size);
  ASSERT_FALSE(set.images.empty());
  auto files = io::encode_camera_files(brightest(set));
  ASSERT_TRUE(files) << files.message();
  const double px = size.area();
  const double jpeg = files->developed.bytes.size() / px, dng = files->raw.bytes.size() / px;
  std::printf("at %dx%d: JPEG %.3f B/px (%.1f MB at 24 Mpx), DNG %.3f B/px (%.1f MB at 24 Mpx)\n", size.width,
              size.height, jpeg, jpeg * 24, dng, dng * 24);
  EXPECT_EQ(files->developed.extension, "jpg");
  EXPECT_EQ(files->raw.extension, "dng");
  EXPECT_GT(jpeg, 0.08);
  EXPECT_LT(jpeg, 0.6);
  EXPECT_GT(dng, 0.6);
  EXPECT_LT(dng, 1.4);
}

TEST(CameraFiles, ASetOfThemReadsBackFromTheRawOrTheJpeg) {
  io::ImageSet set = rendered({320, 214}, 0.0, "orange");
  ASSERT_FALSE(set.images.empty());
  io::ImageSet with_files = set;
  ASSERT_TRUE(io::add_camera_files(with_files));
  Scratch dir;
  ASSERT_TRUE(io::write_set(with_files, dir / "set"));
  EXPECT_TRUE(std::filesystem::exists(dir / "set" / "light_00.jpg"));
  EXPECT_TRUE(std::filesystem::exists(dir / "set" / "light_00.dng"));
  EXPECT_TRUE(std::filesystem::exists(dir / "set" / "ambient.jpg"));
  EXPECT_FALSE(std::filesystem::exists(dir / "set" / "light_00.png"));
  auto raw = io::read_set(dir / "set");
  ASSERT_TRUE(raw) << raw.message();
  EXPECT_EQ(raw->photos_from, "raw");
  io::ReadOptions developed;
  developed.photos = io::PhotoSource::developed;
  auto jpeg = io::read_set(dir / "set", developed);
  ASSERT_TRUE(jpeg) << jpeg.message();
  EXPECT_EQ(jpeg->photos_from, "jpeg");
  const cv::Mat& mask = set.truth.mask;
  for (size_t i = 0; i < set.images.size(); ++i) {
    const double denominator = cv::norm(set.images[i], cv::NORM_L1, mask);
    // The RAW path's demosaicing of the orange's texture at this small size
    // (RawSim checks it within 1 % at 512x340).
    EXPECT_LT(cv::norm(raw->images[i], set.images[i], cv::NORM_L1, mask) / denominator, 0.02) << "raw " << i;
    EXPECT_LT(cv::norm(jpeg->images[i], set.images[i], cv::NORM_L1, mask) / denominator, 0.03) << "jpeg " << i;
  }
}

}  // namespace
}  // namespace veneer
