#include "veneerd/config.hpp"

#include <cmath>
#include <fstream>
#include <sstream>

#include "veneer/sim/simulator.hpp"
#if __has_include("veneerd/hw/check.hpp")
#include "veneerd/hw/check.hpp"
#endif

namespace veneerd {

using nlohmann::json;
using veneer::make_error;

namespace {

std::string show(const json& value) {
  std::string s = value.dump();
  if (s.size() > 60) s = s.substr(0, 57) + "...";
  return s;
}

// Field readers: each returns an error naming origin, field path and value.
struct Reader {
  const std::string& origin;

  veneer::Error bad(const std::string& field, const std::string& expected, const json& value) const {
    return make_error(origin + ": " + field + ": expected " + expected + ", got " + show(value));
  }
  veneer::Status string(const json& obj, const char* key, const std::string& path, std::string& out) const {
    if (!obj.contains(key)) return {};
    const json& v = obj.at(key);
    if (!v.is_string() || v.get<std::string>().empty()) return bad(path, "a non-empty string", v);
    out = v.get<std::string>();
    return {};
  }
  veneer::Status number(const json& obj, const char* key, const std::string& path, double lo, double hi,
                        double& out) const {
    if (!obj.contains(key)) return {};
    const json& v = obj.at(key);
    if (!v.is_number() || !std::isfinite(v.get<double>()) || v.get<double>() < lo || v.get<double>() > hi) {
      std::ostringstream range;
      range << "a number in [" << lo << ", " << hi << "]";
      return bad(path, range.str(), v);
    }
    out = v.get<double>();
    return {};
  }
  veneer::Status integer(const json& obj, const char* key, const std::string& path, long lo, long hi,
                         long& out) const {
    if (!obj.contains(key)) return {};
    const json& v = obj.at(key);
    if (!v.is_number_integer() || v.get<long>() < lo || v.get<long>() > hi) {
      return bad(path, "an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]", v);
    }
    out = v.get<long>();
    return {};
  }
  veneer::Status device(const json& doc, const char* key, DeviceConfig& out) const {
    if (!doc.contains(key)) return {};
    const json& v = doc.at(key);
    if (!v.is_object()) return bad(key, "an object", v);
    out.section = v;
    if (v.contains("backend")) {
      if (!v.at("backend").is_string() || v.at("backend").get<std::string>().empty()) {
        return bad(std::string(key) + ".backend", "a back-end name", v.at("backend"));
      }
      out.backend = v.at("backend").get<std::string>();
    }
    return {};
  }
};

}  // namespace

std::vector<cv::Vec3d> thesis_ring_positions() {
  std::vector<cv::Vec3d> out;
  for (const auto& lamp : veneer::sim::thesis_rig()) out.push_back(lamp.position_m);
  if (!out.empty()) return out;
  // The simulator's rig is the reference; this is the same geometry spelled out.
  const double kPi = 3.14159265358979323846;
  for (int socket = 0; socket < 8; ++socket) {
    double a = kPi / 2 - socket * kPi / 4;  // top first, clockwise
    if (socket == 4) continue;              // bottom socket left empty
    out.emplace_back(0.47 * std::cos(a), 0.47 * std::sin(a), 1.0);
  }
  return out;
}

veneer::Status parse_listen(const std::string& text, std::string& host, uint16_t& port) {
  std::string h = text;
  long p = 7878;
  auto colon = text.rfind(':');
  if (colon != std::string::npos) {
    h = text.substr(0, colon);
    std::string digits = text.substr(colon + 1);
    if (digits.empty() || digits.size() > 5 || digits.find_first_not_of("0123456789") != std::string::npos) {
      return make_error("listen address '" + text + "': port '" + digits + "' is not a number");
    }
    p = std::stol(digits);
    if (p < 0 || p > 65535) return make_error("listen address '" + text + "': port out of range");
  }
  if (h.empty()) h = "0.0.0.0";
  if (h.size() > 2 && h.front() == '[' && h.back() == ']') h = h.substr(1, h.size() - 2);
  host = h;
  port = static_cast<uint16_t>(p);
  return {};
}

veneer::Expected<Config> parse_config(const json& doc, const std::string& origin) {
  Reader r{origin};
  if (!doc.is_object()) return r.bad("(top level)", "an object", doc);
  static const char* known[] = {"name", "listen", "store", "token_file", "tls_key_file", "tls_cert_file",
                                "plain_tcp", "lamps", "camera", "trigger", "led", "gpio", "capture"};
  for (const auto& [key, value] : doc.items()) {
    bool ok = false;
    for (const char* k : known) ok = ok || key == k;
    if (!ok) return make_error(origin + ": unknown field '" + key + "'");
  }
  Config c;
  std::string text;
  if (auto s = r.string(doc, "name", "name", c.name); !s) return s.error();
  if (doc.contains("listen")) {
    if (auto s = r.string(doc, "listen", "listen", text); !s) return s.error();
    if (auto s = parse_listen(text, c.listen_host, c.listen_port); !s) return make_error(origin + ": listen: " + s.message());
  }
  text.clear();
  if (auto s = r.string(doc, "store", "store", text); !s) return s.error();
  if (!text.empty()) c.store = text;
  text.clear();
  if (auto s = r.string(doc, "token_file", "token_file", text); !s) return s.error();
  if (!text.empty()) c.token_file = text;
  text.clear();
  if (auto s = r.string(doc, "tls_key_file", "tls_key_file", text); !s) return s.error();
  if (!text.empty()) c.tls_key_file = text;
  text.clear();
  if (auto s = r.string(doc, "tls_cert_file", "tls_cert_file", text); !s) return s.error();
  if (!text.empty()) c.tls_cert_file = text;
  if (doc.contains("plain_tcp")) {
    if (!doc.at("plain_tcp").is_boolean()) return r.bad("plain_tcp", "true or false", doc.at("plain_tcp"));
    c.plain_tcp = doc.at("plain_tcp").get<bool>();
  }

  if (auto s = r.device(doc, "lamps", c.lamps); !s) return s.error();
  if (auto s = r.device(doc, "camera", c.camera); !s) return s.error();
  if (auto s = r.device(doc, "trigger", c.trigger); !s) return s.error();
  if (auto s = r.device(doc, "led", c.led); !s) return s.error();

  // The simulated camera renders what the Hue bridge reports: it reads the
  // same bridge as the lamps, so its section need not repeat where that is.
  if (c.camera.backend == "simulated" && c.lamps.section.is_object()) {
    for (const char* key : {"bridge", "key", "lamps", "timeout_ms"}) {
      if (!c.camera.section.contains(key) && c.lamps.section.contains(key)) c.camera.section[key] = c.lamps.section[key];
    }
  }

  const json& lamps = c.lamps.section;
  if (lamps.contains("lamps")) {
    const json& ids = lamps.at("lamps");
    if (!ids.is_array() || ids.empty()) return r.bad("lamps.lamps", "a non-empty array of Hue light ids", ids);
    for (size_t i = 0; i < ids.size(); ++i) {
      if (!ids[i].is_string() || ids[i].get<std::string>().empty()) {
        return r.bad("lamps.lamps[" + std::to_string(i) + "]", "a Hue light id string", ids[i]);
      }
      c.lamp_ids.push_back(ids[i].get<std::string>());
    }
  }
  long settle = c.settle_ms;
  if (auto s = r.integer(lamps, "settle_ms", "lamps.settle_ms", 0, 10000, settle); !s) return s.error();
  c.settle_ms = static_cast<int>(settle);
  if (lamps.contains("positions_m")) {
    const json& pos = lamps.at("positions_m");
    if (!pos.is_array()) return r.bad("lamps.positions_m", "an array of [x, y, z] in metres", pos);
    for (size_t i = 0; i < pos.size(); ++i) {
      const json& p = pos[i];
      std::string field = "lamps.positions_m[" + std::to_string(i) + "]";
      if (!p.is_array() || p.size() != 3 || !p[0].is_number() || !p[1].is_number() || !p[2].is_number()) {
        return r.bad(field, "[x, y, z] in metres", p);
      }
      cv::Vec3d v(p[0].get<double>(), p[1].get<double>(), p[2].get<double>());
      if (!std::isfinite(v[0]) || !std::isfinite(v[1]) || !std::isfinite(v[2]) || cv::norm(v) < 0.05 ||
          cv::norm(v) > 20) {
        return r.bad(field, "a lamp position 0.05..20 m from the object", p);
      }
      c.lamp_positions.push_back(v);
    }
    if (!c.lamp_ids.empty() && c.lamp_positions.size() != c.lamp_ids.size()) {
      return make_error(origin + ": lamps.positions_m has " + std::to_string(c.lamp_positions.size()) +
                        " entries but lamps.lamps names " + std::to_string(c.lamp_ids.size()) + " lamps");
    }
  }

  if (doc.contains("gpio")) {
    const json& g = doc.at("gpio");
    if (!g.is_object()) return r.bad("gpio", "an object", g);
    std::string chip;
    if (auto s = r.string(g, "chip", "gpio.chip", chip); !s) return s.error();
    long line = 0;
    if (auto s = r.integer(g, "button_line", "gpio.button_line", 0, 1023, line); !s) return s.error();
    if (auto s = r.integer(g, "led_line", "gpio.led_line", 0, 1023, line); !s) return s.error();
    // The GPIO back-ends read their lines from their own section; the shared
    // "gpio" block fills in what they do not say themselves.
    for (DeviceConfig* d : {&c.trigger, &c.led}) {
      for (const auto& [key, value] : g.items()) {
        if (!d->section.contains(key)) d->section[key] = value;
      }
    }
  }

  if (doc.contains("capture")) {
    const json& cap = doc.at("capture");
    if (!cap.is_object()) return r.bad("capture", "an object", cap);
    if (auto s = r.number(cap, "shutter_s", "capture.shutter_s", 0, 60, c.exposure.shutter_s); !s) return s.error();
    if (auto s = r.number(cap, "aperture", "capture.aperture", 0, 64, c.exposure.aperture); !s) return s.error();
    long iso = 0;
    if (auto s = r.integer(cap, "iso", "capture.iso", 0, 409600, iso); !s) return s.error();
    c.exposure.iso = static_cast<int>(iso);
    if (auto s = r.number(cap, "ambient_warning", "capture.ambient_warning", 0, 1, c.ambient_warning); !s) {
      return s.error();
    }
  }
  return c;
}

veneer::Expected<Config> load_config(const std::filesystem::path& file) {
  std::ifstream in(file);
  if (!in) return make_error(file.string() + ": cannot open config file");
  json doc = json::parse(in, nullptr, /*allow_exceptions=*/false, /*ignore_comments=*/true);
  if (doc.is_discarded()) return make_error(file.string() + ": not valid JSON");
  auto config = parse_config(doc, file.string());
  if (!config) return config;
#if __has_include("veneerd/hw/check.hpp")
  // The hardware back-ends' own sections, checked before anything is opened.
  if (auto s = validate_hardware_config(doc); !s) return make_error(file.string() + ": " + s.message());
#endif
  return config;
}

}  // namespace veneerd
