// Single-image files: PFM layout and channel order, 16-bit PNG round trips,
// damaged files, pictures.
#include <cmath>
#include <cstring>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "test_util.hpp"
#include "veneer/io/image_io.hpp"

namespace veneer {
namespace {
namespace fs = std::filesystem;
using test::Scratch;
using test::slurp;
using test::spit;

float float_at(const std::string& bytes, size_t offset) {
  float f;
  std::memcpy(&f, bytes.data() + offset, 4);  // the file is little-endian, like this machine
  return f;
}

// A 3x2 image whose channel c at (row, col) is 100*c + 10*row + col.
cv::Mat coded_image() {
  cv::Mat m(2, 3, CV_32FC3);
  for (int r = 0; r < 2; ++r)
    for (int c = 0; c < 3; ++c) m.at<cv::Vec3f>(r, c) = cv::Vec3f(10.f * r + c, 100 + 10.f * r + c, 200 + 10.f * r + c);
  return m;
}

TEST(Pfm, XyzFileStartsWithBottomLeftPixelAndXInR) {
  Scratch dir;
  ASSERT_TRUE(io::write_pfm(dir / "n.pfm", coded_image(), true));
  std::string bytes = slurp(dir / "n.pfm");
  const std::string header = "PF\n3 2\n-1.0\n";
  ASSERT_EQ(bytes.substr(0, header.size()), header);
  ASSERT_EQ(bytes.size(), header.size() + 3 * 2 * 3 * 4);
  // First triple: bottom row (row 1), left pixel; R slot = channel 0 (x).
  EXPECT_EQ(float_at(bytes, header.size() + 0), 10.f);
  EXPECT_EQ(float_at(bytes, header.size() + 4), 110.f);
  EXPECT_EQ(float_at(bytes, header.size() + 8), 210.f);
  // Second triple: bottom row, second pixel.
  EXPECT_EQ(float_at(bytes, header.size() + 12), 11.f);
  // Fourth triple: top row, left pixel.
  EXPECT_EQ(float_at(bytes, header.size() + 36), 0.f);
}

TEST(Pfm, PhotoOrderPutsRedInR) {
  Scratch dir;
  ASSERT_TRUE(io::write_pfm(dir / "p.pfm", coded_image(), false));
  std::string bytes = slurp(dir / "p.pfm");
  const size_t h = std::string("PF\n3 2\n-1.0\n").size();
  // Mat is BGR: channel 2 is red and must land in the R slot.
  EXPECT_EQ(float_at(bytes, h + 0), 210.f);
  EXPECT_EQ(float_at(bytes, h + 4), 110.f);
  EXPECT_EQ(float_at(bytes, h + 8), 10.f);
}

TEST(Pfm, RoundTripsBothOrdersAndOneChannel) {
  Scratch dir;
  cv::Mat m(17, 23, CV_32FC3);
  cv::RNG(3).fill(m, cv::RNG::UNIFORM, cv::Scalar::all(-5), cv::Scalar::all(5));
  for (bool xyz : {true, false}) {
    ASSERT_TRUE(io::write_pfm(dir / "a.pfm", m, xyz));
    auto back = io::read_pfm(dir / "a.pfm", xyz);
    ASSERT_TRUE(back) << back.message();
    EXPECT_EQ(cv::norm(*back, m, cv::NORM_INF), 0.0);
  }
  // Written as xyz, read as a photo: channels come back reversed.
  ASSERT_TRUE(io::write_pfm(dir / "a.pfm", m, true));
  auto swapped = io::read_pfm(dir / "a.pfm", false);
  ASSERT_TRUE(swapped);
  EXPECT_EQ(swapped->at<cv::Vec3f>(4, 5)[0], m.at<cv::Vec3f>(4, 5)[2]);

  cv::Mat g(9, 11, CV_32FC1);
  cv::RNG(4).fill(g, cv::RNG::UNIFORM, cv::Scalar::all(0), cv::Scalar::all(2));
  ASSERT_TRUE(io::write_pfm(dir / "g.pfm", g, true));
  EXPECT_EQ(slurp(dir / "g.pfm").substr(0, 3), "Pf\n");
  auto gb = io::read_pfm(dir / "g.pfm", true);
  ASSERT_TRUE(gb);
  EXPECT_EQ(gb->type(), CV_32FC1);
  EXPECT_EQ(cv::norm(*gb, g, cv::NORM_INF), 0.0);
}

TEST(Pfm, ReadsBigEndianFiles) {
  // Positive scale = big-endian. One row, two grey pixels: 1.5 and -2.
  std::string bytes = "Pf\n2 1\n1.0\n";
  for (float f : {1.5f, -2.0f}) {
    uint32_t u;
    std::memcpy(&u, &f, 4);
    for (int shift = 24; shift >= 0; shift -= 8) bytes.push_back(static_cast<char>((u >> shift) & 0xff));
  }
  auto m = io::read_pfm_bytes(bytes, true, "be.pfm");
  ASSERT_TRUE(m) << m.message();
  EXPECT_EQ(m->at<float>(0, 0), 1.5f);
  EXPECT_EQ(m->at<float>(0, 1), -2.0f);
}

TEST(Pfm, BadFilesNameTheFile) {
  Scratch dir;
  ASSERT_TRUE(io::write_pfm(dir / "t.pfm", coded_image(), true));
  std::string good = slurp(dir / "t.pfm");
  struct Case {
    std::string bytes, expect;
  };
  for (const Case& c : {Case{good.substr(0, good.size() - 5), "truncated"}, Case{"PF\n3\n", "header"},
                        Case{"PF\n0 2\n-1.0\n", "size"}, Case{"PF\n99999999 99999999\n-1.0\n", "size"},
                        Case{"PF\n3 2\nabc\n", "scale"}, Case{"PF\n3 2\n0\n", "scale"}, Case{"P6\n3 2\n", "not a PFM"},
                        Case{"", "not a PFM"}}) {
    spit(dir / "bad.pfm", c.bytes);
    auto r = io::read_pfm(dir / "bad.pfm", true);
    ASSERT_FALSE(r) << c.expect;
    EXPECT_NE(r.message().find("bad.pfm"), std::string::npos) << r.message();
    EXPECT_NE(r.message().find(c.expect), std::string::npos) << r.message();
  }
  auto missing = io::read_pfm(dir / "missing.pfm", true);
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.message().find("missing.pfm"), std::string::npos);
}

TEST(Png16, RoundTripWithinQuantisationAndRedInR) {
  Scratch dir;
  cv::Mat m(170, 256, CV_32FC3);
  cv::RNG(11).fill(m, cv::RNG::UNIFORM, cv::Scalar::all(0), cv::Scalar::all(1));
  ASSERT_TRUE(io::write_png16(dir / "a.png", m));
  cv::Mat raw = cv::imread((dir / "a.png").string(), cv::IMREAD_UNCHANGED);
  ASSERT_EQ(raw.type(), CV_16UC3);
  auto back = io::read_linear_image(dir / "a.png");
  ASSERT_TRUE(back) << back.message();
  ASSERT_EQ(back->type(), CV_32FC3);
  EXPECT_LE(cv::norm(*back, m, cv::NORM_INF), 0.5 / 65535 + 1e-7);

  // A pure red BGR Mat: the PNG's red sample is full scale (checked in the raw bytes of a 1x1 file).
  cv::Mat red(1, 1, CV_32FC3, cv::Scalar(0, 0, 1));
  auto png = io::encode_png16(red);
  ASSERT_TRUE(png);
  cv::Mat decoded = cv::imdecode(cv::Mat(1, static_cast<int>(png->size()), CV_8UC1, png->data()), cv::IMREAD_UNCHANGED);
  const cv::Vec3w px = decoded.at<cv::Vec3w>(0, 0);
  EXPECT_EQ(px[2], 65535);  // OpenCV's BGR = PNG's R in slot 2
  EXPECT_EQ(px[0], 0);
}

TEST(Png16, ClampsOutOfRangeAndNaN) {
  Scratch dir;
  cv::Mat m(1, 4, CV_32FC3, cv::Scalar::all(0.5));
  m.at<cv::Vec3f>(0, 0) = cv::Vec3f(-1, 2, std::nanf(""));
  ASSERT_TRUE(io::write_png16(dir / "c.png", m));
  auto back = io::read_linear_image(dir / "c.png");
  ASSERT_TRUE(back);
  EXPECT_EQ(back->at<cv::Vec3f>(0, 0), cv::Vec3f(0, 1, 0));
}

TEST(LinearImage, Reads8BitPngGreyAndPpm) {
  Scratch dir;
  cv::Mat bgr8(2, 2, CV_8UC3, cv::Scalar(10, 20, 255));
  cv::imwrite((dir / "c8.png").string(), bgr8);
  auto c8 = io::read_linear_image(dir / "c8.png");
  ASSERT_TRUE(c8) << c8.message();
  EXPECT_NEAR(c8->at<cv::Vec3f>(1, 1)[2], 1.0f, 1e-6);
  EXPECT_NEAR(c8->at<cv::Vec3f>(1, 1)[0], 10.0f / 255, 1e-6);

  cv::Mat grey(3, 2, CV_16UC1, cv::Scalar(65535 / 5));
  cv::imwrite((dir / "g16.png").string(), grey);
  auto g = io::read_linear_image(dir / "g16.png");
  ASSERT_TRUE(g);
  EXPECT_EQ(g->type(), CV_32FC3);
  EXPECT_NEAR(g->at<cv::Vec3f>(2, 1)[1], 0.2f, 1e-6);

  // PPM stores R,G,B; 16-bit samples are big-endian.
  std::string ppm = "P6\n1 1\n65535\n";
  for (uint16_t v : {uint16_t(65535), uint16_t(0), uint16_t(32768)}) {
    ppm.push_back(static_cast<char>(v >> 8));
    ppm.push_back(static_cast<char>(v & 0xff));
  }
  spit(dir / "x.ppm", ppm);
  auto p = io::read_linear_image(dir / "x.ppm");
  ASSERT_TRUE(p) << p.message();
  EXPECT_NEAR(p->at<cv::Vec3f>(0, 0)[2], 1.0f, 1e-6);  // red
  EXPECT_NEAR(p->at<cv::Vec3f>(0, 0)[1], 0.0f, 1e-6);
  EXPECT_NEAR(p->at<cv::Vec3f>(0, 0)[0], 32768.0f / 65535, 1e-6);  // blue
  // An ASCII PPM whose samples are all there still reads.
  spit(dir / "a.ppm", "P3\n2 1\n255\n255 0 0 0 0 255\n");
  auto a = io::read_linear_image(dir / "a.ppm");
  ASSERT_TRUE(a) << a.message();
  EXPECT_NEAR(a->at<cv::Vec3f>(0, 0)[2], 1.0f, 1e-6);  // red
  EXPECT_NEAR(a->at<cv::Vec3f>(0, 1)[0], 1.0f, 1e-6);  // blue
}

TEST(LinearImage, DamagedFilesAreRefusedNamingTheFile) {
  Scratch dir;
  cv::Mat m(64, 64, CV_32FC3);
  cv::RNG(5).fill(m, cv::RNG::UNIFORM, cv::Scalar::all(0), cv::Scalar::all(1));
  ASSERT_TRUE(io::write_png16(dir / "good.png", m));
  const std::string good = slurp(dir / "good.png");
  struct Case {
    std::string bytes, expect;
  };
  for (const Case& c : {Case{good.substr(0, good.size() / 2), "truncated"},
                        Case{good.substr(0, good.size() - 12), "truncated"},  // IEND missing
                        Case{good.substr(0, 20), "truncated"}, Case{"GIF89a....", "not a PNG"},
                        Case{"", "empty"}, Case{"P6\n4 4\n255\nabc", "truncated"}, Case{"P6\n0 4\n255\n", "size"},
                        // ASCII variants declaring more samples than their bytes can hold
                        // (fuzz_png: 18 bytes declaring 266666x3534 asked OpenCV for 2.8 GB)
                        Case{"P3\n266666\n3534\r3\r3", "size"}, Case{"P3\n26666\n3534\r3\r3", "truncated"}, Case{"P2\n3 3\n255\n1 2 3", "truncated"},
                        Case{"P1\n4000 4000\n0101", "truncated"}, Case{"P4\n64 64\nab", "truncated"}}) {
    spit(dir / "damaged.png", c.bytes);
    auto r = io::read_linear_image(dir / "damaged.png");
    ASSERT_FALSE(r) << c.expect;
    EXPECT_NE(r.message().find("damaged.png"), std::string::npos) << r.message();
    EXPECT_NE(r.message().find(c.expect), std::string::npos) << r.message();
  }
  // Corrupt pixel data with an intact chunk chain: the decoder itself refuses.
  std::string flipped = good;
  size_t idat = flipped.find("IDAT");
  ASSERT_NE(idat, std::string::npos);
  for (size_t i = idat + 4; i < idat + 200 && i < flipped.size(); ++i) flipped[i] = static_cast<char>(~flipped[i]);
  spit(dir / "flipped.png", flipped);
  auto r = io::read_linear_image(dir / "flipped.png");
  ASSERT_FALSE(r);
  EXPECT_NE(r.message().find("flipped.png"), std::string::npos) << r.message();
  // A header claiming an absurd size is refused before any allocation.
  std::string wide = good;
  wide[16] = wide[17] = wide[18] = wide[19] = '\x7f';  // IHDR width
  spit(dir / "wide.png", wide);
  auto w = io::read_linear_image(dir / "wide.png");
  ASSERT_FALSE(w);
  EXPECT_NE(w.message().find("wide.png"), std::string::npos) << w.message();
  EXPECT_NE(w.message().find("out of range"), std::string::npos) << w.message();
  auto missing = io::read_linear_image(dir / "nope.png");
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.message().find("nope.png"), std::string::npos);
}

TEST(Pictures, NormalsPictureColoursAndBlackOutside) {
  cv::Mat n(1, 3, CV_32FC3, cv::Scalar::all(0));
  n.at<cv::Vec3f>(0, 0) = cv::Vec3f(0, 0, 1);
  n.at<cv::Vec3f>(0, 1) = cv::Vec3f(1, 0, 0);
  cv::Mat p = io::normals_picture(n);
  ASSERT_EQ(p.type(), CV_8UC3);
  EXPECT_EQ(p.at<cv::Vec3b>(0, 0), cv::Vec3b(255, 128, 128));  // B = z
  EXPECT_EQ(p.at<cv::Vec3b>(0, 1), cv::Vec3b(128, 128, 255));  // R = x
  EXPECT_EQ(p.at<cv::Vec3b>(0, 2), cv::Vec3b(0, 0, 0));
}

TEST(Pictures, TonemapPutsPercentileAtWhiteWithSrgbGamma) {
  cv::Mat lin(1, 100, CV_32FC3);
  for (int i = 0; i < 100; ++i) lin.at<cv::Vec3f>(0, i) = cv::Vec3f::all(0.001f * (i + 1));
  cv::Mat p = io::tonemap_picture(lin, 100.0);
  ASSERT_EQ(p.type(), CV_8UC3);
  EXPECT_EQ(p.at<cv::Vec3b>(0, 99)[0], 255);
  // Half of white in linear light is sRGB 188.
  EXPECT_NEAR(p.at<cv::Vec3b>(0, 49)[1], 188, 1);
}

TEST(Files, WriteFileAtomicLeavesNoTemporary) {
  Scratch dir;
  ASSERT_TRUE(io::write_file_atomic(dir / "f.txt", "one"));
  ASSERT_TRUE(io::write_file_atomic(dir / "f.txt", "two"));
  EXPECT_EQ(slurp(dir / "f.txt"), "two");
  int entries = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator(dir.path())) ++entries;
  EXPECT_EQ(entries, 1);
  auto bad = io::write_file_atomic(dir / "no-such-folder" / "f.txt", "x");
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.message().find("f.txt"), std::string::npos);
}

}  // namespace
}  // namespace veneer
