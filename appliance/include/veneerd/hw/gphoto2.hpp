#pragma once
// The "gphoto2" camera: a DSLR over USB (PTP) or over the network (PTP/IP,
// libgphoto2's "ptpip:" port) through libgphoto2, behind a seam. Gphoto2Api is the small part of libgphoto2 the back-end uses, one
// method per call sequence; make_libgphoto2_api() wraps the real library and
// tests substitute a fake. USB hotplug (libusb) sits behind UsbHotplug the
// same way. No gphoto2 or libusb type appears in this header.
//
// RAW: no RAW decoder is in the package list, so a set image comes from a
// JPEG: the camera's paired JPEG when it shoots RAW+JPEG (recommended), else
// the largest JPEG embedded in the RAW file (CR2/NEF/ARW/DNG all carry one).
// The JPEG is linearised (inverse sRGB curve). The RAW file itself is kept in
// Still::original, untouched, for anyone who wants to decode it offline.
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "veneer/util/expected.hpp"
#include "veneerd/devices/camera.hpp"

namespace veneerd::hw {

// libgphoto2's result codes the back-end reacts to (same values as GP_*;
// gphoto2_api.cpp checks them at compile time).
namespace gp {
constexpr int ok = 0;
constexpr int error = -1;
constexpr int bad_parameters = -2;
constexpr int not_supported = -6;
constexpr int io = -7;
constexpr int timeout = -10;
constexpr int io_usb_find = -52;
constexpr int io_usb_claim = -53;
constexpr int model_not_found = -105;
constexpr int camera_busy = -110;
constexpr int camera_error = -113;
}  // namespace gp

struct CameraFilePath {
  std::string folder, name;
};

struct ConfigValue {
  enum class Type { text, range, toggle, radio, menu, other } type = Type::other;
  std::string value;                  // current value as text (ranges: "%g")
  std::vector<std::string> choices;   // radio / menu choices
  float min = 0, max = 0, step = 0;   // ranges
  bool readonly = false;
};

struct DetectedCamera {
  std::string model, port;  // port like "usb:001,005"
};

class Gphoto2Api {
 public:
  virtual ~Gphoto2Api() = default;
  // gp_camera_new + gp_camera_init; model/port "" = the first camera found.
  virtual int open(const std::string& model, const std::string& port) = 0;
  virtual void close() = 0;  // gp_camera_exit + gp_camera_unref
  virtual std::string model() = 0;      // gp_camera_get_abilities
  virtual std::string port_path() = 0;  // gp_camera_get_port_info + gp_port_info_get_path
  // gp_camera_get_single_config + gp_widget_get_type/value/choices/readonly
  virtual int get_config(const std::string& name, ConfigValue& out) = 0;
  // gp_camera_get_single_config + gp_widget_set_value + gp_camera_set_single_config
  virtual int set_config(const std::string& name, const std::string& value) = 0;
  virtual int capture(CameraFilePath& path) = 0;  // gp_camera_capture(GP_CAPTURE_IMAGE)
  // gp_camera_wait_for_event: `added` is set for GP_EVENT_FILE_ADDED.
  virtual int wait_file_added(int timeout_ms, CameraFilePath& added, bool& got) = 0;
  // gp_camera_file_get + gp_file_get_data_and_size
  virtual int download(const CameraFilePath& path, std::vector<unsigned char>& data) = 0;
  virtual int remove(const CameraFilePath& path) = 0;  // gp_camera_file_delete
  // gp_camera_capture_preview + gp_file_get_data_and_size
  virtual int preview(std::vector<unsigned char>& jpeg) = 0;
  virtual int autodetect(std::vector<DetectedCamera>& found) = 0;  // gp_camera_autodetect
  // Whether the session still answers, cheaply: gp_camera_wait_for_event for
  // 1 ms (over PTP/IP a closed connection shows at once). Used for network
  // cameras before the first call of a set; USB has hotplug instead.
  virtual int probe() { return gp::ok; }
  virtual std::string error_text(int code) = 0;                     // gp_result_as_string
};

std::unique_ptr<Gphoto2Api> make_libgphoto2_api();

struct UsbDeviceId {
  int bus = 0, address = 0;
  uint16_t vendor = 0, product = 0;
};

class UsbHotplug {
 public:
  virtual ~UsbHotplug() = default;
  // Calls `changed(arrived, device)` from an event thread for every USB device
  // that arrives or leaves.
  virtual veneer::Status start(std::function<void(bool arrived, const UsbDeviceId&)> changed) = 0;
  virtual void stop() = 0;
};

// libusb_hotplug_register_callback with an event thread; an error when the
// platform has no hotplug support.
std::unique_ptr<UsbHotplug> make_libusb_hotplug();

struct Gphoto2Options {
  // "" = first camera found; over PTP/IP "" means libgphoto2's generic
  // "PTP/IP Camera" driver (a vendor's "Nikon DSLR (WLAN)", "Canon EOS (WLAN)"
  // ... may be named instead).
  std::string model;
  // "" = any USB camera; "usb:001,005" pins one; "ptpip:HOST[:PORT[:EVENTPORT]]"
  // is a camera on the network (IPv4 address, port 15740 by default). The
  // parser writes both ports out: libgphoto2 2.5.30 would otherwise open the
  // event connection on 15740 whatever the command port.
  std::string port;
  bool manual_mode = true;           // put the body in M
  bool autofocus_off = true;         // focus once by hand; a failed AF lock reads as "busy"
  bool keep_on_card = false;         // false: capture to the camera's RAM / delete after download
  int reopen_delay_ms = 1500;        // wait after a USB arrival (or a lost network
                                     // connection) before reopening
  int paired_jpeg_wait_ms = 3000;    // how long to wait for the JPEG of a RAW+JPEG pair
  int still_width = 0, still_height = 0;  // set-image size; 0 = the live-view size
};

veneer::Expected<Gphoto2Options> parse_gphoto2_options(const nlohmann::json& section, const std::string& where);

// True for a libgphoto2 network port ("ptpip:...").
bool is_network_port(const std::string& port);

// The names vendors give the three exposure settings, in the order tried.
const std::vector<std::string>& shutter_setting_names();   // shutterspeed, shutterspeed2, ...
const std::vector<std::string>& aperture_setting_names();  // f-number, aperture, ...
const std::vector<std::string>& iso_setting_names();       // iso, isospeed, ...

// Picks the offered choice matching a value: shutter "1/250", "0.5", "30",
// "2s"; aperture "f/8", "8.0"; ISO "100". Nullopt when none is close enough.
std::optional<std::string> match_shutter(const std::vector<std::string>& choices, double seconds);
std::optional<std::string> match_aperture(const std::vector<std::string>& choices, double f_number);
std::optional<std::string> match_iso(const std::vector<std::string>& choices, int iso);

class Gphoto2Camera : public Camera {
 public:
  // Borrows nothing: takes the API and the hotplug source (may be null).
  Gphoto2Camera(std::unique_ptr<Gphoto2Api> api, std::unique_ptr<UsbHotplug> hotplug, Gphoto2Options options);
  ~Gphoto2Camera() override;

  std::string name() const override { return "gphoto2"; }
  veneer::Status open() override;
  bool connected() const override { return connected_; }
  veneer::Expected<CameraDescription> describe() override;
  veneer::Status set_exposure(const Exposure& exposure) override;
  veneer::Expected<Still> capture() override;
  veneer::Expected<std::vector<unsigned char>> preview() override;

  // The hotplug path (public for tests that play the USB events directly).
  void usb_changed(bool arrived, const UsbDeviceId& device);
  // Blocks until a pending reopen has finished (tests); false on timeout.
  bool wait_reopen_idle(int timeout_ms);

 private:
  veneer::Status open_locked();
  void close_locked();
  veneer::Status setup_locked();
  veneer::Status set_one(const std::vector<std::string>& names, const char* what, const std::string& shown,
                         const std::function<std::optional<std::string>(const std::vector<std::string>&)>& match);
  std::string find_setting(const std::vector<std::string>& names, ConfigValue* value);
  std::string describe_error(int code, const std::string& doing);
  void set_connected(bool c);
  void reopen_loop();
  // Network cameras: drop a session whose connection failed and open a new
  // one (after reopen_delay_ms); each operation does this at most once.
  veneer::Status reconnect_locked(const std::string& why);
  veneer::Status ensure_alive_locked(const char* doing);  // network: probe, reconnect when gone
  CameraDescription describe_locked();
  veneer::Status set_exposure_locked(const Exposure& exposure);
  veneer::Expected<Still> capture_locked();
  bool lost_code(int code) const;  // a code that means the network connection is gone
  int note(int code);              // records lost_code(code) in lost_seen_; returns code

  std::unique_ptr<Gphoto2Api> api_;
  std::unique_ptr<UsbHotplug> hotplug_;
  Gphoto2Options opt_;
  const bool network_;  // a PTP/IP camera: no hotplug, a lost connection is reopened on use
  bool lost_seen_ = false;  // a call since the last check failed as if the connection were gone
  std::mutex session_;  // one gphoto2 call sequence at a time
  bool open_ = false;
  std::atomic<bool> connected_{false};
  std::atomic<bool> unplugged_{false};  // set by hotplug; a capture in flight reads it
  std::string model_;
  std::atomic<int> bus_{-1}, address_{-1};
  cv::Size live_size_;
  // Reopen worker.
  std::mutex reopen_mu_;
  std::condition_variable reopen_cv_;
  bool reopen_wanted_ = false, reopen_busy_ = false, stopping_ = false;
  std::thread reopen_thread_;
};

// 8-bit sRGB BGR → linear float BGR, resized to fit `size` if nonzero.
cv::Mat linearize_srgb8(const cv::Mat& bgr8, cv::Size size = {});
// JPEG bytes → linear float BGR (inverse sRGB), resized to `size` if nonzero.
veneer::Expected<cv::Mat> decode_jpeg_linear(const std::vector<unsigned char>& jpeg, cv::Size size);
// The largest JPEG stream embedded in a RAW file; empty when there is none.
std::vector<unsigned char> embedded_jpeg(const std::vector<unsigned char>& raw);
bool is_raw_name(const std::string& file_name);

}  // namespace veneerd::hw
