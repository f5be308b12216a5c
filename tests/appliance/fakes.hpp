#pragma once
// In-memory lamps and camera for sequencer/store tests (no HTTP, no rendering).
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
  veneer::Expected<std::vector<veneerd::LampState>> read() override { return states_; }
  veneer::Status set(const std::vector<bool>& on, int brightness) override {
    ++sets;
    if (fail_on_set > 0 && sets == fail_on_set) return veneer::make_error("bridge timeout (fake)");
    if (down) return veneer::make_error("bridge down (fake)");
    for (size_t i = 0; i < on.size(); ++i) {
      states_[i].on = on[i];
      states_[i].brightness = brightness;
      states_[i].x = 0.3227;
      states_[i].y = 0.329;
    }
    return {};
  }
  veneer::Status restore(const std::vector<veneerd::LampState>& s) override {
    ++restores;
    if (down) return veneer::make_error("bridge down (fake)");
    states_ = s;
    return {};
  }
  std::vector<veneerd::LampState> states_;
  int sets = 0, restores = 0, fail_on_set = 0;
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
    float v = ambient;
    for (int i = 0; i < lamps_.count(); ++i) {
      if (lamps_.states_[i].on) v += 0.1f * (i + 1);
    }
    veneerd::Still s;
    s.linear = cv::Mat(size_, CV_32FC3, cv::Scalar(v, v, v));
    return s;
  }
  veneer::Expected<std::vector<unsigned char>> preview() override { return std::vector<unsigned char>{0xff, 0xd8}; }
  FakeLamps& lamps_;
  cv::Size size_;
  int shots = 0, fail_on_shot = 0;
  float ambient = 0;
};

}  // namespace rigtest
