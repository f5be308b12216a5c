// probe_track_light: the tracker alone on light-path sequences written by
// tools/prototypes/live/lightpath.sh (WORK/src, WORK/seq): per frame the
// correlation, lost, the registration error against motion.json's truth and
// the time. Usage: probe_track_light [key=value ...] WORK...
// keys set TrackOptions fields (see parse below).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "veneer/io/imageset.hpp"
#include "veneer/match/object.hpp"
#include "veneer/repaint/track.hpp"
#include "veneer/sim/motion.hpp"

using namespace veneer;

static double pct(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[static_cast<size_t>(p * (v.size() - 1) + 0.5)];
}

int main(int argc, char** argv) {
  repaint::TrackOptions o;
  bool verbose = std::getenv("VERBOSE") != nullptr;
  std::vector<std::string> works;
  for (int i = 1; i < argc; ++i) {
    std::string a = argv[i];
    auto eq = a.find('=');
    if (eq == std::string::npos) { works.push_back(a); continue; }
    std::string k = a.substr(0, eq);
    double v = std::atof(a.c_str() + eq + 1);
    if (k == "robust") { if (v != 0) o = repaint::light_robust_track_options(); }  // first, then the others
    else if (k == "min") o.min_correlation = v;
    else if (k == "hp") o.highpass_sigma_px = v;
    else if (k == "region") o.max_region_px = int(v);
    else if (k == "points") o.ecc_points = int(v);
    else if (k == "lit") o.lit_fraction = v;
    else if (k == "iters") o.iterations = int(v);
    else if (k == "rounds") o.relight_rounds = int(v);
    else if (k == "speck") o.lit_speck_px = int(v);
    else if (k == "nn") o.nonnegative_relight = v != 0;
    else if (k == "stlit") o.stills_lit_fraction = v;
    else if (k == "smin") o.shadow_min_correlation = v;
    else { std::fprintf(stderr, "unknown key %s\n", k.c_str()); return 2; }
  }
  for (const auto& w : works) {
    io::ReadOptions ro;
    ro.load_truth_appearance = false;
    auto set = io::read_set(w + "/src", ro);
    if (!set) { std::fprintf(stderr, "%s\n", set.message().c_str()); return 1; }
    auto mask = match::object_mask(*set, false);
    auto truth = sim::read_motion_json(w + "/seq/motion.json");
    if (!mask || !truth) { std::fprintf(stderr, "mask/truth\n"); return 1; }
    repaint::Tracker tracker(set->images, *mask, o);
    std::vector<double> errs, ms, corr;
    int lost = 0;
    std::string lost_list;
    for (size_t i = 0; i < truth->files.size(); ++i) {
      cv::Mat f = cv::imread(w + "/seq/" + truth->files[i], cv::IMREAD_COLOR);
      auto t0 = std::chrono::steady_clock::now();
      auto r = tracker.track(f);
      ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
      double e = repaint::motion_error_px(r.still_to_frame, truth->truth[i].still_to_frame, *mask);
      corr.push_back(r.correlation);
      if (r.lost) { ++lost; lost_list.push_back(' '); lost_list.append(std::to_string(i)); }
      else errs.push_back(e);
      const cv::Moments mo = cv::moments(*mask, true);
      const cv::Vec3d c(mo.m10 / mo.m00, mo.m01 / mo.m00, 1);
      const cv::Vec2d d = r.still_to_frame * c - truth->truth[i].still_to_frame * c;
      if (verbose) std::printf("  %2zu corr %.3f lit %.2f d %+.2f %+.2f sc %.4f %s err %.3f px %.2f ms\n", i, r.correlation, r.lit, d[0], d[1],
                               std::sqrt(std::abs(r.still_to_frame(0, 0) * r.still_to_frame(1, 1) - r.still_to_frame(0, 1) * r.still_to_frame(1, 0))), r.lost ? "LOST" : "    ", e, ms.back());
    }
    std::printf("%-28s lost %2d/%zu  corr min %.3f med %.3f  err med %.3f p95 %.3f max %.3f  ms med %.2f |%s\n",
                w.substr(w.rfind('/') + 1).c_str(), lost, truth->files.size(), *std::min_element(corr.begin(), corr.end()),
                pct(corr, 0.5), pct(errs, 0.5), pct(errs, 0.95), errs.empty() ? 0 : *std::max_element(errs.begin(), errs.end()),
                pct(ms, 0.5), lost_list.c_str());
  }
  return 0;
}
