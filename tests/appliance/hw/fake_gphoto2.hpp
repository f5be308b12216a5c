#pragma once
// A fake of the small libgphoto2 surface (Gphoto2Api): a camera body with
// named settings, files it "shoots", and switches for the faults a real rig
// meets (busy device, unplug mid-capture, no camera at all).
#include <condition_variable>
#include <map>
#include <mutex>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "veneerd/hw/gphoto2.hpp"

namespace veneerd::hw::testing {

struct FakeBody {
  std::string model = "Canon EOS 600D";
  std::string port = "usb:001,005";
  std::map<std::string, ConfigValue> settings;
  // What capture() produces: file name → bytes, in order (RAW first for pairs).
  std::vector<std::pair<std::string, std::vector<unsigned char>>> shot_files;
  std::vector<unsigned char> preview_jpeg;
};

class FakeGphoto2 : public Gphoto2Api {
 public:
  explicit FakeGphoto2(FakeBody body) : body_(std::move(body)) {}

  // Faults.
  int open_error = gp::ok;          // e.g. gp::io_usb_claim
  bool present = true;              // false = unplugged
  bool block_capture = false;       // capture waits until release() or unplug()
  int opens = 0, closes = 0, captures = 0;
  std::vector<std::string> removed;

  void unplug() {
    std::lock_guard<std::mutex> l(mu_);
    present = false;
    cv_.notify_all();
  }
  void replug(const std::string& port) {
    std::lock_guard<std::mutex> l(mu_);
    present = true;
    body_.port = port;
  }
  void release() {
    std::lock_guard<std::mutex> l(mu_);
    block_capture = false;
    cv_.notify_all();
  }
  bool wait_capture_started(int timeout_ms) {
    std::unique_lock<std::mutex> l(mu_);
    return cv_.wait_for(l, std::chrono::milliseconds(timeout_ms), [&] { return in_capture_; });
  }
  std::string setting(const std::string& name) {
    std::lock_guard<std::mutex> l(mu_);
    return body_.settings.at(name).value;
  }

  int open(const std::string&, const std::string&) override {
    std::lock_guard<std::mutex> l(mu_);
    if (!present) return gp::model_not_found;
    if (open_error != gp::ok) return open_error;
    ++opens;
    session_ = true;
    return gp::ok;
  }
  void close() override {
    std::lock_guard<std::mutex> l(mu_);
    if (session_) ++closes;
    session_ = false;
  }
  std::string model() override { return body_.model; }
  std::string port_path() override { return body_.port; }
  int get_config(const std::string& name, ConfigValue& out) override {
    std::lock_guard<std::mutex> l(mu_);
    if (!live()) return gp::io;
    auto it = body_.settings.find(name);
    if (it == body_.settings.end()) return gp::bad_parameters;
    out = it->second;
    return gp::ok;
  }
  int set_config(const std::string& name, const std::string& value) override {
    std::lock_guard<std::mutex> l(mu_);
    if (!live()) return gp::io;
    auto it = body_.settings.find(name);
    if (it == body_.settings.end()) return gp::bad_parameters;
    if (it->second.readonly) return gp::not_supported;
    const auto& c = it->second.choices;
    if (!c.empty() && std::find(c.begin(), c.end(), value) == c.end()) return gp::bad_parameters;
    it->second.value = value;
    return gp::ok;
  }
  int capture(CameraFilePath& path) override {
    std::unique_lock<std::mutex> l(mu_);
    if (!live()) return gp::io;
    in_capture_ = true;
    cv_.notify_all();
    cv_.wait(l, [&] { return !block_capture || !present; });
    in_capture_ = false;
    if (!present) return gp::io;
    ++captures;
    pending_.clear();
    for (size_t i = 1; i < body_.shot_files.size(); ++i) pending_.push_back(body_.shot_files[i].first);
    path = {"/store_00020001/DCIM/100CANON", body_.shot_files.at(0).first};
    return gp::ok;
  }
  int wait_file_added(int, CameraFilePath& added, bool& got) override {
    std::lock_guard<std::mutex> l(mu_);
    if (!live()) return gp::io;
    got = !pending_.empty();
    if (got) {
      added = {"/store_00020001/DCIM/100CANON", pending_.front()};
      pending_.erase(pending_.begin());
    }
    return gp::ok;
  }
  int download(const CameraFilePath& path, std::vector<unsigned char>& data) override {
    std::lock_guard<std::mutex> l(mu_);
    if (!live()) return gp::io;
    for (const auto& [name, bytes] : body_.shot_files)
      if (name == path.name) {
        data = bytes;
        return gp::ok;
      }
    return -108;  // file not found
  }
  int remove(const CameraFilePath& path) override {
    std::lock_guard<std::mutex> l(mu_);
    removed.push_back(path.name);
    return live() ? gp::ok : gp::io;
  }
  int preview(std::vector<unsigned char>& jpeg) override {
    std::lock_guard<std::mutex> l(mu_);
    if (!live()) return gp::io;
    jpeg = body_.preview_jpeg;
    return gp::ok;
  }
  int autodetect(std::vector<DetectedCamera>& found) override {
    found.clear();
    if (present) found.push_back({body_.model, body_.port});
    return gp::ok;
  }
  std::string error_text(int code) override { return code == gp::io ? "I/O problem" : "Unspecified error"; }

 private:
  bool live() const { return present && session_; }
  FakeBody body_;
  std::mutex mu_;
  std::condition_variable cv_;
  bool session_ = false, in_capture_ = false;
  std::vector<std::string> pending_;
};

inline ConfigValue radio(std::string value, std::vector<std::string> choices, bool readonly = false) {
  ConfigValue v;
  v.type = ConfigValue::Type::radio;
  v.value = std::move(value);
  v.choices = std::move(choices);
  v.readonly = readonly;
  return v;
}

}  // namespace veneerd::hw::testing
