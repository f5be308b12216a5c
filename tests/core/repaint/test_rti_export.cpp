// The PTM export of a transfer's repainted photos, read back by a reader
// written here from the format's description only (HP Labs, "Polynomial
// Texture Map (.ptm) File Format", v1.2): five header lines (version, format,
// "width height", six scales, six biases), then the bytes, rows bottom to
// top; coefficient = (byte - bias) * scale; C = a0 u^2 + a1 v^2 + a2 uv +
// a3 u + a4 v + a5 for the light's projected direction (u, v); RGB: a block
// of six bytes per pixel for each of R, G, B; LRGB: a block of six luminance
// bytes per pixel, then a block of R, G, B bytes, C = L * colour.
// Evaluated at each lamp's direction it reproduces the repainted photos
// within the residual the export reports (issue 37).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>

#include <gtest/gtest.h>

#include "veneer/pipeline/transfer.hpp"
#include "veneer/repaint/rti_export.hpp"
#include "veneer/sim/simulator.hpp"

namespace veneer {
namespace {
namespace fs = std::filesystem;

struct Ptm {
  std::string format;
  int width = 0, height = 0;
  double scale[6] = {}, bias[6] = {};
  std::vector<unsigned char> data;  // everything after the header
  bool lrgb() const { return format == "PTM_FORMAT_LRGB"; }

  // The display value (0..255) of pixel (x, y) -- y counted from the top of
  // the picture -- channel c (0 = R), under a light of unit direction d.
  double evaluate(int x, int y, int c, const cv::Vec3d& d, bool rows_top_down = false) const {
    const int row = rows_top_down ? y : height - 1 - y;  // the file's row
    const size_t pixel = static_cast<size_t>(row) * width + x;
    const size_t plane = static_cast<size_t>(width) * height;
    const unsigned char* a = lrgb() ? &data[pixel * 6] : &data[(static_cast<size_t>(c) * plane + pixel) * 6];
    const double u = d[0], v = d[1];
    const double terms[6] = {u * u, v * v, u * v, u, v, 1};
    double value = 0;
    for (int k = 0; k < 6; ++k) value += (a[k] - bias[k]) * scale[k] * terms[k];
    if (lrgb()) value *= data[plane * 6 + pixel * 3 + static_cast<size_t>(c)];
    return std::clamp(value, 0.0, 255.0);
  }
};

Ptm read_ptm(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  std::string all((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  Ptm p;
  size_t pos = 0;
  auto line = [&] {
    const size_t end = all.find('\n', pos);
    std::string l = all.substr(pos, end - pos);
    pos = end + 1;
    return l;
  };
  EXPECT_EQ(line(), "PTM_1.2");
  p.format = line();
  std::istringstream(line()) >> p.width >> p.height;
  std::istringstream scales(line()), biases(line());
  for (int k = 0; k < 6; ++k) scales >> p.scale[k];
  for (int k = 0; k < 6; ++k) biases >> p.bias[k];
  p.data.assign(all.begin() + static_cast<long>(pos), all.end());
  const size_t plane = static_cast<size_t>(p.width) * p.height;
  EXPECT_EQ(p.data.size(), p.lrgb() ? plane * 9 : plane * 18) << "bytes after the header";
  return p;
}

// The photo as people look at it: exposure, then the sRGB curve, 0..255.
double display(float linear, double exposure) {
  const double v = std::clamp(linear * exposure, 0.0, 1.0);
  return 255 * (v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1 / 2.4) - 0.055);
}

// RMS over the picture between the file under lamp `d` and the photo.
double rms_against(const Ptm& p, const cv::Mat& photo, const cv::Vec3d& d, double exposure, bool rows_top_down = false) {
  double sq = 0;
  for (int y = 0; y < photo.rows; ++y)
    for (int x = 0; x < photo.cols; ++x)
      for (int c = 0; c < 3; ++c) {
        const double e = p.evaluate(x, y, c, d, rows_top_down) - display(photo.at<cv::Vec3f>(y, x)[2 - c], exposure);
        sq += e * e;
      }
  return std::sqrt(sq / (3.0 * photo.total()));
}

io::ImageSet simulated(const std::string& scene, io::Role role) {
  sim::RenderOptions o;
  o.size = {160, 106};
  auto set = sim::simulate_set(scene, o, role);
  EXPECT_TRUE(set) << set.message();
  return set ? std::move(set).value() : io::ImageSet{};
}

TEST(RtiExport, PtmReadFromItsDescriptionReproducesTheRepaintedPhotos) {
  const io::ImageSet dst = simulated("cup-white", io::Role::destination);
  const io::ImageSet src = simulated("orange", io::Role::source);
  pipeline::TransferOptions o;
  o.match.method = match::Method::linear;
  o.match.fast = false;
  o.truth_normals = true;
  auto result = pipeline::transfer(dst, src, o);
  ASSERT_TRUE(result) << result.message();
  ASSERT_EQ(result->repainted.size(), dst.lights.size());
  std::vector<cv::Vec3d> dirs;
  for (const io::Light& l : dst.lights) dirs.push_back(l.direction);

  const fs::path dir = fs::temp_directory_path() / ("veneer-rti-export-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  for (const auto format : {repaint::PtmFormat::lrgb, repaint::PtmFormat::rgb}) {
    SCOPED_TRACE(repaint::ptm_format_name(format));
    repaint::RtiExportOptions options;
    options.format = format;
    const fs::path file = dir / "out.ptm";
    auto fit = repaint::export_ptm(result->repainted, dirs, file, options);
    ASSERT_TRUE(fit) << fit.message();
    const Ptm ptm = read_ptm(file);
    EXPECT_EQ(ptm.format, repaint::ptm_format_name(format));
    ASSERT_EQ(ptm.width, dst.size.width);
    ASSERT_EQ(ptm.height, dst.size.height);
    ASSERT_EQ(fit->rms_per_lamp.size(), dirs.size());
    double sq = 0, flipped = 0;
    for (size_t i = 0; i < dirs.size(); ++i) {
      const double rms = rms_against(ptm, result->repainted[i], dirs[i], fit->exposure);
      EXPECT_LE(rms, fit->rms_per_lamp[i] + 0.01) << "lamp " << i;
      sq += rms * rms;
      flipped += rms_against(ptm, result->repainted[i], dirs[i], fit->exposure, true);
    }
    const double rms = std::sqrt(sq / static_cast<double>(dirs.size()));
    std::printf("%s: residual %.2f levels RMS (export reported %.2f, p99 %.2f; the photos spread %.2f about their "
                "mean), exposure %.3f; rows read top-down: %.2f\n",
                repaint::ptm_format_name(format), rms, fit->rms, fit->p99, fit->photo_spread, fit->exposure,
                flipped / static_cast<double>(dirs.size()));
    EXPECT_LE(rms, fit->rms + 0.01);
    // The fit explains the light: far below the photos' spread over the lamps.
    EXPECT_LT(fit->rms, 0.35 * fit->photo_spread);
    EXPECT_GT(flipped / static_cast<double>(dirs.size()), 3 * fit->rms);
  }

  // Refusals leave no file.
  const fs::path bad = dir / "bad.ptm";
  std::vector<cv::Mat> five(result->repainted.begin(), result->repainted.begin() + 5);
  auto few = repaint::export_ptm(five, {dirs.begin(), dirs.begin() + 5}, bad);
  ASSERT_FALSE(few);
  EXPECT_NE(few.message().find("at least 6"), std::string::npos) << few.message();
  auto mismatch = repaint::export_ptm(result->repainted, {dirs.begin(), dirs.begin() + 6}, bad);
  ASSERT_FALSE(mismatch);
  EXPECT_NE(mismatch.message().find("lamp directions"), std::string::npos) << mismatch.message();
  EXPECT_FALSE(fs::exists(bad));
  fs::remove_all(dir);
}

}  // namespace
}  // namespace veneer
