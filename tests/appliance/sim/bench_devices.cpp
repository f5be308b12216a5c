// bench_devices: the simulated rig's device layer on loopback.
//  1. Lamp switching through the "hue" backend against the bridge emulator with
//     the bridge's limits (10 light/s, 1 group/s, 3 in flight), per-request
//     latency and ack-before-change delay, compared with one raw PUT round trip.
//  2. Full capture sequences through the real sequencer (run_capture: each
//     step's lamps proven by reading the bridge before and after the exposure,
//     the owner's lamps restored) with the simulated camera at 1024x680: time
//     per shot beyond the camera's own time and the settle wait, requests per
//     shot, refusals; with the owner's lamps all off and with two left on.
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

#include "veneerd/config.hpp"
#include "veneerd/sim/simulated_rig.hpp"
#include "veneerd/sequencer.hpp"

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

// The camera, with the time spent in it counted (what the shot needs anyway).
class TimedCamera : public veneerd::Camera {
 public:
  explicit TimedCamera(veneerd::Camera& c) : c_(c) {}
  std::string name() const override { return c_.name(); }
  veneer::Status open() override { return c_.open(); }
  bool connected() const override { return c_.connected(); }
  veneer::Expected<veneerd::CameraDescription> describe() override { return c_.describe(); }
  veneer::Status set_exposure(const veneerd::Exposure& e) override { return c_.set_exposure(e); }
  veneer::Expected<veneerd::Still> capture() override {
    auto t0 = Clock::now();
    auto s = c_.capture();
    ms += ms_since(t0);
    ++shots;
    return s;
  }
  veneer::Expected<std::vector<unsigned char>> preview() override { return c_.preview(); }
  double ms = 0;
  int shots = 0;

 private:
  veneerd::Camera& c_;
};

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
  veneerd::hw::HueLampsOptions raw_opts = (*lamps)->options();
  raw_opts.settle_ms = 0;
  raw_opts.group.clear();
  auto raw = veneerd::hw::HueLamps::create(raw_opts);
  std::vector<double> round_trip;
  (void)(*raw)->all_off();
  for (int i = 0; i < 8; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(400));
    std::vector<veneerd::LampState> from(7, veneerd::LampState{}), to = from;
    (i % 2 == 0 ? to : from)[0] = veneerd::rig_white();
    auto t0 = Clock::now();
    (void)(*raw)->command(from, to);  // one PUT, no reading
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
  std::printf("| one proven step (read, lamp i off + lamp i+1 on, settle, read back) | %.1f | %.1f | %.1f |\n", median(step_ms),
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
  std::printf("\n### Capture sequences through the sequencer: 3 sets x 8 shots (ambient + 7 lamps), simulated camera "
              "1024x680\n\n");
  std::printf("Each step: read the bridge, command what differs, read back (proven), expose, read again. "
              "Overhead = wall time per shot minus the camera's time (bridge read + render) minus the settle wait "
              "(%d ms, which covers the bridge's %d ms ack-before-change).\n\n",
              o.settle_ms, o.apply_delay_ms);
  std::printf("| owner's lamps before the set | shots | ms per shot | camera ms per shot | overhead ms per shot "
              "(beyond camera + settle) | light cmds per shot | GETs per shot | commands paced | retakes | 429 | 503 |\n"
              "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
  auto ring = veneerd::thesis_ring_positions();
  for (int owner_on : {0, 2}) {
    // The owner's lamps as they would be found: all off, or two on in their own colours.
    std::vector<veneerd::LampState> owner(7, veneerd::LampState{});
    if (owner_on) {
      owner[1] = veneerd::LampState{.on = true, .brightness = 150, .mode = veneerd::ColourMode::ct, .ct = 400};
      owner[4] = veneerd::LampState{.on = true, .brightness = 90, .x = 0.5, .y = 0.4};
    }
    for (int i = 0; i < 7; ++i) bridge.set_lamp(std::to_string(i + 1), owner[i]);
    TimedCamera timed(**camera);
    bridge.reset_counters();
    const auto paced0 = (*lamps)->stats().paced_waits;
    const int sets = 3;
    double total_ms = 0;
    int retakes = 0;
    for (int s = 0; s < sets; ++s) {
      (void)(*camera)->set_scene(s % 2 ? (*rig)->source_scene() : (*rig)->destination_scene());
      veneerd::CapturePlan plan;
      plan.set_id = "bench";
      plan.exposure.shutter_s = 1.0 / 30;
      for (int i = 0; i < 7; ++i) plan.lamp_ids.push_back(std::to_string(i + 1));
      plan.lamp_positions.assign(ring.begin(), ring.begin() + 7);
      auto t0 = Clock::now();
      auto r = veneerd::run_capture(**lamps, timed, plan);
      // The restore at the end is part of the set's cost; spread over its shots.
      total_ms += ms_since(t0);
      if (!r) std::fprintf(stderr, "capture failed: %s\n", r.message().c_str());
      else retakes += r->retakes;
      if (r && s == 0 && !out_dir.empty()) {
        cv::Mat png;
        r->set.images[3].convertTo(png, CV_16UC3, 65535.0);
        cv::imwrite(out_dir + "/sequence_lamp4.png", png);
      }
    }
    auto c = bridge.counters();
    const double shots = timed.shots;
    const double per_shot = total_ms / shots, cam = timed.ms / shots;
    std::printf("| %s | %.0f | %.1f | %.1f | %.1f | %.2f | %.2f | %llu | %d | %llu | %llu |\n",
                owner_on ? "two on (ct, xy)" : "all off", shots, per_shot, cam, per_shot - cam - o.settle_ms,
                c.light_commands / shots, (c.requests - c.light_commands - c.group_commands) / shots,
                static_cast<unsigned long long>((*lamps)->stats().paced_waits - paced0), retakes,
                static_cast<unsigned long long>(c.refused_rate), static_cast<unsigned long long>(c.refused_busy));
  }
  std::printf("\nThe simulated camera reads the bridge once per shot itself (one of the GETs).\n");

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
