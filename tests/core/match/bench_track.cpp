// bench_track: the live view's per-frame cost with registration (issue 27's
// budget: registration + repaint of a 1024x680 frame within 10 ms median on
// 2 cores). Frames: `simulate_motion` of the orange, shift=30:0,rotate=5,
// lamp=sweep over 30 frames; the map reads every destination pixel from the
// source pixel at the same place (the repaint's cost does not depend on where
// it reads). Peers in the same run: the untracked lookup (the old live view,
// nearest neighbour through a fixed table) and cv::warpAffine of the whole
// frame (one bilinear pass, the floor of any bilinear repaint). The machine
// is shared: the min column says what an idle core pair does.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "veneer/match/live.hpp"
#include "veneer/match/track.hpp"
#include "veneer/sim/motion.hpp"
#include "veneer/sim/simulator.hpp"

namespace {

using Clock = std::chrono::steady_clock;

double ms_since(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : v[v.size() / 2];
}

double p95(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : v[static_cast<size_t>(0.95 * (v.size() - 1) + 0.5)];
}

}  // namespace

int main() {
  using namespace veneer;
  std::printf("## Live registration + repaint per frame, 1024x680, orange, shift=30:0,rotate=5,lamp=sweep, 30 frames\n\n");
  std::printf("threads: %d\n\n", cv::getNumThreads());
  std::printf("| object | object px | track ms median | p95 | repaint ms median | total ms median | untracked repaint ms | warpAffine ms | total ms min | align err px median | p95 | lost |\n");
  std::printf("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
  for (double scale : {1.0, 2.5}) {
    sim::RenderOptions o;
    o.size = {1024, 680};
    o.scale = scale;
    o.ambient = 0.05;
    o.noise_sigma = 0.005;
    auto set = sim::simulate_set("orange", o, Role::source);
    auto spec = sim::parse_motion("shift=30:0,rotate=5,lamp=sweep");
    auto seq = sim::simulate_motion("orange", o, *spec, 30);
    if (!set || !seq) {
      std::printf("| orange x%.1f | simulation failed |\n", scale);
      continue;
    }
    match::Map map;
    map.xy.create(o.size, CV_32FC2);
    for (int y = 0; y < o.size.height; ++y)
      for (int x = 0; x < o.size.width; ++x) map.xy.at<cv::Vec2f>(y, x) = {float(x), float(y)};
    map.distance = cv::Mat::zeros(o.size, CV_32F);
    match::LiveRepainter repainter(map, o.size);
    struct Variant { int region, rounds, iterations; double epsilon; };
    const match::TrackOptions d;
    for (const Variant v : {Variant{d.max_region_px, d.relight_rounds, d.iterations, d.epsilon},
                            Variant{4096, 1, 20, 1e-2}}) {
    match::TrackOptions to;
    const int region = v.region;
    to.max_region_px = v.region;
    to.relight_rounds = v.rounds;
    to.iterations = v.iterations;
    to.epsilon = v.epsilon;
    match::Tracker tracker(set->images, set->truth.mask, to);
    std::vector<double> track_ms, repaint_ms, total_ms, plain_ms, warp_ms, errors;
    int lost = 0;
    for (size_t i = 0; i < seq->frames.size(); ++i) {
      const auto t0 = Clock::now();
      const auto r = tracker.track(seq->frames[i]);
      const double t_track = ms_since(t0);
      const auto t1 = Clock::now();
      cv::Mat out = repainter.apply(seq->frames[i], r.still_to_frame);
      const double t_repaint = ms_since(t1);
      track_ms.push_back(t_track);
      repaint_ms.push_back(t_repaint);
      total_ms.push_back(t_track + t_repaint);
      const auto t2 = Clock::now();
      cv::Mat plain = repainter.apply(seq->frames[i]);
      plain_ms.push_back(ms_since(t2));
      const auto t3 = Clock::now();
      cv::Mat warped;
      cv::warpAffine(seq->frames[i], warped, cv::Mat(r.still_to_frame), o.size, cv::INTER_LINEAR | cv::WARP_INVERSE_MAP);
      warp_ms.push_back(ms_since(t3));
      lost += r.lost;
      if (!r.lost) errors.push_back(match::motion_error_px(r.still_to_frame, seq->truth[i].still_to_frame, set->truth.mask));
    }
    std::printf("| orange x%.1f, region <= %d px, %d relight x %d ECC it, eps %.0e | %d | %.2f | %.2f | %.2f | %.2f | %.2f | %.2f | %.2f | %.2f | %.2f | %d |\n", scale, region, v.rounds, v.iterations, v.epsilon,
                cv::countNonZero(set->truth.mask), median(track_ms), p95(track_ms), median(repaint_ms),
                median(total_ms), median(plain_ms), median(warp_ms), *std::min_element(total_ms.begin(), total_ms.end()),
                median(errors), p95(errors), lost);
    }
  }
  return 0;
}
