// bench_track: the live view's per-frame cost with registration (issue 27's
// budget: registration + repaint of a 1024x680 frame within 10 ms median on
// 2 cores). Frames: `simulate_motion` of the orange, shift=30:0,rotate=5,
// lamp=sweep over 30 frames; the map reads every destination pixel from the
// source pixel at the same place (the repaint's cost does not depend on where
// it reads; the whole frame mapped is the worst case, a column gives a map
// over the object only, as a transfer's is). The live default (LiveSession)
// gathers the nearest pixel; bilinear (repaint --video) is shown beside. Peers in the same run: the untracked lookup (the old live view,
// nearest neighbour through a fixed table) and cv::warpAffine of the whole
// frame (one bilinear pass, the floor of any bilinear repaint). The machine
// is shared: the min column says what an idle core pair does.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "veneer/repaint/live.hpp"
#include "veneer/repaint/track.hpp"
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
  std::printf("| object | object px | track ms median | p95 | repaint nearest ms (live default) | total ms median | "
              "total min | repaint bilinear ms | total bilinear ms | bilinear, object-only map ms | untracked repaint "
              "ms | warpAffine ms | align err px median | p95 | lost |\n");
  std::printf("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
  for (double scale : {1.0, 2.5}) {
    sim::RenderOptions o;
    o.size = {1024, 680};
    o.scale = scale;
    o.ambient = 0.05;
    o.noise_sigma = 0.005;
    auto set = sim::simulate_set("orange", o, io::Role::source);
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
    repaint::LiveRepainter repainter(map, o.size);  // bilinear
    repaint::LiveRepainter nearest(map, o.size);    // the live default (LiveSession)
    nearest.set_bilinear(false);
    // a map as a transfer makes one: only the destination object's pixels
    // (here the source object's own, a self-map) are mapped
    match::Map object_map = map;
    object_map.xy.setTo(cv::Scalar(-1, -1), set->truth.mask == 0);
    repaint::LiveRepainter object_repainter(object_map, o.size);
    struct Variant { int region, rounds, iterations; double epsilon; };
    const repaint::TrackOptions d;
    for (const Variant v : {Variant{d.max_region_px, d.relight_rounds, d.iterations, d.epsilon},
                            Variant{4096, 1, 20, 1e-2}}) {
    repaint::TrackOptions to;
    const int region = v.region;
    to.max_region_px = v.region;
    to.relight_rounds = v.rounds;
    to.iterations = v.iterations;
    to.epsilon = v.epsilon;
    repaint::Tracker tracker(set->images, set->truth.mask, to);
    std::vector<double> track_ms, near_ms, total_ms, bilinear_ms, total_bilinear_ms, object_ms, plain_ms, warp_ms,
        errors;
    int lost = 0;
    auto timed = [](auto&& f) {
      const auto t0 = Clock::now();
      f();
      return ms_since(t0);
    };
    for (size_t i = 0; i < seq->frames.size(); ++i) {
      const cv::Mat& frame = seq->frames[i];
      repaint::TrackResult r;
      cv::Mat out;
      track_ms.push_back(timed([&] { r = tracker.track(frame); }));
      near_ms.push_back(timed([&] { out = nearest.apply(frame, r.still_to_frame); }));
      total_ms.push_back(track_ms.back() + near_ms.back());
      bilinear_ms.push_back(timed([&] { out = repainter.apply(frame, r.still_to_frame); }));
      total_bilinear_ms.push_back(track_ms.back() + bilinear_ms.back());
      object_ms.push_back(timed([&] { out = object_repainter.apply(frame, r.still_to_frame); }));
      plain_ms.push_back(timed([&] { out = repainter.apply(frame); }));
      warp_ms.push_back(timed([&] {
        cv::warpAffine(frame, out, cv::Mat(r.still_to_frame), o.size, cv::INTER_LINEAR | cv::WARP_INVERSE_MAP);
      }));
      lost += r.lost;
      if (!r.lost) errors.push_back(repaint::motion_error_px(r.still_to_frame, seq->truth[i].still_to_frame, set->truth.mask));
    }
    std::printf("| orange x%.1f, region <= %d px, %d relight x %d ECC it, eps %.0e | %d | %.2f | %.2f | %.2f | %.2f | "
                "%.2f | %.2f | %.2f | %.2f | %.2f | %.2f | %.2f | %.2f | %d |\n",
                scale, region, v.rounds, v.iterations, v.epsilon, cv::countNonZero(set->truth.mask), median(track_ms),
                p95(track_ms), median(near_ms), median(total_ms), *std::min_element(total_ms.begin(), total_ms.end()),
                median(bilinear_ms), median(total_bilinear_ms), median(object_ms), median(plain_ms), median(warp_ms),
                median(errors), p95(errors), lost);
    }
  }
  return 0;
}
