// bench_live_look: the live view's per-frame cost with the shaded look (issue
// 40's budget: registration + look of a 1024x680 frame within 10 ms median on
// one core), beside the pixel copy's in the same run. Frames: `simulate_motion`
// of the orange filling the frame (x2.5), shift=30:0,rotate=5,lamp=sweep; the
// map reads every object pixel from itself (the cost does not depend on where
// it reads; the whole object mapped is a transfer's worst case). Columns:
// registration (ECC), the light estimate, the painting at that light, the
// frame's total (process() wall) -- median and p95 -- and the copy's paint and
// total. One core: cv::setNumThreads(1); the machine is shared. Below the
// table, the painting alone at a fixed light (the frame's change carried or not).
// Each size with the light's own cast shadows (LiveLookOptions::shadows, issue
// 47) on, then off; setup s: the still look and the live look's making.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/core/utility.hpp>

#include "veneer/repaint/live_look.hpp"
#include "veneer/repaint/live_session.hpp"
#include "veneer/repaint/look.hpp"
#include "veneer/sim/motion.hpp"
#include "veneer/sim/simulator.hpp"

namespace {

using Clock = std::chrono::steady_clock;

double ms_since(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

double pct(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[static_cast<size_t>(p * (v.size() - 1) + 0.5)];
}

}  // namespace

int main() {
  using namespace veneer;
  std::printf("## Live frame with the shaded look vs the pixel copy, orange x2.5, shift=30:0,rotate=5,lamp=sweep, "
              "20 frames\n\n");
  std::printf("| size | shadows | threads | object px | track ms median | p95 | light ms median | p95 | shade ms median | p95 "
              "| total ms median | p95 | copy paint ms median | copy total ms median | p95 | light deg off median | "
              "setup s |\n");
  std::printf("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
  const int default_threads = cv::getNumThreads();
  std::string notes;
  for (const cv::Size size : {cv::Size(1024, 680), cv::Size(1920, 1280)}) {
    sim::RenderOptions o;
    o.size = size;
    o.scale = 2.5;
    o.ambient = 0.05;
    o.noise_sigma = 0.005;
    auto set = sim::simulate_set("orange", o, io::Role::source);
    auto spec = sim::parse_motion("shift=30:0,rotate=5,lamp=sweep");
    auto seq = sim::simulate_motion("orange", o, *spec, 20);
    if (!set || !seq) {
      std::printf("| %dx%d | simulation failed |\n", size.width, size.height);
      continue;
    }
    const cv::Mat& mask = set->truth.mask;
    match::Map map(cv::Mat(size, CV_32FC2, cv::Scalar(-1, -1)), cv::Mat::zeros(size, CV_32F));
    for (int y = 0; y < size.height; ++y)
      for (int x = 0; x < size.width; ++x)
        if (mask.at<uchar>(y, x)) map.xy.at<cv::Vec2f>(y, x) = {float(x), float(y)};
    match::ObjectView view;
    view.normals = set->truth.normals;
    view.mask = mask;
    view.images = set->images;
    std::vector<cv::Vec3d> lamps;
    for (const io::Light& l : set->lights) lamps.push_back(l.direction);
    const auto t0 = Clock::now();
    auto still = repaint::ShadedLook::make({view, lamps}, {view, lamps}, map);
    if (!still) {
      std::printf("| %dx%d | %s |\n", size.width, size.height, still.message().c_str());
      continue;
    }
    const double still_s = ms_since(t0) / 1000;
    for (const bool shadows : {true, false}) {  // the light's own cast shadows (issue 47) on, then off
    const auto t3 = Clock::now();
    repaint::LiveLookOptions live_options;
    live_options.shadows = shadows;
    auto live = repaint::LiveLook::make(*still, {view, lamps}, {view, lamps}, map, {}, live_options);
    if (!live) {
      std::printf("| %dx%d | %s |\n", size.width, size.height, live.message().c_str());
      continue;
    }
    const double setup_s = still_s + ms_since(t3) / 1000;
    auto look = std::make_shared<const repaint::LiveLook>(std::move(*live));
    for (int threads : {1, default_threads}) {
      cv::setNumThreads(threads);
      repaint::LiveSession shaded(set->images, mask, map, size, look);
      repaint::LiveSession copy(set->images, mask, map, size, look);
      copy.set_look(repaint::Look::copy);
      std::vector<double> track, light, shade, total, copy_paint, copy_total, off;
      for (size_t i = 0; i < seq->frames.size(); ++i) {
        const cv::Mat& frame = seq->frames[i];
        auto t1 = Clock::now();
        auto f = shaded.process(frame);
        const double wall = ms_since(t1);
        t1 = Clock::now();
        auto c = copy.process(frame);
        const double copy_wall = ms_since(t1);
        if (!f || !c) continue;
        track.push_back(f->track_ms), light.push_back(f->light_ms), shade.push_back(f->shade_ms);
        total.push_back(wall), copy_paint.push_back(c->repaint_ms), copy_total.push_back(copy_wall);
        if (f->light) {
          const cv::Vec3d truth = seq->truth[i].lamp_m / cv::norm(seq->truth[i].lamp_m);
          off.push_back(std::acos(std::clamp(truth.dot(f->light->direction), -1.0, 1.0)) * 180 / CV_PI);
        }
      }
      {  // the painting alone, at a fixed light: without a frame (no change carried) and with one
        repaint::LiveLight L;
        L.direction = {0.2, 0.3, 0.93};
        L.intensity = 1;
        L.ambient = 0.01;
        std::vector<double> a1, a2;
        for (int r = 0; r < 20; ++r) {
          auto t2 = Clock::now();
          cv::Mat m1 = look->paint(cv::Mat(), cv::Matx23d(1, 0, 0, 0, 1, 0), L, cv::Mat());
          a1.push_back(ms_since(t2));
          t2 = Clock::now();
          cv::Mat m2 = look->paint(seq->frames[0], cv::Matx23d(1, 0, 0, 0, 1, 0), L, cv::Mat());
          a2.push_back(ms_since(t2));
        }
        char note[160];
        std::snprintf(note, sizeof note,
                      "- %dx%d, %d thread(s), shadows %s: the painting alone at a fixed light, median of 20: "
                      "without a frame %.2f ms, with one (its change carried) %.2f ms\n",
                      size.width, size.height, threads, shadows ? "on" : "off", pct(a1, 0.5), pct(a2, 0.5));
        notes += note;
      }
      std::printf("| %dx%d | %s | %d | %d | %.2f | %.2f | %.2f | %.2f | %.2f | %.2f | %.2f | %.2f | %.2f | %.2f | %.2f | "
                  "%.2f | %.1f |\n",
                  size.width, size.height, shadows ? "on" : "off", threads, cv::countNonZero(mask), pct(track, 0.5), pct(track, 0.95),
                  pct(light, 0.5), pct(light, 0.95), pct(shade, 0.5), pct(shade, 0.95), pct(total, 0.5),
                  pct(total, 0.95), pct(copy_paint, 0.5), pct(copy_total, 0.5), pct(copy_total, 0.95), pct(off, 0.5),
                  setup_s);
    }
    cv::setNumThreads(default_threads);
    }
  }
  std::printf("\n%s", notes.c_str());
  return 0;
}
