// The HSH basis and fit (repaint/hsh.hpp) and the HSH .rti export
// (rti_export.hpp, issue 40), the file read back by a reader written here from
// the format's description only (RTIViewer's and Relight's "#HSH1.2"): lines
// starting with '#', then the file type (3 = HSH), "width height bands",
// "terms basis_type element_size"; then terms little-endian float32 scales
// and terms biases; then bytes, rows bottom to top, per pixel per band (R, G,
// B) its terms; coefficient = byte / 255 * scale + bias; shown as
// clamp(sum coefficient * H(light), 0, 1) * 255, with the hemispherical
// harmonics written out below once more, from the published formulas.
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <numbers>
#include <sstream>

#include <gtest/gtest.h>

#include "veneer/pipeline/transfer.hpp"
#include "veneer/repaint/hsh.hpp"
#include "veneer/repaint/rti_export.hpp"
#include "veneer/sim/simulator.hpp"

namespace veneer {
namespace {
namespace fs = std::filesystem;

// Hemispherical harmonics, first three orders (9 terms), from theta (off the
// view axis) and phi (from the x axis toward y).
std::vector<double> reader_basis(const cv::Vec3d& light, int terms) {
  const double pi = std::numbers::pi;
  const cv::Vec3d d = light / cv::norm(light);
  const double theta = std::acos(std::min(1.0, d[2]));
  double phi = std::atan2(d[1], d[0]);
  if (phi < 0) phi += 2 * pi;
  const double ct = std::cos(theta);
  const double root = std::sqrt(std::max(0.0, ct - ct * ct));
  const double all[9] = {1 / std::sqrt(2 * pi),
                         std::sqrt(6 / pi) * std::cos(phi) * root,
                         std::sqrt(3 / (2 * pi)) * (-1 + 2 * ct),
                         std::sqrt(6 / pi) * root * std::sin(phi),
                         std::sqrt(30 / pi) * std::cos(2 * phi) * (-ct + ct * ct),
                         std::sqrt(30 / pi) * std::cos(phi) * (-1 + 2 * ct) * root,
                         std::sqrt(5 / (2 * pi)) * (1 - 6 * ct + 6 * ct * ct),
                         std::sqrt(30 / pi) * (-1 + 2 * ct) * root * std::sin(phi),
                         std::sqrt(30 / pi) * (-ct + ct * ct) * std::sin(2 * phi)};
  return {all, all + terms};
}

struct Hsh {
  int type = 0, width = 0, height = 0, bands = 0, terms = 0, basis_type = 0, element = 0;
  std::vector<float> scale, bias;
  std::vector<unsigned char> data;
  // display value 0..255 of pixel (x, y from the top), band b (0 = R)
  double evaluate(int x, int y, int b, const cv::Vec3d& light) const {
    const std::vector<double> h = reader_basis(light, terms);
    const size_t row = static_cast<size_t>(height - 1 - y);
    const unsigned char* c = &data[((row * width + x) * bands + b) * terms];
    double v = 0;
    for (int k = 0; k < terms; ++k) v += (c[k] / 255.0 * scale[k] + bias[k]) * h[k];
    return std::clamp(v, 0.0, 1.0) * 255.0;
  }
};

Hsh read_hsh(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  std::string all((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  size_t pos = 0;
  auto line = [&] {
    const size_t end = all.find('\n', pos);
    std::string s = all.substr(pos, end - pos);
    pos = end + 1;
    return s;
  };
  Hsh h;
  EXPECT_EQ(all.compare(0, 7, "#HSH1.2"), 0);
  while (pos < all.size() && all[pos] == '#') line();
  std::istringstream(line()) >> h.type;
  std::istringstream(line()) >> h.width >> h.height >> h.bands;
  std::istringstream(line()) >> h.terms >> h.basis_type >> h.element;
  h.scale.resize(static_cast<size_t>(h.terms));
  h.bias.resize(static_cast<size_t>(h.terms));
  std::memcpy(h.scale.data(), &all[pos], 4 * static_cast<size_t>(h.terms));
  pos += 4 * static_cast<size_t>(h.terms);
  std::memcpy(h.bias.data(), &all[pos], 4 * static_cast<size_t>(h.terms));
  pos += 4 * static_cast<size_t>(h.terms);
  h.data.assign(all.begin() + static_cast<long>(pos), all.end());
  EXPECT_EQ(h.data.size(), static_cast<size_t>(h.width) * h.height * h.bands * h.terms) << "bytes after the header";
  return h;
}

double display(float linear, double exposure) {
  const double v = std::clamp(linear * exposure, 0.0, 1.0);
  return 255 * (v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1 / 2.4) - 0.055);
}

double rms_against(const Hsh& h, const cv::Mat& photo, const cv::Vec3d& d, double exposure) {
  double sq = 0;
  for (int y = 0; y < photo.rows; ++y)
    for (int x = 0; x < photo.cols; ++x)
      for (int c = 0; c < 3; ++c) {
        const double e = h.evaluate(x, y, c, d) - display(photo.at<cv::Vec3f>(y, x)[2 - c], exposure);
        sq += e * e;
      }
  return std::sqrt(sq / (3.0 * photo.total()));
}

// A Lambertian hemisphere (a dome seen from above) with a coloured texture,
// under distant lamps: linear CV_32FC3 BGR photos.
std::vector<cv::Mat> lambert_scene(const std::vector<cv::Vec3d>& lamps, cv::Size size) {
  std::vector<cv::Mat> photos;
  for (const cv::Vec3d& lamp : lamps) {
    const cv::Vec3d l = lamp / cv::norm(lamp);
    cv::Mat p(size, CV_32FC3, cv::Scalar::all(0.02));
    for (int y = 0; y < size.height; ++y)
      for (int x = 0; x < size.width; ++x) {
        const double u = (x + 0.5) / size.width * 2 - 1, v = 1 - (y + 0.5) / size.height * 2;
        if (u * u + v * v >= 0.95) continue;
        const cv::Vec3d n(u, v, std::sqrt(1 - u * u - v * v));
        const double shade = std::max(0.0, n.dot(l));
        const cv::Vec3d albedo(0.3 + 0.2 * std::sin(9 * u), 0.5, 0.7 + 0.2 * std::cos(7 * v));  // B, G, R
        for (int c = 0; c < 3; ++c) p.at<cv::Vec3f>(y, x)[c] = static_cast<float>(0.8 * albedo[c] * shade);
      }
    photos.push_back(p);
  }
  return photos;
}

// Lamps on rings of a dome: `rings` x `per_ring`, from 20 to 70 degrees off the axis.
std::vector<cv::Vec3d> dome(int rings, int per_ring) {
  std::vector<cv::Vec3d> out;
  for (int r = 0; r < rings; ++r) {
    const double theta = (20.0 + 50.0 * r / std::max(1, rings - 1)) * std::numbers::pi / 180;
    for (int k = 0; k < per_ring; ++k) {
      const double phi = (k + 0.5 * r) * 2 * std::numbers::pi / per_ring;
      out.push_back({std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta)});
    }
  }
  return out;
}

std::vector<cv::Vec3d> rig_directions() {
  std::vector<cv::Vec3d> out;
  for (const auto& l : sim::thesis_rig()) out.push_back(l.position_m / cv::norm(l.position_m));
  return out;
}

TEST(Hsh, BasisIsTheReadersAndTheFitRecoversKnownCoefficients) {
  // the library's basis against the reader's, off the axes
  for (const cv::Vec3d& d : dome(3, 5)) {
    const auto a = repaint::hsh_basis(d, 3), b = reader_basis(d, 9);
    ASSERT_EQ(a.size(), 9u);
    for (int k = 0; k < 9; ++k) EXPECT_NEAR(a[k], b[k], 1e-12) << "term " << k;
  }
  EXPECT_EQ(repaint::hsh_basis({0, 0, 1}, 2).size(), 4u);
  EXPECT_TRUE(repaint::hsh_basis({0, 0, 1}, 4).empty());
  EXPECT_EQ(repaint::hsh_order_for(7), 2);
  EXPECT_EQ(repaint::hsh_order_for(9), 3);
  EXPECT_EQ(repaint::hsh_order_for(3), 1);
  EXPECT_EQ(repaint::hsh_order_for(0), 0);
  // images made from known coefficients over 15 dome lamps come back to them
  const std::vector<cv::Vec3d> lamps = dome(3, 5);
  const cv::Size size(8, 5);
  cv::Mat truth(size, CV_32FC(9));
  cv::RNG rng(40);
  rng.fill(truth, cv::RNG::UNIFORM, -1, 1);
  std::vector<cv::Mat> images;
  for (const cv::Vec3d& d : lamps) {
    const auto h = repaint::hsh_basis(d, 3);
    cv::Mat im(size, CV_32FC1);
    for (int y = 0; y < size.height; ++y)
      for (int x = 0; x < size.width; ++x) {
        double v = 0;
        for (int k = 0; k < 9; ++k) v += truth.ptr<float>(y)[x * 9 + k] * h[static_cast<size_t>(k)];
        im.at<float>(y, x) = static_cast<float>(v);
      }
    images.push_back(im);
  }
  auto fit = repaint::fit_hsh(images, lamps, 3);
  ASSERT_TRUE(fit) << fit.message();
  ASSERT_EQ(fit->coefficients.size(), 1u);
  EXPECT_EQ(fit->coefficients[0].type(), CV_32FC(9));
  EXPECT_LT(cv::norm(fit->coefficients[0], truth, cv::NORM_INF), 1e-4);
  EXPECT_LT(fit->rms, 1e-5);
  EXPECT_LT(cv::norm(repaint::evaluate_hsh(*fit, lamps[4]), images[4], cv::NORM_INF), 1e-4);
}

TEST(Hsh, BadInputGivesOneClearError) {
  const std::vector<cv::Vec3d> rig = rig_directions();
  const std::vector<cv::Mat> photos = lambert_scene(rig, {16, 16});
  auto none = repaint::fit_hsh({}, {}, 2);
  ASSERT_FALSE(none);
  EXPECT_NE(none.message().find("no lamps"), std::string::npos) << none.message();
  auto few = repaint::fit_hsh(photos, rig, 3);  // 9 coefficients, 7 lamps
  ASSERT_FALSE(few);
  EXPECT_NE(few.message().find("9 coefficients per colour, 7 lamps cannot determine them"), std::string::npos)
      << few.message();
  auto mismatch = repaint::fit_hsh(photos, {rig.begin(), rig.begin() + 5}, 1);
  ASSERT_FALSE(mismatch);
  EXPECT_NE(mismatch.message().find("lamp directions"), std::string::npos) << mismatch.message();
  std::vector<cv::Vec3d> below = rig;
  below[2][2] = -0.1;
  auto under = repaint::fit_hsh(photos, below, 2);
  ASSERT_FALSE(under);
  EXPECT_NE(under.message().find("horizon"), std::string::npos) << under.message();

  const fs::path dir = fs::temp_directory_path() / ("veneer-hsh-bad-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const fs::path bad = dir / "bad.rti";
  auto no_lamps = repaint::export_hsh({}, {}, bad);
  ASSERT_FALSE(no_lamps);
  EXPECT_NE(no_lamps.message().find("no lamps"), std::string::npos) << no_lamps.message();
  auto order3 = repaint::export_hsh(photos, rig, bad, {.order = 3});
  ASSERT_FALSE(order3);
  EXPECT_NE(order3.message().find("7 lamps cannot determine"), std::string::npos) << order3.message();
  EXPECT_FALSE(fs::exists(bad));
  fs::remove_all(dir);
}

// A synthetic Lambert scene through the export and the reader: the rig's 7
// lamps (automatic order: 2, 4 terms) and a 25-lamp dome at order 3.
TEST(Hsh, ReaderFromTheDescriptionReproducesALambertSceneWithinTheResidual) {
  const fs::path dir = fs::temp_directory_path() / ("veneer-hsh-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  struct Case {
    const char* name;
    std::vector<cv::Vec3d> lamps;
    int order, expect_order;
  };
  for (const Case& c : {Case{"rig, 7 lamps, automatic", rig_directions(), 0, 2}, Case{"dome, 25 lamps, order 3", dome(5, 5), 3, 3}}) {
    SCOPED_TRACE(c.name);
    const std::vector<cv::Mat> photos = lambert_scene(c.lamps, {64, 48});
    const fs::path file = dir / "out.rti";
    auto fit = repaint::export_hsh(photos, c.lamps, file, {.order = c.order});
    ASSERT_TRUE(fit) << fit.message();
    EXPECT_EQ(fit->hsh_order, c.expect_order);
    const Hsh h = read_hsh(file);
    EXPECT_EQ(h.type, 3);
    EXPECT_EQ(h.width, 64);
    EXPECT_EQ(h.height, 48);
    EXPECT_EQ(h.bands, 3);
    EXPECT_EQ(h.terms, c.expect_order * c.expect_order);
    EXPECT_EQ(h.element, 1);
    double sq = 0;
    for (size_t i = 0; i < c.lamps.size(); ++i) {
      const double rms = rms_against(h, photos[i], c.lamps[i], fit->exposure);
      EXPECT_LE(rms, fit->rms_per_lamp[i] + 0.01) << "lamp " << i;
      sq += rms * rms;
    }
    const double rms = std::sqrt(sq / static_cast<double>(c.lamps.size()));
    std::printf("%s: reader's residual %.2f levels RMS (export reported %.2f, p99 %.2f; photos spread %.2f)\n", c.name,
                rms, fit->rms, fit->p99, fit->photo_spread);
    EXPECT_LE(rms, fit->rms + 0.01);
    EXPECT_LT(fit->rms, 0.5 * fit->photo_spread);  // the fit explains the light
  }
  fs::remove_all(dir);
}

// The repainted photos of a simulated transfer (the rig's 7 lamps), as
// `veneer transfer --rti-format hsh` writes them.
TEST(Hsh, RepaintedPhotosReadBackWithinTheResidual) {
  sim::RenderOptions o;
  o.size = {160, 106};
  auto dst = sim::simulate_set("cup-white", o, io::Role::destination);
  auto src = sim::simulate_set("orange", o, io::Role::source);
  ASSERT_TRUE(dst && src);
  pipeline::TransferOptions t;
  t.match.method = match::Method::linear;
  t.match.fast = false;
  t.truth_normals = true;
  auto result = pipeline::transfer(*dst, *src, t);
  ASSERT_TRUE(result) << result.message();
  std::vector<cv::Vec3d> dirs;
  for (const io::Light& l : dst->lights) dirs.push_back(l.direction);
  const fs::path file = fs::temp_directory_path() / ("veneer-hsh-repainted-" + std::to_string(::getpid()) + ".rti");
  auto fit = repaint::export_hsh(result->repainted, dirs, file);
  ASSERT_TRUE(fit) << fit.message();
  const Hsh h = read_hsh(file);
  double sq = 0;
  for (size_t i = 0; i < dirs.size(); ++i) {
    const double rms = rms_against(h, result->repainted[i], dirs[i], fit->exposure);
    EXPECT_LE(rms, fit->rms_per_lamp[i] + 0.01) << "lamp " << i;
    sq += rms * rms;
  }
  std::printf("repainted cup-white <- orange, HSH order %d: reader's residual %.2f levels RMS (reported %.2f, p99 %.2f; "
              "photos spread %.2f)\n",
              fit->hsh_order, std::sqrt(sq / dirs.size()), fit->rms, fit->p99, fit->photo_spread);
  EXPECT_LE(std::sqrt(sq / dirs.size()), fit->rms + 0.01);
  fs::remove(file);
}

}  // namespace
}  // namespace veneer
