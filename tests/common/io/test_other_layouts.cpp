// The capture folders other rigs write: RTI folders (photos + a .lp light
// file, as RTIBuilder and Relight read them), and JPEG, TIFF and RAW photos
// in the DiLiGenT and thesis layouts; `veneer info` says how it read them.
#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "test_util.hpp"
#include "veneer/io/dng.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/io/imageset.hpp"
#include "veneer/ps/photometric_stereo.hpp"

namespace veneer {
namespace {
namespace fs = std::filesystem;
using test::Scratch;
using test::slurp;
using test::spit;

const fs::path kCat = fs::path(VENEER_SHARED_DATA) / "real" / "cat";

double srgb_to_linear(double code) {
  const double c = code / 255.0;
  return c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4);
}

std::vector<cv::Vec3d> cat_directions() {
  std::vector<cv::Vec3d> dirs;
  std::ifstream in(kCat / "light_directions.txt");
  double x, y, z;
  while (in >> x >> y >> z) dirs.emplace_back(x, y, z);
  return dirs;
}

double median_angle_deg(const cv::Mat& a, const cv::Mat& b, const cv::Mat& mask) {
  std::vector<double> deg;
  for (int y = 0; y < a.rows; ++y)
    for (int x = 0; x < a.cols; ++x) {
      if (!mask.at<uchar>(y, x)) continue;
      const cv::Vec3f p = a.at<cv::Vec3f>(y, x), q = b.at<cv::Vec3f>(y, x);
      const double d = std::clamp(double(p.dot(q)) / (cv::norm(p) * cv::norm(q) + 1e-12), -1.0, 1.0);
      deg.push_back(std::acos(d) * 180 / CV_PI);
    }
  if (deg.empty()) return 180;
  std::nth_element(deg.begin(), deg.begin() + long(deg.size() / 2), deg.end());
  return deg[deg.size() / 2];
}

// An RTIBuilder project made of the cat's photos as 8-bit sRGB JPEGs:
// jpeg-exports/NNN.jpg and assembly-files/cat.lp naming them by the absolute
// Windows paths RTIBuilder writes (with a space in them). `y_sign` -1 writes
// the directions with y pointing down the image (the wrong convention).
void write_rti_project(const fs::path& dir, const std::vector<std::string>& jpegs, double y_sign = 1) {
  fs::create_directories(dir / "jpeg-exports");
  fs::create_directories(dir / "assembly-files");
  const auto dirs = cat_directions();
  std::ofstream lp(dir / "assembly-files" / "cat.lp");
  lp << jpegs.size() << "\n";
  for (size_t i = 0; i < jpegs.size(); ++i) {
    char name[48];
    std::snprintf(name, sizeof name, "%03zu.jpg", i + 1);
    spit(dir / "jpeg-exports" / name, jpegs[i]);
    lp << "C:\\Users\\RTI user\\cat\\jpeg-exports\\" << name << " " << dirs[i][0] << " " << y_sign * dirs[i][1] << " "
       << dirs[i][2] << "\r\n";
  }
  fs::copy_file(kCat / "mask.png", dir / "mask.png");
}

std::vector<std::string> cat_jpegs() {
  std::vector<std::string> out;
  for (int i = 1; i <= 12; ++i) {
    char name[48];
    std::snprintf(name, sizeof name, "%03d.png", i);
    cv::Mat bgr8 = cv::imread((kCat / name).string(), cv::IMREAD_COLOR);
    EXPECT_FALSE(bgr8.empty()) << name;
    std::vector<uchar> bytes;
    cv::imencode(".jpg", bgr8, bytes, {cv::IMWRITE_JPEG_QUALITY, 95});
    out.emplace_back(bytes.begin(), bytes.end());
  }
  return out;
}

// Issue 37: an RTI folder of 8-bit sRGB JPEGs of a real object gives the
// normals a correct reader gives -- the same JPEGs linearised and read in the
// DiLiGenT layout -- within 0.5 deg median. The same folder with y written
// pointing down is far off, so the comparison sees the convention.
TEST(RtiFolder, CatJpegsGiveTheNormalsOfTheSameJpegsReadAsDiLiGenT) {
  if (!fs::exists(kCat / "filenames.txt")) GTEST_SKIP() << "no real cat set at " << kCat;
  Scratch dir;
  const auto jpegs = cat_jpegs();
  write_rti_project(dir / "rti", jpegs);
  // The DiLiGenT folder: the same JPEG files, the cat's directions and mask.
  fs::create_directories(dir / "diligent");
  {
    std::ofstream names(dir / "diligent" / "filenames.txt");
    for (size_t i = 0; i < jpegs.size(); ++i) {
      char name[48];
      std::snprintf(name, sizeof name, "%03zu.jpg", i + 1);
      spit(dir / "diligent" / name, jpegs[i]);
      names << name << "\n";
    }
  }
  fs::copy_file(kCat / "light_directions.txt", dir / "diligent" / "light_directions.txt");
  fs::copy_file(kCat / "mask.png", dir / "diligent" / "mask.png");

  auto rti = io::read_set(dir / "rti");
  ASSERT_TRUE(rti) << rti.message();
  auto diligent = io::read_set(dir / "diligent");
  ASSERT_TRUE(diligent) << diligent.message();
  EXPECT_EQ(rti->layout, "RTI .lp");
  EXPECT_EQ(rti->photos_from, "jpeg");
  EXPECT_NE(rti->photos_read.find("inverse sRGB"), std::string::npos) << rti->photos_read;
  ASSERT_EQ(rti->lights.size(), 12u);
  EXPECT_EQ(rti->lights[0].lamp_id, "001");
  ASSERT_FALSE(rti->mask.empty());

  // The linearisation: a JPEG pixel decoded by OpenCV, through the sRGB curve.
  cv::Mat bgr8 = cv::imdecode(cv::Mat(1, int(jpegs[3].size()), CV_8UC1, const_cast<char*>(jpegs[3].data())),
                              cv::IMREAD_COLOR);
  const cv::Vec3b code = bgr8.at<cv::Vec3b>(170, 256);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(rti->images[3].at<cv::Vec3f>(170, 256)[c], srgb_to_linear(code[c]), 1e-6);

  auto from_rti = ps::photometric_stereo(*rti, rti->mask);
  auto from_diligent = ps::photometric_stereo(*diligent, diligent->mask);
  ASSERT_TRUE(from_rti) << from_rti.message();
  ASSERT_TRUE(from_diligent) << from_diligent.message();
  const double agree = median_angle_deg(from_rti->normals, from_diligent->normals, rti->mask);

  write_rti_project(dir / "rti-y-down", jpegs, -1);
  auto flipped = io::read_set(dir / "rti-y-down");
  ASSERT_TRUE(flipped) << flipped.message();
  auto from_flipped = ps::photometric_stereo(*flipped, flipped->mask);
  ASSERT_TRUE(from_flipped) << from_flipped.message();
  const double wrong = median_angle_deg(from_flipped->normals, from_diligent->normals, rti->mask);
  std::printf("cat, RTI folder of JPEGs against the same JPEGs as DiLiGenT: median %.3f deg; with y written down: "
              "%.1f deg\n",
              agree, wrong);
  EXPECT_LT(agree, 0.5);
  EXPECT_GT(wrong, 5.0);
}

// The real sets' 8-bit PNGs read as they always were (linear, code / 255) in
// the DiLiGenT layout; in an RTI folder 8-bit PNG and TIFF photos are sRGB and
// linearised, 16-bit ones are linear.
TEST(RtiFolder, EightBitPhotosAreLinearisedSixteenBitAreNot) {
  if (fs::exists(kCat / "filenames.txt")) {
    auto cat = io::read_set(kCat);
    ASSERT_TRUE(cat) << cat.message();
    EXPECT_EQ(cat->photos_from, "png");
    EXPECT_NE(cat->photos_read.find("taken as linear"), std::string::npos) << cat->photos_read;
    cv::Mat bgr8 = cv::imread((kCat / "001.png").string(), cv::IMREAD_COLOR);
    const cv::Vec3b code = bgr8.at<cv::Vec3b>(170, 256);
    for (int c = 0; c < 3; ++c) EXPECT_FLOAT_EQ(cat->images[0].at<cv::Vec3f>(170, 256)[c], code[c] / 255.0f);
  }
  Scratch dir;
  const cv::Size size(8, 6);
  cv::imwrite((dir / "a.png").string(), cv::Mat(size, CV_8UC3, cv::Scalar(64, 128, 200)));
  cv::imwrite((dir / "b.tif").string(), cv::Mat(size, CV_8UC3, cv::Scalar(64, 128, 200)));
  cv::imwrite((dir / "c.tif").string(), cv::Mat(size, CV_16UC3, cv::Scalar(16384, 32768, 65535)));
  cv::imwrite((dir / "d.png").string(), cv::Mat(size, CV_16UC3, cv::Scalar(16384, 32768, 65535)));
  spit(dir / "lights.lp", "4\na.png 0 0 1\nb.tif 0.5 0 0.866025\nc.tif 0 0.5 0.866025\nd.png 0 -1 1\n");
  auto set = io::read_set(dir.path());
  ASSERT_TRUE(set) << set.message();
  EXPECT_EQ(set->layout, "RTI .lp");
  EXPECT_EQ(set->photos_from, "mixed");
  for (int i : {0, 1}) {
    const cv::Vec3f p = set->images[size_t(i)].at<cv::Vec3f>(2, 3);
    EXPECT_NEAR(p[0], srgb_to_linear(64), 1e-6) << i;
    EXPECT_NEAR(p[1], srgb_to_linear(128), 1e-6) << i;
    EXPECT_NEAR(p[2], srgb_to_linear(200), 1e-6) << i;
  }
  for (int i : {2, 3}) {
    const cv::Vec3f p = set->images[size_t(i)].at<cv::Vec3f>(2, 3);
    EXPECT_NEAR(p[0], 0.25, 1e-4) << i;
    EXPECT_NEAR(p[1], 0.5, 1e-4) << i;
    EXPECT_NEAR(p[2], 1.0, 1e-6) << i;
  }
  // Directions are normalised (Relight does not promise unit vectors), with a warning.
  EXPECT_NEAR(set->lights[3].direction[1], -std::sqrt(0.5), 1e-9);
  EXPECT_NEAR(set->lights[3].direction[2], std::sqrt(0.5), 1e-9);
  ASSERT_EQ(set->warnings.size(), 1u);
  EXPECT_NE(set->warnings[0].find("normalised"), std::string::npos);
}

// Each bad light file is refused with one error naming the file and line.
TEST(RtiFolder, BadLightFilesAreRefusedWithTheirLine) {
  Scratch dir;
  cv::imwrite((dir / "a.jpg").string(), cv::Mat(6, 8, CV_8UC3, cv::Scalar::all(90)));
  cv::imwrite((dir / "b.jpg").string(), cv::Mat(6, 8, CV_8UC3, cv::Scalar::all(90)));
  struct Case {
    const char* text;
    const char* expect;
  };
  for (const Case& c : {Case{"3\na.jpg 0 0 1\nb.jpg 0 0 1\n", "says 3 photos"},
                        Case{"two\na.jpg 0 0 1\nb.jpg 0 0 1\n", "line 1: expected the number of photos"},
                        Case{"2\na.jpg 0 0 1\nb.jpg 0 x 1\n", "line 3: expected \"<file> <x> <y> <z>\""},
                        Case{"2\na.jpg 0 0 1\nb.jpg 0 0 0\n", "line 3: light direction"},
                        Case{"2\na.jpg 0 0 1\nc.jpg 0 0 1\n", "photo \"c.jpg\" not found"},
                        Case{"2\na.jpg 0 0 1\na.jpg 0 1 1\n", "listed twice"}}) {
    SCOPED_TRACE(c.text);
    spit(dir / "set.lp", c.text);
    auto set = io::read_set(dir.path());
    ASSERT_FALSE(set);
    EXPECT_NE(set.message().find("set.lp"), std::string::npos) << set.message();
    EXPECT_NE(set.message().find(c.expect), std::string::npos) << set.message();
  }
  spit(dir / "set.lp", "2\na.jpg 0 0 1\nb.jpg 0 1 1\n");
  EXPECT_TRUE(io::read_set(dir.path()));
  spit(dir / "other.lp", "2\na.jpg 0 0 1\nb.jpg 0 1 1\n");
  auto two = io::read_set(dir.path());
  ASSERT_FALSE(two);
  EXPECT_NE(two.message().find("2 RTI light files"), std::string::npos) << two.message();
}

// DNG photos in DiLiGenT and thesis folders go through LibRaw; JPEG and TIFF
// photos are read in the thesis layout too; a list mixing RAW and developed
// photos is refused.
TEST(OtherLayouts, RawJpegAndTiffPhotosInTheDiLiGenTAndThesisLayouts) {
  Scratch dir;
  const cv::Size size(64, 48);
  cv::Mat photo(size, CV_32FC3);
  cv::randu(photo, 0.1, 0.6);
  const auto dng = io::encode_dng(photo);
  ASSERT_TRUE(dng) << dng.message();
  fs::create_directories(dir / "d");
  spit(dir / "d" / "filenames.txt", "one.DNG\ntwo.dng\n");
  spit(dir / "d" / "light_directions.txt", "0 0 1\n0.6 0 0.8\n");
  spit(dir / "d" / "one.DNG", *dng);
  spit(dir / "d" / "two.dng", *dng);
  auto d = io::read_set(dir / "d");
  ASSERT_TRUE(d) << d.message();
  EXPECT_EQ(d->photos_from, "raw");
  EXPECT_NE(d->photos_read.find("LibRaw"), std::string::npos) << d->photos_read;
  ASSERT_EQ(d->size, size);
  // The measured channel of each Bayer cell comes back (the rig's DNG is RGGB).
  EXPECT_NEAR(d->images[0].at<cv::Vec3f>(10, 10)[2], photo.at<cv::Vec3f>(10, 10)[2], 2e-3);
  EXPECT_NEAR(d->images[0].at<cv::Vec3f>(11, 11)[0], photo.at<cv::Vec3f>(11, 11)[0], 2e-3);
  io::ReadOptions half;
  half.raw.half_size = true;
  auto small = io::read_set(dir / "d", half);
  ASSERT_TRUE(small) << small.message();
  EXPECT_EQ(small->size, cv::Size(32, 24));

  spit(dir / "d" / "two.png", slurp(dir / "d" / "one.DNG"));  // wrong name: a DNG called .png
  spit(dir / "d" / "filenames.txt", "one.DNG\ntwo.png\n");
  auto mixed = io::read_set(dir / "d");
  ASSERT_FALSE(mixed);
  EXPECT_NE(mixed.message().find("RAW"), std::string::npos) << mixed.message();

  fs::create_directories(dir / "t");
  spit(dir / "t" / "lights.txt", "0 0 1\n0.6 0 0.8\n0 0.6 0.8\n");
  cv::Mat bgr8(size, CV_8UC3, cv::Scalar(30, 60, 90));
  cv::imwrite((dir / "t" / "1.jpg").string(), bgr8);
  cv::imwrite((dir / "t" / "2.jpeg").string(), bgr8);
  cv::imwrite((dir / "t" / "3.tif").string(), cv::Mat(size, CV_16UC3, cv::Scalar::all(1000)));
  auto t = io::read_set(dir / "t");
  ASSERT_TRUE(t) << t.message();
  EXPECT_EQ(t->layout, "thesis");
  EXPECT_EQ(t->images.size(), 3u);
  EXPECT_NEAR(t->images[0].at<cv::Vec3f>(5, 5)[2], srgb_to_linear(90), 0.01);  // JPEG: sRGB, lossy
  EXPECT_NEAR(t->images[2].at<cv::Vec3f>(5, 5)[1], 1000 / 65535.0, 1e-6);

  fs::create_directories(dir / "r");
  spit(dir / "r" / "lights.txt", "0 0 1\n0.6 0 0.8\n");
  spit(dir / "r" / "1.dng", *dng);
  spit(dir / "r" / "2.dng", *dng);
  auto r = io::read_set(dir / "r");
  ASSERT_TRUE(r) << r.message();
  EXPECT_EQ(r->photos_from, "raw");
}

std::pair<std::string, int> run_veneer(const std::string& args) {
  std::string cmd = std::string(VENEER_BIN_DIR) + "/veneer " + args + " 2>&1";
  std::string out;
  FILE* pipe = ::popen(cmd.c_str(), "r");
  if (!pipe) return {"", -1};
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, pipe)) > 0) out.append(buf, n);
  const int status = ::pclose(pipe);
  return {out, WIFEXITED(status) ? WEXITSTATUS(status) : -1};
}

TEST(InfoCommand, SaysWhichLayoutAndHowThePhotosAreRead) {
  if (!fs::exists(fs::path(VENEER_BIN_DIR) / "veneer")) GTEST_SKIP() << "veneer is not built in " << VENEER_BIN_DIR;
  if (!fs::exists(kCat / "filenames.txt")) GTEST_SKIP() << "no real cat set at " << kCat;
  Scratch dir;
  write_rti_project(dir / "rti", cat_jpegs());
  auto [rti, rc] = run_veneer("info " + (dir / "rti").string());
  EXPECT_EQ(rc, 0) << rti;
  for (const char* part : {"RTI .lp", "12 files: 8-bit JPEG, sRGB: linearised through the inverse sRGB curve",
                           "assembly-files/cat.lp", "512x340"})
    EXPECT_NE(rti.find(part), std::string::npos) << part << " not in:\n" << rti;
  auto [cat, rc2] = run_veneer("info " + kCat.string());
  EXPECT_EQ(rc2, 0) << cat;
  for (const char* part : {"DiLiGenT", "8-bit PNG, taken as linear"})
    EXPECT_NE(cat.find(part), std::string::npos) << part << " not in:\n" << cat;
}

}  // namespace
}  // namespace veneer
