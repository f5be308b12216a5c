// bench_sim: how long the simulator takes to render a whole set (7 lamps +
// ambient frame) at 1024x680, per scene. The peer measured in the same run is
// the straightforward ray caster that re-casts the camera rays for every shot
// (no G-buffer reuse); the ratio is what the G-buffer buys. Last, the set
// rendered through the camera twin's optics (samples at outlines, low-pass).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/sim/simulator.hpp"

namespace {

using Clock = std::chrono::steady_clock;

double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

template <class F>
double best_of(int runs, F&& f) {
  double best = 1e300;
  for (int i = 0; i < runs; ++i) {
    auto t0 = Clock::now();
    f();
    best = std::min(best, ms_since(t0));
  }
  return best;
}

}  // namespace

int main() {
  using namespace veneer::sim;
  const auto lamps = thesis_rig();
  std::printf("## Scene simulator, 1024x680, thesis rig (7 lamps + ambient = 8 shots), noise 0.005\n\n");
  std::printf("| scene | object px | set (8 shots) ms | set CPU ms | camera rays ms | per shot ms | re-cast every shot ms | speed-up | set with camera optics ms | optics cost |\n");
  std::printf("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
  struct Row {
    std::string scene;
    double scale;
  };
  std::vector<Row> rows;
  for (const auto& name : scene_names()) rows.push_back({name, 1.0});
  rows.push_back({"orange", 2.5});  // fills the frame (~150 000 px) like a benchmark capture
  double total = 0;
  for (const auto& row : rows) {
    RenderOptions o;
    o.size = {1024, 680};
    o.noise_sigma = 0.005;
    o.scale = row.scale;
    int pixels = 0;
    std::clock_t cpu0 = std::clock();
    double set_ms = best_of(2, [&] {
      auto set = simulate_set(row.scene, o);
      if (!set) {
        std::fprintf(stderr, "bench_sim: %s\n", set.message().c_str());
        std::exit(1);
      }
      pixels = cv::countNonZero(set->truth.mask);
    });
    // CPU time of all threads (the machine may be shared; wall time then says less)
    double set_cpu_ms = 1000.0 * static_cast<double>(std::clock() - cpu0) / CLOCKS_PER_SEC / 2;
    // split: the camera rays (a fresh scene has no cached G-buffer) and one shot from the cache
    double rays_ms = best_of(2, [&] {
      auto scene = make_scene(row.scene, o);
      (void)render_truth(**scene, o);
    });
    auto scene = make_scene(row.scene, o);
    (void)render_truth(**scene, o);
    double shot_ms = best_of(3, [&] { (void)render(**scene, {lamps[0]}, o); });
    // peer: every shot casts its camera rays again
    double naive_ms = best_of(1, [&] {
      for (int shot = 0; shot < 8; ++shot) {
        auto fresh = make_scene(row.scene, o);
        RenderOptions s = o;
        s.shot = static_cast<uint32_t>(shot);
        std::vector<Lamp> on;
        if (shot < 7) on.push_back(lamps[static_cast<size_t>(shot)]);
        (void)render(**fresh, on, s);
      }
    });
    // the same set through the camera twin's optics (RenderOptions::camera_optics)
    RenderOptions with_optics = o;
    with_optics.camera_optics();
    double optics_ms = best_of(2, [&] { (void)simulate_set(row.scene, with_optics); });
    total += set_ms;
    std::string label = row.scene + (row.scale != 1.0 ? " (scale " + cv::format("%.1f", row.scale) + ")" : "");
    std::printf("| %s | %d | %.0f | %.0f | %.0f | %.1f | %.0f | %.1fx | %.0f | %.2fx |\n", label.c_str(), pixels, set_ms,
                set_cpu_ms, rays_ms, shot_ms, naive_ms, naive_ms / set_ms, optics_ms, optics_ms / set_ms);
  }
  std::printf("\nAll %zu sets: %.2f s wall. Load average when run: see `uptime`; on a busy machine the CPU column\n"
              "(all threads, mean of the runs) is the steadier figure.\n", rows.size(), total / 1000.0);
  return 0;
}
