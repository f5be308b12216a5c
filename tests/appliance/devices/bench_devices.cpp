// bench_devices: the simulated rig's device layer on loopback.
//  1. Lamp switching through the "hue" backend against the bridge emulator with
//     the bridge's limits (10 light/s, 1 group/s, 3 in flight), per-request
//     latency and ack-before-change delay, compared with one raw PUT round trip.
//  2. Full capture sequences (all off + one shot per lamp) with the simulated
//     camera at 1024x680: time per shot beyond settle + render, refusals.
//  3. Simulated camera: still render and live-view JPEG frames at 1024x680.
#include <algorithm>
#include <chrono>
#include <ctime>
#include <cstdio>
#include <numeric>
#include <thread>
#include <cmath>
#include <vector>

#include <opencv2/imgcodecs.hpp>

#include "veneerd/devices/simulated_rig.hpp"

using Clock = std::chrono::steady_clock;

namespace {

double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}
double mean(const std::vector<double>& v) {
  return v.empty() ? 0 : std::accumulate(v.begin(), v.end(), 0.0) / v.size();
}
double maxv(const std::vector<double>& v) { return v.empty() ? 0 : *std::max_element(v.begin(), v.end()); }

std::vector<bool> one_hot(int n, int i) {
  std::vector<bool> v(n, false);
  if (i >= 0) v[i] = true;
  return v;
}

}  // namespace

int main(int argc, char** argv) {
  // Optional: a folder to write what the simulated camera saw (PNG shots, JPEG live view).
  const std::string out_dir = argc > 1 ? argv[1] : "";
  veneerd::SimulatedRigOptions o;
  o.scenes = {"bull", "stone"};
  o.size = {1024, 680};
  o.preview_size = {1024, 680};
  o.latency_ms = 20;       // a real bridge answers in 20-50 ms
  o.apply_delay_ms = 50;   // and changes the lamp after the ack
  o.settle_ms = 80;        // covers it
  o.rate_limits = true;
  auto rig = veneerd::SimulatedRig::start(o);
  if (!rig) {
    std::fprintf(stderr, "bench_devices: %s\n", rig.message().c_str());
    return 1;
  }
  auto lamps = (*rig)->make_lamps();
  auto camera = (*rig)->make_camera();
  if (!lamps || !camera) {
    std::fprintf(stderr, "bench_devices: cannot make devices\n");
    return 1;
  }
  auto& bridge = (*rig)->bridge();

  // --- 1. lamp steps -------------------------------------------------------
  // Peer: one light command with nothing to pace (lamp 1 toggled every 400 ms,
  // settle 0, no group) = the bridge's round trip as the backend sees it.
  veneerd::HueLampsOptions raw_opts = (*lamps)->options();
  raw_opts.settle_ms = 0;
  raw_opts.verify_reachable = false;
  raw_opts.group.clear();
  auto raw = veneerd::HueLamps::create(raw_opts);
  std::vector<double> round_trip;
  (void)(*raw)->all_off();
  for (int i = 0; i < 8; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(400));
    auto t0 = Clock::now();
    (void)(*raw)->set(i % 2 == 0 ? one_hot(7, 0) : std::vector<bool>(7, false));  // one command each
    round_trip.push_back(ms_since(t0));
  }
  (void)(*raw)->all_off();
  std::this_thread::sleep_for(std::chrono::milliseconds(1200));

  bridge.reset_counters();
  std::vector<double> step_ms;
  (void)(*lamps)->all_off();
  auto before = bridge.counters();
  for (int round = 0; round < 3; ++round) {
    for (int i = 0; i < 7; ++i) {
      auto t0 = Clock::now();
      auto st = (*lamps)->set(one_hot(7, i));
      step_ms.push_back(ms_since(t0));
      if (!st) std::fprintf(stderr, "step failed: %s\n", st.message().c_str());
      std::this_thread::sleep_for(std::chrono::milliseconds(150));  // stands in for the exposure
    }
  }
  auto after = bridge.counters();
  double steps = static_cast<double>(step_ms.size());
  std::printf("\n### Lamp switching on the emulated bridge (latency %d ms, apply delay %d ms, settle %d ms)\n\n",
              o.latency_ms, o.apply_delay_ms, o.settle_ms);
  std::printf("| measure | median ms | mean ms | max ms |\n|---|---:|---:|---:|\n");
  std::printf("| raw light command round trip (peer) | %.1f | %.1f | %.1f |\n", median(round_trip), mean(round_trip),
              maxv(round_trip));
  std::printf("| one step (lamp i off, lamp i+1 on) incl. settle | %.1f | %.1f | %.1f |\n", median(step_ms),
              mean(step_ms), maxv(step_ms));
  std::vector<double> beyond;
  for (double s : step_ms) beyond.push_back(s - o.settle_ms);
  std::printf("| step beyond settle | %.1f | %.1f | %.1f |\n\n", median(beyond), mean(beyond), maxv(beyond));
  std::printf("| steps | light commands/step | 429 refused | 503 refused | max in flight |\n|---:|---:|---:|---:|---:|\n");
  std::printf("| %.0f | %.2f | %llu | %llu | %llu |\n", steps,
              static_cast<double>(after.light_commands - before.light_commands) / steps,
              static_cast<unsigned long long>(after.refused_rate), static_cast<unsigned long long>(after.refused_busy),
              static_cast<unsigned long long>(after.max_in_flight_seen));
  std::printf("\nstep beyond settle / raw round trip: %.2fx\n", median(beyond) / std::max(1e-9, median(round_trip)));

  // --- 2. full capture sequences -----------------------------------------
  bridge.reset_counters();
  auto states = (*lamps)->read();
  std::vector<double> lamp_ms, render_ms, shot_ms;
  const int sets = 3;
  auto seq0 = Clock::now();
  for (int s = 0; s < sets; ++s) {
    (void)(*camera)->set_scene(s % 2 ? (*rig)->source_scene() : (*rig)->destination_scene());
    for (int i = -1; i < 7; ++i) {  // -1: the ambient frame
      auto t0 = Clock::now();
      auto st = i < 0 ? (*lamps)->all_off() : (*lamps)->set(one_hot(7, i));
      double l = ms_since(t0);
      auto t1 = Clock::now();
      auto still = (*camera)->capture();
      double r = ms_since(t1);
      if (!st || !still) std::fprintf(stderr, "shot failed\n");
      if (still && !out_dir.empty() && (i == -1 || i == 0 || i == 3)) {
        cv::Mat png;
        still->linear.convertTo(png, CV_16UC3, 65535.0);
        cv::imwrite(out_dir + "/shot_" + (*camera)->scene() + "_" + (i < 0 ? std::string("ambient") : "lamp" + std::to_string(i + 1)) + ".png", png);
      }
      lamp_ms.push_back(l);
      render_ms.push_back(r);
      shot_ms.push_back(l + r);
    }
    if (states) (void)(*lamps)->restore(*states);
  }
  double seq_total = ms_since(seq0);
  auto c = bridge.counters();
  std::vector<double> overhead;
  for (std::size_t k = 0; k < lamp_ms.size(); ++k) overhead.push_back(lamp_ms[k] - o.settle_ms);
  std::printf("\n### Capture sequences: %d sets x 8 shots (ambient + 7 lamps), simulated camera 1024x680\n\n", sets);
  std::printf("| per shot | median ms | mean ms | max ms |\n|---|---:|---:|---:|\n");
  std::printf("| lamps (incl. settle %d ms) | %.1f | %.1f | %.1f |\n", o.settle_ms, median(lamp_ms), mean(lamp_ms),
              maxv(lamp_ms));
  std::printf("| lamps beyond settle | %.1f | %.1f | %.1f |\n", median(overhead), mean(overhead), maxv(overhead));
  std::printf("| camera (bridge read + render) | %.1f | %.1f | %.1f |\n", median(render_ms), mean(render_ms),
              maxv(render_ms));
  std::printf("| whole shot | %.1f | %.1f | %.1f |\n\n", median(shot_ms), mean(shot_ms), maxv(shot_ms));
  std::printf("| total s (incl. restore) | light cmds | group cmds | 429 | 503 |\n|---:|---:|---:|---:|---:|\n");
  std::printf("| %.2f | %llu | %llu | %llu | %llu |\n", seq_total / 1000, static_cast<unsigned long long>(c.light_commands),
              static_cast<unsigned long long>(c.group_commands), static_cast<unsigned long long>(c.refused_rate),
              static_cast<unsigned long long>(c.refused_busy));

  // --- 3. live view --------------------------------------------------------
  std::printf("\n### Live view (source scene under the moving hand lamp), 1024x680 JPEG\n\n");
  std::printf("| live view | frames | median ms/frame | max ms | fps | CPU ms/frame (all threads) | mean KiB/frame |\n"
              "|---|---:|---:|---:|---:|---:|---:|\n");
  double fast_fps = 0, full_fps = 0;
  for (bool full : {false, true}) {
    auto cfg = (*rig)->camera_config();
    cfg["preview_render"] = full ? "full" : "fast";
    auto co = veneerd::SimulatedCameraOptions::from_json(cfg);
    auto cam = veneerd::SimulatedCamera::create(*co);
    (void)(*cam)->preview();  // first frame builds the scene's G-buffer
    std::vector<double> frame_ms;
    std::size_t bytes = 0;
    int frames = full ? 8 : 60;
    auto lv0 = Clock::now();
    std::clock_t cpu0 = std::clock();
    for (int f = 0; f < frames; ++f) {
      (*cam)->set_hand_lamp({0.4 * std::cos(f * 0.2), 0.4 * std::sin(f * 0.2), 0.6});
      auto t0 = Clock::now();
      auto jpeg = (*cam)->preview();
      frame_ms.push_back(ms_since(t0));
      if (jpeg) bytes += jpeg->size();
      if (jpeg && !out_dir.empty() && f == frames / 2)
        cv::imwrite(out_dir + (full ? "/liveview_full.png" : "/liveview_fast.png"), cv::imdecode(*jpeg, cv::IMREAD_COLOR));
    }
    double fps = 1000.0 * frame_ms.size() / ms_since(lv0);
    double cpu_ms = 1000.0 * static_cast<double>(std::clock() - cpu0) / CLOCKS_PER_SEC / frames;
    (full ? full_fps : fast_fps) = fps;
    std::printf("| %s | %zu | %.1f | %.1f | %.1f | %.1f | %.0f |\n", full ? "full render (peer)" : "fast G-buffer shading",
                frame_ms.size(), median(frame_ms), maxv(frame_ms), fps, cpu_ms, bytes / 1024.0 / frame_ms.size());
  }
  std::printf("\nfast / full live-view frame rate: %.1fx\n", fast_fps / std::max(1e-9, full_fps));
  return 0;
}
