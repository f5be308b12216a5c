// A full-resolution map refined from a coarser one (refine.hpp).
#include "veneer/match/refine.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <mutex>
#include <string>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

namespace veneer::match {

Status RefineOptions::check() const {
  if (radius < 0 || radius > 8) return make_error("refine radius must be in 0..8, got " + std::to_string(radius));
  if (threads < 0) return make_error("refine threads must be >= 0, got " + std::to_string(threads));
  return Status::success();
}

Expected<Map> refine_map(const Map& coarse, const ObjectView& destination, const ObjectView& source,
                         const RefineOptions& options, const Progress& progress) {
  if (Status s = options.check(); !s) return s.error();
  if (coarse.xy.empty() || coarse.xy.type() != CV_32FC2) return make_error("refine_map: the coarse map must be CV_32FC2");
  for (const ObjectView* v : {&destination, &source}) {
    const char* who = v == &destination ? "destination" : "source";
    if (v->normals.type() != CV_32FC3 || v->mask.type() != CV_8UC1 || v->normals.size() != v->mask.size() ||
        v->mask.empty())
      return make_error(std::string("refine_map: the ") + who + "'s normals (CV_32FC3) and mask (CV_8UC1) must be of one size");
  }
  const int W = destination.mask.cols, H = destination.mask.rows;
  const int cw = coarse.xy.cols, ch = coarse.xy.rows;
  const int SW = source.mask.cols, SH = source.mask.rows;
  if (cw > W || ch > H) return make_error("refine_map: the coarse map is larger than the destination");
  // full / coarse, per axis; the source scales as the destination does
  const double kx = double(W) / cw, ky = double(H) / ch;
  Map out;
  out.xy.create(H, W, CV_32FC2);
  out.distance.create(H, W, CV_32FC1);
  const int r = options.radius;
  std::atomic<int> rows_done{0};
  std::atomic<bool> cancelled{false};
  std::mutex report_mutex;  // the callback is called from one thread at a time
  auto body = [&](const tbb::blocked_range<int>& range) {
    for (int y = range.begin(); y < range.end(); ++y) {
      if (cancelled.load(std::memory_order_relaxed)) return;
      const uint8_t* m = destination.mask.ptr<uint8_t>(y);
      const cv::Vec3f* nd = destination.normals.ptr<cv::Vec3f>(y);
      cv::Vec2f* o = out.xy.ptr<cv::Vec2f>(y);
      float* od = out.distance.ptr<float>(y);
      const int qy = std::min(ch - 1, static_cast<int>((y + 0.5) / ky));
      for (int x = 0; x < W; ++x) {
        o[x] = cv::Vec2f(-1, -1);
        od[x] = 0;
        if (!m[x]) continue;
        const int qx = std::min(cw - 1, static_cast<int>((x + 0.5) / kx));
        const cv::Vec3f n = nd[x];
        float best = std::numeric_limits<float>::max();
        int bx = -1, by = -1;
        static constexpr int kSeeds[5][2] = {{0, 0}, {-1, 0}, {1, 0}, {0, -1}, {0, 1}};
        for (const auto& d : kSeeds) {
          const int sx = qx + d[0], sy = qy + d[1];
          if (sx < 0 || sy < 0 || sx >= cw || sy >= ch) continue;
          const cv::Vec2f c = coarse.xy.at<cv::Vec2f>(sy, sx);
          if (c[0] < 0) continue;
          // the coarse pixel's centre and its match, in full-resolution pixels; then this pixel's offset
          const double fx = (sx + 0.5) * kx - 0.5, fy = (sy + 0.5) * ky - 0.5;
          const int px = static_cast<int>(std::lround((c[0] + 0.5) * kx - 0.5 + (x - fx)));
          const int py = static_cast<int>(std::lround((c[1] + 0.5) * ky - 0.5 + (y - fy)));
          for (int v = std::max(0, py - r); v <= std::min(SH - 1, py + r); ++v) {
            const uint8_t* sm = source.mask.ptr<uint8_t>(v);
            const cv::Vec3f* ns = source.normals.ptr<cv::Vec3f>(v);
            for (int u = std::max(0, px - r); u <= std::min(SW - 1, px + r); ++u) {
              if (!sm[u]) continue;
              const cv::Vec3f e = n - ns[u];
              const float cost = e.dot(e);
              if (cost < best) best = cost, bx = u, by = v;
            }
          }
        }
        if (bx >= 0) {
          o[x] = cv::Vec2f(static_cast<float>(bx), static_cast<float>(by));
          od[x] = std::sqrt(best);
        }
      }
      const int done = ++rows_done;
      if (done % 64 == 0) {
        std::lock_guard lock(report_mutex);
        progress.report(double(done) / H, "refining the map");
        if (progress.cancelled()) cancelled = true;
      }
    }
  };
  auto run = [&] { tbb::parallel_for(tbb::blocked_range<int>(0, H, 16), body); };
  if (options.threads > 0) {
    tbb::task_arena arena(options.threads);
    arena.execute(run);
  } else {
    run();
  }
  if (cancelled) return make_error("refining the map cancelled");
  progress.report(1.0, "refining the map");
  return out;
}

}  // namespace veneer::match
