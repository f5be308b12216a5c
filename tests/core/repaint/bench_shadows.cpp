// bench_shadows: the cast shadows from a destination's normals (issue 47;
// repaint/shadows.hpp) -- what the shadow map costs to make and to ask per
// frame, and how well it agrees with the simulator's own cast shadows at the
// rig's captured lamps. The object: `simulate_set(scene)` prepared as a
// transfer prepares it (segmentation, photometric stereo on the photos); the
// oracle: the scene rendered under each lamp with and without cast shadows
// (noise-free), a pixel in the cast shadow where it faces the lamp (n.l > 0.2
// on the truth normals) and is lit below 0.35 of what it would be unoccluded
// (lightpath.py's test). Beside it, the photos' own dark-where-facing pixels
// (the prepared normals, each pixel's albedo the median of photo / n.l over
// its lamps): what the photos say without geometry.
//
//   bench_shadows [SCENE ...]   (default: bull cup-dots); VENEER_SHADOW_SIZE=WxH (default 1024x680),
//   VENEER_SHADOW_DUMP=DIR writes heights and per-lamp agreement pictures there.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgcodecs.hpp>

#include "veneer/match/object.hpp"
#include "veneer/repaint/shadows.hpp"
#include "veneer/sim/simulator.hpp"

namespace {

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

float grey(const cv::Vec3f& v) { return (v[0] + v[1] + v[2]) / 3.f; }

struct Agreement {
  long both = 0, geometric_only = 0, truth_only = 0;
  double iou() const { return both / std::max(1.0, double(both + geometric_only + truth_only)); }
  double precision() const { return both / std::max(1.0, double(both + geometric_only)); }
  double recall() const { return both / std::max(1.0, double(both + truth_only)); }
  void add(const Agreement& a) {
    both += a.both, geometric_only += a.geometric_only, truth_only += a.truth_only;
  }
};

}  // namespace

int main(int argc, char** argv) {
  using namespace veneer;
  std::vector<std::string> scenes;
  for (int i = 1; i < argc; ++i) scenes.push_back(argv[i]);
  if (scenes.empty()) scenes = {"bull", "cup-dots"};
  cv::Size size(1024, 680);
  if (const char* s = std::getenv("VENEER_SHADOW_SIZE")) std::sscanf(s, "%dx%d", &size.width, &size.height);
  const char* dump = std::getenv("VENEER_SHADOW_DUMP");
  if (dump) std::filesystem::create_directories(dump);
  std::printf("## Cast shadows from the normals, %dx%d, at the rig's 7 lamps\n\n", size.width, size.height);
  std::printf("IoU / precision / recall against the oracle's cast shadows, pooled over the lamps: the geometry "
              "alone (heights from the normals); the photos' dark-where-facing pixels; the geometry told the photos "
              "(ShadowMap::observe), at the lamps it was told; the same at each lamp left out, told the other six.\n\n");
  std::printf("| scene | object px | grid step | make ms (%d threads) | query ns/px | height err px (median abs) | "
              "geometry | photos | told the photos | lamp left out |\n",
              cv::getNumThreads());
  std::printf("|---|---:|---:|---:|---:|---:|---|---|---|---|\n");
  for (const std::string& name : scenes) {
    sim::RenderOptions o;
    o.size = size;
    o.noise_sigma = 0.005;
    auto set = sim::simulate_set(name, o, io::Role::destination);
    if (!set) {
      std::printf("| %s | %s |\n", name.c_str(), set.message().c_str());
      continue;
    }
    auto object = match::prepare_object(*set, false);
    if (!object) {
      std::printf("| %s | %s |\n", name.c_str(), object.message().c_str());
      continue;
    }
    const cv::Mat& normals = object->view.normals;
    const cv::Mat& mask = object->view.mask;
    const auto t0 = Clock::now();
    repaint::ShadowOptions so;
    if (const char* e = std::getenv("VENEER_SHADOW_SLOPE")) so.max_slope = std::atof(e);
    auto map = repaint::ShadowMap::make(normals, mask, so);
    const double make_ms = ms_since(t0);
    if (!map) {
      std::printf("| %s | %s |\n", name.c_str(), map.message().c_str());
      continue;
    }
    // per-frame cost: the horizons of every object pixel asked at random lamps
    std::vector<int> pixels;
    for (int y = 0; y < mask.rows; ++y)
      for (int x = 0; x < mask.cols; ++x)
        if (mask.at<uchar>(y, x)) pixels.push_back(y * mask.cols + x);
    const repaint::PixelHorizons ph = map->at(pixels);
    std::vector<float> vis(pixels.size());
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> u(-0.8, 0.8);
    const int asks = 200;
    const auto t1 = Clock::now();
    double sink = 0;
    for (int k = 0; k < asks; ++k) {
      ph.visibility(cv::Vec3d(u(rng), u(rng), 1), 0, static_cast<int>(pixels.size()), vis.data());
      sink += vis[k % vis.size()];
    }
    const double ns_px = ms_since(t1) * 1e6 / (double(asks) * pixels.size());
    // the heights against the truth's depth (z = 1 - depth, in pixels: focal px per metre at the object)
    const double f = set->camera.focal_px > 0 ? set->camera.focal_px : 2.0 * size.width;
    auto height = repaint::height_from_normals(normals, mask, map->step(), so.max_slope);
    std::vector<double> diff;
    for (int i : pixels) {
      const int x = i % mask.cols, y = i / mask.cols;
      if (!set->truth.mask.at<uchar>(y, x)) continue;
      diff.push_back(height->at<float>(y, x) - (1.0 - set->truth.depth.at<float>(y, x)) * f);
    }
    std::vector<double> sorted = diff;
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    const double offset = sorted[sorted.size() / 2];
    for (double& d : diff) d = std::abs(d - offset);
    std::nth_element(diff.begin(), diff.begin() + diff.size() / 2, diff.end());
    const double height_err = diff[diff.size() / 2];
    if (dump) {
      cv::Mat est(mask.size(), CV_32FC1, cv::Scalar(0)), tru(mask.size(), CV_32FC1, cv::Scalar(0));
      for (int i : pixels) {
        const int x = i % mask.cols, y = i / mask.cols;
        est.at<float>(y, x) = height->at<float>(y, x) - static_cast<float>(offset);
        if (set->truth.mask.at<uchar>(y, x))
          tru.at<float>(y, x) = static_cast<float>((1.0 - set->truth.depth.at<float>(y, x)) * f);
      }
      cv::FileStorage fs(std::string(dump) + "/" + name + "_height.yml.gz", cv::FileStorage::WRITE);
      fs << "estimated" << est << "truth" << tru;
    }
    // agreement at each captured lamp: the oracle's shadows first
    auto scene = sim::make_scene(name, o);
    sim::RenderOptions clean = o;
    clean.noise_sigma = 0;
    sim::RenderOptions free = clean;
    free.cast_shadows = false;
    const std::vector<sim::Lamp> rig = sim::thesis_rig();
    std::vector<cv::Vec3d> lamps;
    std::vector<cv::Vec3f> dirs;
    for (const io::Light& l : set->lights) {
      lamps.push_back(l.direction);
      dirs.emplace_back(cv::Vec3f(l.direction[0], l.direction[1], l.direction[2]));
    }
    std::vector<cv::Mat> truth(lamps.size()), judged(lamps.size());  // the oracle's shadow; the pixels judged
    for (size_t k = 0; k < rig.size() && k < lamps.size(); ++k) {
      const cv::Mat lit = sim::render(**scene, {rig[k]}, clean);
      const cv::Mat open = sim::render(**scene, {rig[k]}, free);
      truth[k] = cv::Mat(mask.size(), CV_8UC1, cv::Scalar(0));
      judged[k] = cv::Mat(mask.size(), CV_8UC1, cv::Scalar(0));
      for (int i : pixels) {
        const int x = i % mask.cols, y = i / mask.cols;
        if (!set->truth.mask.at<uchar>(y, x)) continue;
        const cv::Vec3f nt = set->truth.normals.at<cv::Vec3f>(y, x);
        const cv::Vec3f ne = normals.at<cv::Vec3f>(y, x);
        if (nt.dot(dirs[k]) <= 0.2f || ne.dot(dirs[k]) <= 0.2f) continue;  // facing the lamp, on both
        const float g_open = grey(open.at<cv::Vec3f>(y, x));
        if (g_open <= 1e-4f) continue;
        judged[k].at<uchar>(y, x) = 255;
        truth[k].at<uchar>(y, x) = grey(lit.at<cv::Vec3f>(y, x)) < 0.35f * g_open ? 255 : 0;
      }
    }
    auto agree = [&](const cv::Mat& shadow, size_t k, const char* what) {
      Agreement a;
      cv::Mat pic(mask.size(), CV_8UC3, cv::Scalar(0, 0, 0));
      for (int i : pixels) {
        const int x = i % mask.cols, y = i / mask.cols;
        if (!judged[k].at<uchar>(y, x)) continue;
        const bool t = truth[k].at<uchar>(y, x) != 0, g = shadow.at<uchar>(y, x) != 0;
        a.both += t && g, a.geometric_only += g && !t, a.truth_only += t && !g;
        pic.at<cv::Vec3b>(y, x) = t && g ? cv::Vec3b(0, 200, 0)
                                  : g    ? cv::Vec3b(0, 0, 255)
                                  : t    ? cv::Vec3b(255, 0, 0)
                                         : cv::Vec3b(90, 90, 90);
      }
      if (dump) cv::imwrite(std::string(dump) + "/" + name + "_" + what + "_lamp" + std::to_string(k) + ".png", pic);
      return a;
    };
    auto shadow_of = [&](const repaint::ShadowMap& m, size_t k) {
      cv::Mat v = m.visibility(lamps[k]), s;
      cv::compare(v, 0.5, s, cv::CMP_LT);
      return s;
    };
    auto photos = repaint::photo_shadows(object->view.images, normals, mask, lamps);
    Agreement geo_all, photo_all, seen_all, left_out_all;
    repaint::ShadowMap seen = *map;
    if (auto st = seen.observe(lamps, photos->shadowed, photos->lit); !st) std::printf("observe: %s\n", st.message().c_str());
    for (size_t k = 0; k < lamps.size(); ++k) {
      const Agreement g = agree(shadow_of(*map, k), k, "geometry");
      geo_all.add(g);
      photo_all.add(agree(photos->shadowed[k], k, "photo"));
      seen_all.add(agree(shadow_of(seen, k), k, "observed"));
      // the lamp left out: the map told only the others' photos
      repaint::ShadowMap others = *map;
      std::vector<cv::Vec3d> ol;
      std::vector<cv::Mat> os, oi;
      for (size_t j = 0; j < lamps.size(); ++j)
        if (j != k) ol.push_back(lamps[j]), os.push_back(photos->shadowed[j]), oi.push_back(photos->lit[j]);
      (void)others.observe(ol, os, oi);
      const Agreement lo = agree(shadow_of(others, k), k, "left_out");
      left_out_all.add(lo);
      std::fprintf(stderr, "%s lamp %zu: geometry IoU %.3f P %.3f R %.3f; left out IoU %.3f (truth %ld px)\n",
                   name.c_str(), k, g.iou(), g.precision(), g.recall(), lo.iou(), g.both + g.truth_only);
    }
    std::printf("| %s | %zu | %d | %.0f | %.2f | %.1f | %.3f / %.3f / %.3f | %.3f / %.3f / %.3f | %.3f / %.3f / %.3f | "
                "%.3f / %.3f / %.3f |\n",
                name.c_str(), pixels.size(), map->step(), make_ms, ns_px, height_err, geo_all.iou(),
                geo_all.precision(), geo_all.recall(), photo_all.iou(), photo_all.precision(), photo_all.recall(),
                seen_all.iou(), seen_all.precision(), seen_all.recall(), left_out_all.iou(), left_out_all.precision(),
                left_out_all.recall());
    if (sink < -1) std::printf("!");
  }
  return 0;
}
