#pragma once
// veneerd's configuration file (JSON). Every field is optional except where a
// back-end needs it; an error names the file, the field and what was wrong.
//
// {
//   "name": "veneer-rig",
//   "listen": "0.0.0.0:7878",
//   "store": "/var/lib/veneer/sets",
//   "token_file": "/var/lib/veneer/sets/token",     default <store>/token
//   "tls_key_file": "...", "tls_cert_file": "...",   default <store>.tls/key.pem, <store>.tls/cert.pem
//   "plain_tcp": false,                              true: the API in clear (no TLS), said in status and log
//   "lamps": {"backend": "hue", "bridge": "192.168.1.20", "key": "...",
//             "lamps": ["3","4","5","6","7","8","9"],   Hue ids in ring order
//             "settle_ms": 150,
//             "positions_m": [[x,y,z], ...]}            default: the thesis ring
//   "camera": {"backend": "gphoto2", ...},              passed to the back-end
//   "trigger": {"backend": "gpio", ...}, "led": {"backend": "gpio", ...},
//   "gpio": {"chip": "gpiochip0", "button_line": 17, "led_line": 27},
//   "capture": {"shutter_s": 0.25, "aperture": 8, "iso": 100,
//               "ambient_warning": 0.05}
// }
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "veneer/util/expected.hpp"
#include "veneerd/devices/camera.hpp"

namespace veneerd {

struct DeviceConfig {
  std::string backend;     // registry name
  nlohmann::json section;  // the whole section, handed to the back-end's factory
};

struct Config {
  std::string name = "veneer-rig";
  std::string listen_host = "127.0.0.1";
  uint16_t listen_port = 7878;
  std::filesystem::path store = "veneer-sets";
  std::filesystem::path token_file;  // empty = <store>/token
  // The TLS identity sits beside the store, not in it: the store holds sets
  // (and the token), and its bytes are the sets' bytes.
  std::filesystem::path tls_key_file;   // empty = <store>.tls/key.pem (made 0600 at first start, folder 0700)
  std::filesystem::path tls_cert_file;  // empty = <store>.tls/cert.pem (self-signed, made with the key)
  bool plain_tcp = false;               // serve the API without TLS (only when configured so)
  DeviceConfig lamps{"hue", nlohmann::json::object()};
  DeviceConfig camera{"simulated", nlohmann::json::object()};
  DeviceConfig trigger{"simulated", nlohmann::json::object()};
  DeviceConfig led{"none", nlohmann::json::object()};
  std::vector<std::string> lamp_ids;       // Hue ids in ring order (from lamps.lamps)
  std::vector<cv::Vec3d> lamp_positions;   // rig frame [m], one per ring position
  int settle_ms = 150;                     // lamp settle time after the bridge's ack [ms]
  Exposure exposure;                       // default exposure of a capture
  double ambient_warning = 0.05;           // ambient mean (fraction of full scale) that warns

  std::filesystem::path token_path() const { return token_file.empty() ? store / "token" : token_file; }
  std::filesystem::path tls_dir() const { return store.string() + ".tls"; }
  std::filesystem::path tls_key_path() const { return tls_key_file.empty() ? tls_dir() / "key.pem" : tls_key_file; }
  std::filesystem::path tls_cert_path() const { return tls_cert_file.empty() ? tls_dir() / "cert.pem" : tls_cert_file; }
};

// "host:port", "host" (port 7878) or ":port" (all interfaces).
veneer::Status parse_listen(const std::string& text, std::string& host, uint16_t& port);

// Parses a config document; `origin` names it in errors.
veneer::Expected<Config> parse_config(const nlohmann::json& doc, const std::string& origin);
veneer::Expected<Config> load_config(const std::filesystem::path& file);

// The thesis ring: 8 sockets on a 0.47 m circle around the camera at (0,0,1),
// the bottom one empty — 7 positions in the rig's light order.
std::vector<cv::Vec3d> thesis_ring_positions();

}  // namespace veneerd
