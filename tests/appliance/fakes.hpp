#pragma once
// In-memory lamps and camera for sequencer/store tests (no HTTP, no rendering).
#include <functional>
#include <memory>
#include <vector>

#include "veneerd/devices/camera.hpp"
#include "veneerd/devices/lamps.hpp"

namespace rigtest {

class FakeLamps : public veneerd::Lamps {
 public:
  explicit FakeLamps(int n) : states_(n) {}
  std::string name() const override { return "fake"; }
  int count() const override { return static_cast<int>(states_.size()); }
  int confirm_ms() const override { return 0; }  // takes commands at once
  veneer::Expected<std::vector<veneerd::LampState>> read() override {
    ++reads;
    if (down) return veneer::make_error("bridge down (fake)");
    return states_;
  }
  // Takes the wanted state at once; counts calls (a call per step or restore).
  veneer::Status command(const std::vector<veneerd::LampState>& now,
                         const std::vector<veneerd::LampState>& want) override {
    ++sets;
    if (fail_on_set > 0 && sets == fail_on_set) return veneer::make_error("bridge timeout (fake)");
    if (down) return veneer::make_error("bridge down (fake)");
    for (size_t i = 0; i < want.size(); ++i) {
      if (veneerd::same_light(now[i], want[i]) && now[i].on) continue;
      bool reachable = states_[i].reachable;
      states_[i] = want[i];
      states_[i].reachable = reachable;
    }
    if (after_command) after_command(sets);
    return {};
  }
  std::function<void(int)> after_command;  // another client's change, after the n-th command()
  std::vector<veneerd::LampState> states_;
  int sets = 0, reads = 0, fail_on_set = 0;
  bool down = false;
};

class FakeCamera : public veneerd::Camera {
 public:
  FakeCamera(FakeLamps& lamps, cv::Size size) : lamps_(lamps), size_(size) {}
  std::string name() const override { return "fake"; }
  veneer::Status open() override { return {}; }
  bool connected() const override { return true; }
  veneer::Expected<veneerd::CameraDescription> describe() override { return veneerd::CameraDescription{"fake cam", {}, {}, {}}; }
  veneer::Status set_exposure(const veneerd::Exposure&) override { return {}; }
  // Pixel value encodes which lamp is on: 0.1 * (i + 1), plus the ambient level.
  veneer::Expected<veneerd::Still> capture() override {
    ++shots;
    if (fail_on_shot == shots) return veneer::make_error("shutter jammed (fake)");
    if (during_exposure) during_exposure(shots);
    float v = ambient;
    for (int i = 0; i < lamps_.count(); ++i) {
      if (lamps_.states_[i].on) v += 0.1f * (i + 1);
    }
    veneerd::Still s;
    s.linear = cv::Mat(size_, CV_32FC3, cv::Scalar(v, v, v));
    if (raw) {  // a RAW+JPEG body: the RAW file as delivered, named by the camera
      s.original_name = "IMG_" + std::to_string(1000 + shots) + ".CR2";
      const std::string bytes = "raw of shot " + std::to_string(shots);
      s.original.assign(bytes.begin(), bytes.end());
    }
    return s;
  }
  veneer::Expected<std::vector<unsigned char>> preview() override { return std::vector<unsigned char>{0xff, 0xd8}; }
  FakeLamps& lamps_;
  cv::Size size_;
  std::function<void(int shot)> during_exposure;  // another client's change while the shutter is open
  int shots = 0, fail_on_shot = 0;
  float ambient = 0;
  bool raw = false;  // deliver a RAW file with each still
};

}  // namespace rigtest
