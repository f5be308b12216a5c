// Third-party DNGs (laid out as the Raspberry Pi camera's DNG library writes
// them: pi_dng.hpp) in a DiLiGenT folder and through a set.json give normals
// as close to the photos' own normals as a correct decode of the same sensor
// data does. Issue 37's "what must show": within +1 deg median and 1.15x
// mean of that distance. (Against the rig's DNGs of the photos themselves --
// a camera without a colour matrix -- the Pi's CCM costs ~0.15 deg median and
// 11-23 % of the mean: it amplifies the demosaicing error; with an identity
// CCM the Pi files give the rig's numbers to 0.01 deg.)
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>

#include <gtest/gtest.h>

#include "test_util.hpp"
#include "pi_dng.hpp"
#include "veneer/io/dng.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/io/imageset.hpp"
#include "veneer/ps/photometric_stereo.hpp"
#include "veneer/sim/simulator.hpp"

namespace veneer {
namespace {
namespace fs = std::filesystem;
using test::Scratch;

io::ImageSet simulated(const std::string& scene) {
  sim::RenderOptions o;
  o.size = {512, 340};
  o.noise_sigma = 0.002;  // the rig twin's
  o.seed = 5;
  o.scale = 2.5;
  o.camera_optics();
  auto set = sim::simulate_set(scene, o, io::Role::destination);
  EXPECT_TRUE(set) << set.message();
  return set ? std::move(set).value() : io::ImageSet{};
}

struct Distance {
  double median = 180, mean = 180;
};

// Angles between two normal maps over `mask`, degrees.
Distance distance(const cv::Mat& a, const cv::Mat& b, const cv::Mat& mask) {
  std::vector<double> deg;
  for (int y = 0; y < a.rows; ++y)
    for (int x = 0; x < a.cols; ++x) {
      if (!mask.at<uchar>(y, x)) continue;
      const cv::Vec3f p = a.at<cv::Vec3f>(y, x), q = b.at<cv::Vec3f>(y, x);
      const double d = std::clamp(double(p.dot(q)) / (cv::norm(p) * cv::norm(q) + 1e-12), -1.0, 1.0);
      deg.push_back(std::acos(d) * 180 / CV_PI);
    }
  if (deg.empty()) return {};
  std::nth_element(deg.begin(), deg.begin() + long(deg.size() / 2), deg.end());
  Distance r;
  r.median = deg[deg.size() / 2];
  r.mean = 0;
  for (double v : deg) r.mean += v;
  r.mean /= double(deg.size());
  return r;
}

// A matrix on linear RGB as cv::transform applies it to a BGR Mat.
cv::Matx33f bgr(const cv::Matx33d& rgb) {
  cv::Matx33f m;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) m(2 - r, 2 - c) = static_cast<float>(rgb(r, c));
  return m;
}

cv::Mat normals_of(const io::ImageSet& set, const cv::Mat& mask) {
  auto ps = ps::photometric_stereo(set, mask);
  EXPECT_TRUE(ps) << ps.message();
  return ps ? ps->normals : cv::Mat();
}

// A DiLiGenT folder of the set's photos (directions and intensities; no
// lamp positions: the distant-light model), each written by `encode` as
// light_NN.<extension>.
template <typename Encode>
void write_diligent(const io::ImageSet& set, const fs::path& dir, const std::string& extension, Encode encode) {
  fs::create_directories(dir);
  std::ofstream names(dir / "filenames.txt"), dirs(dir / "light_directions.txt"), ints(dir / "light_intensities.txt");
  for (size_t i = 0; i < set.images.size(); ++i) {
    char name[48];
    std::snprintf(name, sizeof name, "light_%02zu.%s", i, extension.c_str());
    test::spit(dir / name, encode(set.images[i]));
    names << name << "\n";
    const cv::Vec3d& d = set.lights[i].direction;
    const cv::Vec3f& in = set.lights[i].intensity;
    dirs << d[0] << " " << d[1] << " " << d[2] << "\n";
    ints << in[0] << " " << in[1] << " " << in[2] << "\n";
  }
}

TEST(ThirdPartyDng, RaspberryPiDngsGiveNormalsAsACorrectDecodeDoes) {
  // The Pi's layouts: the HQ camera's BGGR at 12 bits, and an upside-down
  // mounted sensor with per-cell black levels at 10 bits.
  test::PiDngOptions hq;
  test::PiDngOptions flipped = hq;
  flipped.cfa = "GRBG";
  flipped.bits = 10;
  flipped.black_level = 64;
  flipped.black_offsets = {0, 2, -1, 1};
  flipped.gains = {2.3, 1.4};
  flipped.orientation = 3;
  for (const std::string scene : {"orange", "bull"}) {
    SCOPED_TRACE(scene);
    io::ImageSet rendered = simulated(scene);
    ASSERT_FALSE(rendered.images.empty());
    rendered.ambient = cv::Mat();  // the Pi files are the lamps' photos only
    const cv::Mat mask = rendered.truth.mask;
    Scratch dir;
    auto read = [&](const fs::path& folder) {
      // LibRaw's DCB, as measured when the bounds were set (issue 37): the io default became our MHC (issue
      // 42), which reads the HQ camera's BGGR orange 2.6x further from the photos' normals (5.34 vs 2.03 deg
      // mean; LibRaw's AHD as far, core/CameraSpace); the layout, not the demosaic, is what this test is about
      io::ReadOptions dcb;
      dcb.raw.demosaic = io::Demosaic::dcb;
      auto set = io::read_set(folder, dcb);
      EXPECT_TRUE(set) << set.message();
      return set ? std::move(set).value() : io::ImageSet{};
    };

    // Each layout against the photos' normals in that layout: DiLiGenT (the
    // render as 16-bit PNGs; distant lights) and set.json (lamp positions).
    write_diligent(rendered, dir / "png", "png", [](const cv::Mat& p) { return io::encode_png16(p).value(); });
    const cv::Mat photos_diligent = normals_of(read(dir / "png"), mask);
    const cv::Mat photos_json = normals_of(rendered, mask);
    for (const auto& [label, options] : {std::pair{"HQ 12-bit BGGR", hq}, std::pair{"10-bit GRBG upside down", flipped}}) {
      SCOPED_TRACE(label);
      auto pi_dng = [&, o = options](const cv::Mat& p) { return test::encode_pi_dng(p, o); };
      write_diligent(rendered, dir / label, "dng", pi_dng);
      const io::ImageSet pi = read(dir / label);
      EXPECT_EQ(pi.photos_from, "raw");
      ASSERT_EQ(pi.size, rendered.size);
      const Distance got = distance(normals_of(pi, mask), photos_diligent, mask);

      // The reference, a correct decode of the same sensor data: the camera's
      // (white-balanced) colours, CCM^-1 x photo, in the rig's own DNGs
      // (which LibRaw decodes to what they hold: core/RawSim.*), then the
      // camera's CCM applied in floating point.
      auto to_camera = [&](const cv::Mat& p) {
        cv::Mat cam;
        cv::transform(p, cam, bgr(options.ccm.inv()));
        return io::encode_dng(cam).value();
      };
      auto to_photo = [&](io::ImageSet set) {
        for (auto& im : set.images) cv::transform(im, im, bgr(options.ccm));
        return set;
      };
      const std::string ref_label = std::string(label) + "-reference";
      write_diligent(rendered, dir / ref_label, "dng", to_camera);
      const io::ImageSet ref_set = to_photo(read(dir / ref_label));
      EXPECT_EQ(ref_set.photos_from, "raw");
      const Distance ref_diligent = distance(normals_of(ref_set, mask), photos_diligent, mask);
      io::ImageSet ref_raw = rendered;
      for (const auto& im : rendered.images) ref_raw.raw.push_back({"dng", to_camera(im)});
      ASSERT_TRUE(io::write_set(ref_raw, dir / (ref_label + "-set")));
      const Distance ref_json =
          distance(normals_of(to_photo(read(dir / (ref_label + "-set"))), mask), photos_json, mask);

      io::ImageSet with_raw = rendered;
      for (const auto& im : rendered.images) with_raw.raw.push_back({"dng", pi_dng(im)});
      ASSERT_TRUE(io::write_set(with_raw, dir / (std::string(label) + "-set")));
      const io::ImageSet via_json = read(dir / (std::string(label) + "-set"));
      EXPECT_EQ(via_json.photos_from, "raw");
      const Distance json = distance(normals_of(via_json, mask), photos_json, mask);

      std::printf("%s, %s: normals from the photos' normals (median / mean deg): DiLiGenT: correct decode %.2f / "
                  "%.2f, Pi DNG %.2f / %.2f; set.json: correct decode %.2f / %.2f, Pi DNG %.2f / %.2f\n",
                  scene.c_str(), label, ref_diligent.median, ref_diligent.mean, got.median, got.mean, ref_json.median,
                  ref_json.mean, json.median, json.mean);
      EXPECT_LE(got.median, ref_diligent.median + 1.0);
      EXPECT_LE(got.mean, ref_diligent.mean * 1.15);
      EXPECT_LE(json.median, ref_json.median + 1.0);
      EXPECT_LE(json.mean, ref_json.mean * 1.15);
    }
  }
}

}  // namespace
}  // namespace veneer
