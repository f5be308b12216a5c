// bench_rig: the simulated rig end to end (in this process, over TCP and the
// libcurl Hue path against the emulator with Hue's rate limits and latency).
//  1. a full 8-shot set at 1024x680: time per shot beyond exposure + settle
//     (and beyond the simulator's own render time), requests refused for rate;
//  2. live view of 1024x680 frames while another client downloads sets,
//     against live view alone.
#include <atomic>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <mutex>
#include <thread>

#include "rig_test_util.hpp"
#include "veneer/rig/client.hpp"
#include "veneer/sim/simulator.hpp"
#include "veneer/util/log.hpp"
#include "veneerd/daemon.hpp"
#include "veneerd/devices/simulated_rig.hpp"

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using Kind = veneer::rig::Event::Kind;

static double secs(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

int main() {
  veneer::log::set_levels("warn");
  fs::path dir = rigtest::temp_dir("bench");
  veneerd::DaemonOptions o;
  o.simulate = true;
  o.size = {1024, 680};
  o.noise_sigma = 0.002;
  o.hue_latency_ms = 20;  // a real bridge answers in 10..50 ms
  o.hue_rate_limits = true;
  o.listen = "127.0.0.1:0";
  o.store = dir / "store";
  auto daemon = veneerd::Daemon::create(o);
  if (!daemon) {
    std::fprintf(stderr, "bench_rig: %s\n", daemon.message().c_str());
    return 1;
  }
  if (auto s = (*daemon)->start(); !s) {
    std::fprintf(stderr, "bench_rig: %s\n", s.message().c_str());
    return 1;
  }
  auto& d = **daemon;
  auto client = veneer::rig::Client::connect({"127.0.0.1", d.port()}, d.token());
  if (!client) {
    std::fprintf(stderr, "bench_rig: %s\n", client.message().c_str());
    return 1;
  }
  auto& c = **client;
  const double settle_s = d.config().settle_ms / 1000.0;
  const double exposure_s = d.config().exposure.shutter_s;

  // The simulator's render time for one shot at this size (what a real camera's
  // readout replaces), measured here as the peer.
  veneer::sim::RenderOptions ro;
  ro.size = o.size;
  auto scene = veneer::sim::make_scene("bull", ro);
  double render_s = 0;
  if (scene) {
    auto ring = veneer::sim::thesis_rig();
    auto t0 = Clock::now();
    for (int i = 0; i < 3; ++i) (void)veneer::sim::render(**scene, {ring[i]}, ro);
    render_s = secs(Clock::now() - t0) / 3;
  }

  // --- 1. one full set
  d.simulated()->bridge().reset_counters();
  std::mutex m;
  std::vector<Clock::time_point> shot_times;
  c.on_event = [&](const veneer::rig::Event& e) {
    std::lock_guard lock(m);
    if (e.kind == Kind::capture_started || e.kind == Kind::shot_taken) shot_times.push_back(Clock::now());
  };
  auto t_start = Clock::now();
  auto id = c.capture();
  if (!id) {
    std::fprintf(stderr, "bench_rig: %s\n", id.message().c_str());
    return 1;
  }
  auto done = c.wait_event([&](const veneer::rig::Event& e) {
    return e.set_id == *id && (e.kind == Kind::set_stored || e.kind == Kind::capture_failed);
  }, 120);
  double total_s = secs(Clock::now() - t_start);
  auto counters = d.simulated()->bridge().counters();
  if (!done || done->kind != Kind::set_stored) {
    std::fprintf(stderr, "bench_rig: capture failed: %s\n", done ? done->reason.c_str() : done.message().c_str());
    return 1;
  }
  std::vector<double> steps;
  {
    std::lock_guard lock(m);
    for (size_t i = 1; i < shot_times.size(); ++i) steps.push_back(secs(shot_times[i] - shot_times[i - 1]));
  }
  double mean_step = 0, worst_step = 0;
  for (double s : steps) {
    mean_step += s / steps.size();
    worst_step = std::max(worst_step, s);
  }
  std::printf("\n### Full set on the simulated rig (1024x680, 7 lamps + ambient = %zu shots, Hue latency %d ms, rate limits on)\n\n",
              steps.size(), o.hue_latency_ms);
  std::printf("| measure | value |\n|---|---|\n");
  std::printf("| whole capture incl. storing (s) | %.2f |\n", total_s);
  std::printf("| mean time per shot (ms) | %.0f |\n", mean_step * 1000);
  std::printf("| worst shot (ms) | %.0f |\n", worst_step * 1000);
  std::printf("| exposure + settle per shot (ms) | %.0f |\n", (exposure_s + settle_s) * 1000);
  std::printf("| simulator render per shot, peer (ms) | %.0f |\n", render_s * 1000);
  std::printf("| **per shot beyond exposure + settle (ms)** | **%.0f** |\n", (mean_step - exposure_s - settle_s) * 1000);
  std::printf("| per shot beyond exposure + settle + render (ms) | %.0f |\n",
              (mean_step - exposure_s - settle_s - render_s) * 1000);
  std::printf("| Hue light commands accepted | %llu |\n", static_cast<unsigned long long>(counters.light_commands));
  std::printf("| Hue group commands accepted | %llu |\n", static_cast<unsigned long long>(counters.group_commands));
  std::printf("| **requests refused for rate (429) / busy (503)** | **%llu / %llu** |\n",
              static_cast<unsigned long long>(counters.refused_rate), static_cast<unsigned long long>(counters.refused_busy));

  // --- 2. live view, alone and while a download runs
  auto live_client = veneer::rig::Client::connect({"127.0.0.1", d.port()}, d.token());
  if (!live_client) return 1;
  std::atomic<int> frames{0};
  std::atomic<int> frame_w{0}, frame_h{0};
  (*live_client)->on_live_frame = [&](const veneer::rig::LiveFrame& f) {
    ++frames;
    frame_w = f.width;
    frame_h = f.height;
  };
  auto measure_live = [&](double seconds) {
    frames = 0;
    auto t0 = Clock::now();
    std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
    return frames.load() / secs(Clock::now() - t0);
  };
  (void)(*live_client)->start_live_view(30);
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  double fps_alone = measure_live(3);

  std::atomic<bool> stop{false};
  std::atomic<uint64_t> downloaded{0};
  std::thread downloader([&] {
    int n = 0;
    while (!stop) {
      fs::path out = dir / ("pull-" + std::to_string(n++));
      if (c.pull(*id, out, true)) {
        std::error_code ec;
        for (auto& e : fs::recursive_directory_iterator(out, ec)) {
          if (e.is_regular_file()) downloaded += e.file_size();
        }
      }
      fs::remove_all(out);
    }
  });
  auto t_dl = Clock::now();
  double fps_download = measure_live(4);
  stop = true;
  downloader.join();
  double dl_mb_s = downloaded.load() / 1048576.0 / secs(Clock::now() - t_dl);
  auto stats = d.server().stats();
  std::printf("\n### Live view (%dx%d JPEG, 30 fps asked)\n\n", frame_w.load(), frame_h.load());
  std::printf("| measure | alone | while downloading | ratio |\n|---|---|---|---|\n");
  std::printf("| **frames per second** | %.1f | **%.1f** | %.2f |\n", fps_alone, fps_download,
              fps_alone > 0 ? fps_download / fps_alone : 0.0);
  std::printf("| download rate (MiB/s) | - | %.1f | - |\n", dl_mb_s);
  std::printf("| live frames dropped for slow clients | - | %llu | - |\n",
              static_cast<unsigned long long>(stats.live_frames_dropped));
  live_client->reset();
  client->reset();
  daemon->reset();
  fs::remove_all(dir);
  return 0;
}
