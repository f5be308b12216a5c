// io/png_codec: the libdeflate PNG path against OpenCV's libpng as the oracle.
// PNGs are built here row by row with every filter type PNG has, in every
// colour type and depth the fast decoder takes, and both decoders must give
// the same samples; damaged image data is refused naming the problem.
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <libdeflate.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "veneer/io/image_io.hpp"

namespace veneer {
namespace {

void be32(std::string& out, uint32_t v) {
  const char b[4] = {char(v >> 24), char(v >> 16), char(v >> 8), char(v)};
  out.append(b, 4);
}

void chunk(std::string& out, const char* type, const std::string& data) {
  be32(out, static_cast<uint32_t>(data.size()));
  std::string body = std::string(type, 4) + data;
  out += body;
  be32(out, static_cast<uint32_t>(libdeflate_crc32(0, body.data(), body.size())));
}

int paeth(int a, int b, int c) {
  const int p = a + b - c, pa = std::abs(p - a), pb = std::abs(p - b), pc = std::abs(p - c);
  return (pa <= pb && pa <= pc) ? a : (pb <= pc ? b : c);
}

// A PNG of random samples (`channels` 1..4, `depth` 8/16), row y filtered
// with filter (y + shift) % 5, or `bad_filter` on row 2 when set; the image
// data deflated and split over IDAT chunks of `idat_size` bytes; only the
// first `keep_rows` rows compressed when >= 0 (a short stream).
std::string make_png(int width, int height, int channels, int depth, uint64_t seed, int shift = 0,
                     int bad_filter = -1, int keep_rows = -1, size_t idat_size = 1000) {
  const size_t bpp = size_t(channels) * depth / 8, row_bytes = size_t(width) * bpp;
  std::vector<unsigned char> plain(row_bytes * height);
  cv::RNG rng(seed);
  for (auto& b : plain) b = static_cast<unsigned char>(rng.uniform(0, 256));
  std::string filtered;
  for (int y = 0; y < height; ++y) {
    const unsigned char* row = plain.data() + row_bytes * y;
    const unsigned char* up = y > 0 ? row - row_bytes : nullptr;
    const int type = (y == 2 && bad_filter >= 0) ? bad_filter : (y + shift) % 5;
    filtered.push_back(static_cast<char>(type));
    for (size_t i = 0; i < row_bytes; ++i) {
      const int a = i >= bpp ? row[i - bpp] : 0, b = up ? up[i] : 0, c = (up && i >= bpp) ? up[i - bpp] : 0;
      int pred = 0;
      switch (type) {
        case 1: pred = a; break;
        case 2: pred = b; break;
        case 3: pred = (a + b) / 2; break;
        case 4: pred = paeth(a, b, c); break;
        default: pred = 0;
      }
      filtered.push_back(static_cast<char>(row[i] - pred));
    }
  }
  if (keep_rows >= 0) filtered.resize(size_t(keep_rows) * (row_bytes + 1));
  libdeflate_compressor* z = libdeflate_alloc_compressor(6);
  std::string deflated(libdeflate_zlib_compress_bound(z, filtered.size()), '\0');
  deflated.resize(libdeflate_zlib_compress(z, filtered.data(), filtered.size(), deflated.data(), deflated.size()));
  libdeflate_free_compressor(z);

  std::string png = "\x89PNG\r\n\x1a\n";
  std::string ihdr;
  be32(ihdr, static_cast<uint32_t>(width));
  be32(ihdr, static_cast<uint32_t>(height));
  const char colour_type[5] = {0, 0, 4, 2, 6};
  ihdr += std::string{static_cast<char>(depth), colour_type[channels], 0, 0, 0};
  chunk(png, "IHDR", ihdr);
  for (size_t at = 0; at < deflated.size(); at += idat_size) chunk(png, "IDAT", deflated.substr(at, idat_size));
  chunk(png, "IEND", "");
  return png;
}

// OpenCV's reading of the same bytes, as decode_linear_image promises it:
// BGR, grey spread, alpha dropped, as 16-bit integers for an exact compare.
cv::Mat opencv_samples(const std::string& png) {
  cv::Mat raw = cv::imdecode(cv::Mat(1, static_cast<int>(png.size()), CV_8UC1, const_cast<char*>(png.data())),
                             cv::IMREAD_UNCHANGED);
  // planes B, G, R; grey (plane 0 of grey or grey + alpha) in all three
  std::vector<cv::Mat> planes;
  cv::split(raw, planes);
  if (planes.size() <= 2) planes = {planes[0], planes[0], planes[0]};
  planes.resize(3);
  cv::Mat bgr, out;
  cv::merge(planes, bgr);
  bgr.convertTo(out, CV_32SC3);
  return out;
}

cv::Mat our_samples(const cv::Mat& linear, int depth) {
  cv::Mat out;
  linear.convertTo(out, CV_32SC3, depth == 16 ? 65535.0 : 255.0);  // rounds: exact for k / full scale
  return out;
}

TEST(PngCodec, EveryFilterColourTypeAndDepthDecodesAsOpenCV) {
  for (int depth : {8, 16})
    for (int channels : {1, 2, 3, 4})
      for (int shift : {0, 3}) {
        const std::string png = make_png(37, 23, channels, depth, 100 + channels * 10 + depth + shift, shift);
        const cv::Mat expect = opencv_samples(png);
        ASSERT_FALSE(expect.empty());
        auto ours = io::decode_linear_image(png, "made.png");
        ASSERT_TRUE(ours) << ours.message();
        ASSERT_EQ(ours->type(), CV_32FC3);
        ASSERT_EQ(ours->size(), expect.size());
        EXPECT_EQ(cv::norm(our_samples(*ours, depth), expect, cv::NORM_INF), 0)
            << depth << "-bit, " << channels << " channels, shift " << shift;
      }
}

TEST(PngCodec, EncodedPhotosDecodeExactlyThroughOpenCV) {
  cv::Mat photo(123, 77, CV_32FC3);
  cv::RNG(7).fill(photo, cv::RNG::UNIFORM, cv::Scalar::all(0), cv::Scalar::all(1));
  auto png = io::encode_png16(photo);
  ASSERT_TRUE(png) << png.message();
  cv::Mat u16;
  photo.convertTo(u16, CV_16UC3, 65535.0);
  cv::Mat back = cv::imdecode(cv::Mat(1, static_cast<int>(png->size()), CV_8UC1, png->data()), cv::IMREAD_UNCHANGED);
  ASSERT_EQ(back.type(), CV_16UC3);
  EXPECT_EQ(cv::norm(back, u16, cv::NORM_INF), 0);  // same BGR samples, every one
  cv::Mat grey(9, 11, CV_32FC1, cv::Scalar(0.25));
  auto g = io::encode_png16(grey);
  ASSERT_TRUE(g);
  cv::Mat gb = cv::imdecode(cv::Mat(1, static_cast<int>(g->size()), CV_8UC1, g->data()), cv::IMREAD_UNCHANGED);
  ASSERT_EQ(gb.type(), CV_16UC1);
  EXPECT_EQ(gb.at<uint16_t>(4, 5), 16384);
}

// Both ways of deflating (stored, as results are written; fast, as sets are)
// give the samples cv::Mat::convertTo gives after cv::patchNaNs, through
// OpenCV's libpng and through our decoder; NaN, negative and > 1 values
// included. Stored is not compressed: its file is larger than the samples.
TEST(PngCodec, StoredAndFastEncodingsKeepEverySample) {
  cv::Mat photo(97, 131, CV_32FC3);
  cv::RNG(11).fill(photo, cv::RNG::UNIFORM, cv::Scalar::all(-0.2), cv::Scalar::all(1.2));
  photo.at<cv::Vec3f>(5, 7) = cv::Vec3f(std::nanf(""), 0.5f, std::nanf(""));
  cv::Mat clean = photo.clone();
  cv::patchNaNs(clean, 0.0);
  cv::Mat u16;
  clean.convertTo(u16, CV_16UC3, 65535.0);
  for (io::PngDeflate mode : {io::PngDeflate::stored, io::PngDeflate::fast}) {
    const char* name = mode == io::PngDeflate::stored ? "stored" : "fast";
    auto png = io::encode_png16(photo, mode);
    ASSERT_TRUE(png) << png.message();
    if (mode == io::PngDeflate::stored) {
      EXPECT_GT(png->size(), u16.total() * u16.elemSize()) << name;
    }
    cv::Mat back = cv::imdecode(cv::Mat(1, static_cast<int>(png->size()), CV_8UC1, png->data()), cv::IMREAD_UNCHANGED);
    ASSERT_EQ(back.type(), CV_16UC3) << name;
    EXPECT_EQ(cv::norm(back, u16, cv::NORM_INF), 0) << name;
    auto ours = io::decode_linear_image(*png, "x.png");
    ASSERT_TRUE(ours) << ours.message();
    cv::Mat expect;
    u16.convertTo(expect, CV_32FC3, 1.0 / 65535.0);
    EXPECT_LT(cv::norm(*ours, expect, cv::NORM_INF), 1e-6) << name;
  }
  cv::Mat grey(9, 11, CV_32FC1, cv::Scalar(0.25));
  auto g = io::encode_png16(grey, io::PngDeflate::stored);
  ASSERT_TRUE(g);
  cv::Mat gb = cv::imdecode(cv::Mat(1, static_cast<int>(g->size()), CV_8UC1, g->data()), cv::IMREAD_UNCHANGED);
  ASSERT_EQ(gb.type(), CV_16UC1);
  EXPECT_EQ(gb.at<uint16_t>(4, 5), 16384);
}

TEST(PngCodec, DamagedImageDataIsRefusedNamingTheProblem) {
  const std::string good = make_png(40, 30, 3, 16, 9);
  ASSERT_TRUE(io::decode_linear_image(good, "good.png"));
  struct Case {
    std::string bytes, expect;
  };
  std::string bad_crc = good;
  const size_t idat = bad_crc.find("IDAT");
  bad_crc[idat + 10] = static_cast<char>(bad_crc[idat + 10] ^ 0x40);
  for (const Case& c : {Case{make_png(40, 30, 3, 16, 9, 0, 7), "unknown row filter 7 in row 2"},
                        Case{make_png(40, 30, 3, 16, 9, 0, -1, 20), "truncated PNG (image data holds"},
                        Case{bad_crc, "CRC error in the IDAT chunk"}}) {
    auto r = io::decode_linear_image(c.bytes, "bad.png");
    ASSERT_FALSE(r) << c.expect;
    EXPECT_NE(r.message().find("bad.png"), std::string::npos) << r.message();
    EXPECT_NE(r.message().find(c.expect), std::string::npos) << r.message();
  }
}

// A header declaring far more pixels than its image data can inflate to is
// refused before any buffer of that size is asked for, whether this decoder
// or OpenCV's (interlaced) would have read it (found by fuzz_png_rows: 69
// bytes declaring 8962x65280, 2.3 GB).
TEST(PngCodec, ADeclaredSizeTheDataCantHoldIsRefusedBeforeAllocating) {
  for (int interlace : {0, 1}) {
    std::string ihdr;
    be32(ihdr, 60000);
    be32(ihdr, 60000);
    ihdr += std::string{char(16), char(2), char(0), char(0), char(interlace)};
    std::string png("\x89PNG\r\n\x1a\n", 8);
    chunk(png, "IHDR", ihdr);
    chunk(png, "IDAT", std::string("\x78\x01\x03\x00\x00\x00\x00\x01", 8));  // an empty zlib stream
    chunk(png, "IEND", "");
    auto r = io::decode_linear_image(png, "huge.png");
    ASSERT_FALSE(r) << "interlace " << interlace;
    EXPECT_NE(r.message().find("huge.png: truncated PNG (8 bytes of image data can't hold the 60000x60000"),
              std::string::npos)
        << r.message();
  }
}

}  // namespace
}  // namespace veneer
