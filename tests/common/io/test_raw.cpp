// The RAW path: DNGs written by encode_dng decode back through LibRaw.
#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "test_util.hpp"
#include <opencv2/imgcodecs.hpp>

#include "veneer/io/dng.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/io/raw.hpp"

namespace veneer {
namespace {

// Smooth colour ramps (demosaicing is exact on them up to rounding).
cv::Mat ramp(cv::Size size) {
  cv::Mat m(size, CV_32FC3);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x)
      m.at<cv::Vec3f>(y, x) = cv::Vec3f(0.1f + 0.5f * x / size.width, 0.3f + 0.4f * y / size.height, 0.6f - 0.3f * x / size.width);
  return m;
}

double mean_relative_error(const cv::Mat& a, const cv::Mat& b, int border) {
  cv::Rect inner(border, border, a.cols - 2 * border, a.rows - 2 * border);
  return cv::norm(a(inner), b(inner), cv::NORM_L1) / cv::norm(b(inner), cv::NORM_L1);
}

TEST(Raw, DngOfARampDecodesBack) {
  const cv::Mat photo = ramp({96, 64});
  auto dng = io::encode_dng(photo);
  ASSERT_TRUE(dng) << dng.message();
  for (io::Demosaic d : {io::Demosaic::ahd, io::Demosaic::ppg, io::Demosaic::bilinear, io::Demosaic::vng, io::Demosaic::dcb, io::Demosaic::dht,
                     io::Demosaic::aahd, io::Demosaic::mhc}) {
    io::RawOptions o;
    o.demosaic = d;
    auto back = io::decode_raw_linear(*dng, o, "ramp.dng");
    ASSERT_TRUE(back) << back.message();
    ASSERT_EQ(back->size(), photo.size()) << io::demosaic_name(d);
    EXPECT_LT(mean_relative_error(*back, photo, 4), 0.005) << io::demosaic_name(d);
  }
  io::RawOptions half;
  half.half_size = true;
  auto small = io::decode_raw_linear(*dng, half, "ramp.dng");
  ASSERT_TRUE(small) << small.message();
  ASSERT_EQ(small->size(), cv::Size(48, 32));
  cv::Mat expect;
  cv::resize(photo, expect, small->size(), 0, 0, cv::INTER_AREA);
  EXPECT_LT(mean_relative_error(*small, expect, 2), 0.01);
}

TEST(Raw, EveryFrameKeepsTheFilesWhiteLevel) {
  // Whatever a frame's brightest sample (a highlight near clipping, or a dim
  // frame), it decodes at the file's white level like every other frame of
  // its set, or photometric stereo sees each frame scaled its own way.
  for (float peak : {0.05f, 0.8f, 0.95f}) {
    const cv::Mat photo = ramp({64, 48}) * (peak / 0.6f);
    auto dng = io::encode_dng(photo);
    ASSERT_TRUE(dng) << dng.message();
    auto back = io::decode_raw_linear(*dng, {}, "dim.dng");
    ASSERT_TRUE(back) << back.message();
    EXPECT_LT(mean_relative_error(*back, photo, 4), 0.01) << "peak " << peak;
  }
}

TEST(Raw, DamagedFilesAreRefusedWithTheirName) {
  auto dng = io::encode_dng(ramp({32, 16}));
  ASSERT_TRUE(dng);
  for (const std::string& bad : {std::string(), std::string("not a raw file at all"), dng->substr(0, 200),
                                 dng->substr(0, dng->size() / 2)}) {
    auto r = io::decode_raw_linear(bad, {}, "bad.dng");
    if (r) continue;  // LibRaw may fill a cut strip with zeros; it must not crash
    EXPECT_NE(r.message().find("bad.dng"), std::string::npos) << r.message();
  }
  EXPECT_FALSE(io::decode_raw_linear("", {}, "empty.dng"));
  EXPECT_FALSE(io::decode_raw_linear("II*\0garbage", {}, "x.dng"));
}

// LibRaw 0.20 reads on past a directory that runs off the file's end and can
// crash (fuzz_raw_decode found a 300-byte DNG: tests/fuzz/corpus/raw_decode/
// truncated-ifd-libraw-crash.dng, replayed by fuzz/raw_decode-corpus). Such a
// file is refused before LibRaw sees it, naming the file and the directory.
TEST(Raw, ADirectoryRunningPastTheEndIsRefusedBeforeLibRawReadsIt) {
  auto dng = io::encode_dng(ramp({32, 16}));
  ASSERT_TRUE(dng);
  EXPECT_TRUE(io::check_raw_structure(*dng, "whole.dng"));
  const uint32_t ifd0 = static_cast<uint8_t>((*dng)[4]) | static_cast<uint8_t>((*dng)[5]) << 8 |
                        static_cast<uint8_t>((*dng)[6]) << 16 | static_cast<uint32_t>(static_cast<uint8_t>((*dng)[7])) << 24;
  ASSERT_EQ(dng->substr(0, 4), std::string("II*\0", 4));  // encode_dng writes little-endian TIFF
  ASSERT_LT(ifd0 + 20, dng->size());
  // Cut inside the first directory's table.
  const std::string cut = dng->substr(0, ifd0 + 20);
  auto r = io::decode_raw_linear(cut, {}, "cut.dng");
  ASSERT_FALSE(r);
  EXPECT_NE(r.message().find("cut.dng: not a whole RAW file"), std::string::npos) << r.message();
  EXPECT_NE(r.message().find("byte " + std::to_string(ifd0)), std::string::npos) << r.message();
  EXPECT_FALSE(io::raw_preview_jpeg(cut, "cut.dng"));
  // A directory claiming 65535 entries.
  std::string swollen = *dng;
  swollen[ifd0] = swollen[ifd0 + 1] = static_cast<char>(0xff);
  auto s = io::decode_raw_linear(swollen, {}, "swollen.dng");
  ASSERT_FALSE(s);
  EXPECT_NE(s.message().find("65535 entries"), std::string::npos) << s.message();
  // Not TIFF: left to LibRaw.
  EXPECT_TRUE(io::check_raw_structure("FUJIFILMCCD-RAW 0201", "x.raf"));
}

TEST(Raw, FileNamesAndOptions) {
  EXPECT_TRUE(io::is_raw_file_name("IMG_0001.CR2"));
  EXPECT_TRUE(io::is_raw_file_name("light_00.dng"));
  EXPECT_FALSE(io::is_raw_file_name("light_00.png"));
  EXPECT_FALSE(io::is_raw_file_name("dng"));
  for (auto d : {io::Demosaic::bilinear, io::Demosaic::vng, io::Demosaic::ppg, io::Demosaic::ahd, io::Demosaic::dcb, io::Demosaic::dht,
                 io::Demosaic::aahd})
    EXPECT_EQ(*io::parse_demosaic(io::demosaic_name(d)), d);
  auto amaze = io::parse_demosaic("amaze");  // not in Debian's LibRaw (no GPL demosaic packs)
  ASSERT_FALSE(amaze);
  EXPECT_NE(amaze.message().find("dcb"), std::string::npos) << amaze.message();
  for (auto p : {io::PhotoSource::automatic, io::PhotoSource::raw, io::PhotoSource::developed})
    EXPECT_EQ(*io::parse_photo_source(io::photo_source_name(p)), p);
  EXPECT_FALSE(io::parse_photo_source("jpeg"));
  EXPECT_FALSE(io::encode_dng(ramp({31, 16})));  // odd width: not whole Bayer cells
  io::DngOptions o;
  o.black_level = o.white_level;
  EXPECT_FALSE(io::encode_dng(ramp({32, 16}), o));
}

TEST(Raw, ManifestNamesRawFilesInsideTheSet) {
  test::Scratch dir;
  io::ImageSet set = test::synthetic_set({64, 48}, 3, 5, false);  // LibRaw refuses sides < 22 px
  ASSERT_TRUE(io::add_dng_raw_files(set));
  ASSERT_TRUE(io::write_set(set, dir / "s"));
  const std::string json = test::slurp(dir / "s" / "set.json");
  EXPECT_NE(json.find("\"raw\": \"light_02.dng\""), std::string::npos) << json;
  EXPECT_NE(json.find("\"ambient_raw\": \"ambient.dng\""), std::string::npos) << json;
  auto m = io::parse_manifest(json, dir / "s");
  ASSERT_TRUE(m) << m.message();
  ASSERT_EQ(m->raw_files.size(), 3u);
  EXPECT_EQ(m->raw_files[1], "light_01.dng");
  EXPECT_EQ(m->ambient_raw_file, "ambient.dng");
  auto escape = json;
  escape.replace(escape.find("light_01.dng"), 12, "../x/b.dng");
  auto bad = io::parse_manifest(escape, dir / "s");
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.message().find("leaves the set folder"), std::string::npos) << bad.message();
  auto twice = json;
  twice.replace(twice.find("light_01.dng"), 12, "light_01.png");
  EXPECT_FALSE(io::parse_manifest(twice, dir / "s"));
  auto back = io::read_set(dir / "s");
  ASSERT_TRUE(back) << back.message();
  EXPECT_EQ(back->photos_from, "raw");
  // Pixel noise cannot survive a Bayer mosaic; the levels must.
  const cv::Scalar got = cv::mean(back->images[2]), want = cv::mean(set.images[2]);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(got[c], want[c], 0.03);
}

TEST(Raw, JpegPhotosGoThroughTheInverseSrgbCurve) {
  cv::Mat grey(8, 8, CV_8UC3, cv::Scalar::all(188));  // sRGB 188 = linear 0.5
  std::vector<uchar> jpeg;
  ASSERT_TRUE(cv::imencode(".jpg", grey, jpeg, {cv::IMWRITE_JPEG_QUALITY, 100}));
  const std::string bytes(jpeg.begin(), jpeg.end());
  EXPECT_EQ(io::image_file_kind(bytes), "jpeg");
  auto linear = io::decode_linear_image(bytes, "grey.jpg");
  ASSERT_TRUE(linear) << linear.message();
  EXPECT_NEAR(cv::mean(*linear)[1], 0.5, 0.01);
}

}  // namespace
}  // namespace veneer
