// The "gphoto2" camera back-end: session handling, vendor setting names,
// capture + download, live view, unplug/replug. All libgphoto2 access goes
// through Gphoto2Api (gphoto2_api.cpp), all libusb access through UsbHotplug.
#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdlib>

#include <opencv2/imgcodecs.hpp>

#include "veneer/util/log.hpp"
#include "veneerd/hw/gphoto2.hpp"

namespace veneerd::hw {

namespace {

std::string lower(std::string s) {
  for (char& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

std::string trim(const std::string& s) {
  size_t a = s.find_first_not_of(" \t");
  size_t b = s.find_last_not_of(" \t");
  return a == std::string::npos ? "" : s.substr(a, b - a + 1);
}

// A number from the start of `s` (after `skip`); nullopt if none.
std::optional<double> leading_number(const std::string& s) {
  const char* p = s.c_str();
  char* end = nullptr;
  double v = std::strtod(p, &end);
  if (end == p || !std::isfinite(v)) return std::nullopt;
  return v;
}

std::optional<double> parse_shutter(const std::string& choice) {
  std::string s = lower(trim(choice));
  if (!s.empty() && s.back() == 's') s = trim(s.substr(0, s.size() - 1));
  if (s.empty() || !(std::isdigit(static_cast<unsigned char>(s[0])))) return std::nullopt;
  size_t slash = s.find('/');
  if (slash != std::string::npos) {
    auto a = leading_number(s.substr(0, slash));
    auto b = leading_number(s.substr(slash + 1));
    if (!a || !b || *b <= 0) return std::nullopt;
    return *a / *b;
  }
  // Reject trailing garbage such as "1 (bulb)".
  char* end = nullptr;
  double v = std::strtod(s.c_str(), &end);
  if (*end != '\0' && *end != ' ') return std::nullopt;
  return v;
}

std::optional<double> parse_f_number(const std::string& choice) {
  std::string s = lower(trim(choice));
  if (s.rfind("f/", 0) == 0) s = s.substr(2);
  else if (s.rfind("f", 0) == 0) s = s.substr(1);
  if (s.empty() || !std::isdigit(static_cast<unsigned char>(s[0]))) return std::nullopt;
  return leading_number(s);
}

// Closest choice within 1/6 stop (nominal values like f/5.6 or 1/60 are
// rounded; neighbouring settings are at least 1/3 stop apart).
std::optional<std::string> closest(const std::vector<std::string>& choices, double wanted,
                                   std::optional<double> (*parse)(const std::string&), double stops_per_factor2) {
  if (!(wanted > 0)) return std::nullopt;
  double best = 1e9;
  std::optional<std::string> pick;
  for (const auto& c : choices) {
    auto v = parse(c);
    if (!v || *v <= 0) continue;
    double d = std::abs(std::log2(*v / wanted)) * stops_per_factor2;
    if (d < best) {
      best = d;
      pick = c;
    }
  }
  if (best > 1.0 / 6.0 + 1e-9) return std::nullopt;
  return pick;
}

std::string join(const std::vector<std::string>& v, size_t max_items = 40) {
  std::string out;
  for (size_t i = 0; i < v.size() && i < max_items; ++i) out += (i ? ", " : "") + v[i];
  if (v.size() > max_items) out += ", ...";
  return out.empty() ? "nothing" : out;
}

std::string shutter_text(double s) {
  char buf[32];
  if (s < 1.0 && s > 0) std::snprintf(buf, sizeof buf, "1/%g s", std::round(1.0 / s * 10) / 10);
  else std::snprintf(buf, sizeof buf, "%g s", s);
  return buf;
}

bool parse_usb_port(const std::string& port, int& bus, int& address) {
  // "usb:001,005"
  if (port.rfind("usb:", 0) != 0) return false;
  return std::sscanf(port.c_str() + 4, "%d,%d", &bus, &address) == 2;
}

// "ptpip:HOST[:PORT[:EVENTPORT]]" -> host, ports (defaults 15740, event = command port).
bool parse_ptpip_port(const std::string& port, std::string& host, int& command, int& event) {
  if (!is_network_port(port)) return false;
  std::string rest = port.substr(6);
  std::vector<std::string> parts;
  size_t start = 0;
  for (;;) {
    size_t colon = rest.find(':', start);
    parts.push_back(rest.substr(start, colon == std::string::npos ? std::string::npos : colon - start));
    if (colon == std::string::npos) break;
    start = colon + 1;
  }
  if (parts.empty() || parts.size() > 3) return false;
  host = parts[0];
  int a = 0, b = 0, c = 0, d = 0;
  char tail = 0;
  if (std::sscanf(host.c_str(), "%d.%d.%d.%d%c", &a, &b, &c, &d, &tail) != 4) return false;
  for (int v : {a, b, c, d})
    if (v < 0 || v > 255) return false;
  auto number = [](const std::string& s, int& out) {
    if (s.empty() || s.size() > 5 || s.find_first_not_of("0123456789") != std::string::npos) return false;
    out = std::atoi(s.c_str());
    return out > 0 && out < 65536;
  };
  command = 15740;
  if (parts.size() > 1 && !number(parts[1], command)) return false;
  event = command;
  if (parts.size() > 2 && !number(parts[2], event)) return false;
  return true;
}

bool is_jpeg_name(const std::string& name) {
  std::string l = lower(name);
  return l.size() > 4 && (l.ends_with(".jpg") || l.ends_with(".jpeg"));
}

}  // namespace

bool is_network_port(const std::string& port) { return port.rfind("ptpip:", 0) == 0; }

const std::vector<std::string>& shutter_setting_names() {
  static const std::vector<std::string> n{"shutterspeed", "shutterspeed2", "exposuretime"};
  return n;
}
const std::vector<std::string>& aperture_setting_names() {
  static const std::vector<std::string> n{"f-number", "aperture", "fnumber"};
  return n;
}
const std::vector<std::string>& iso_setting_names() {
  static const std::vector<std::string> n{"iso", "isospeed", "iso speed"};
  return n;
}

std::optional<std::string> match_shutter(const std::vector<std::string>& choices, double seconds) {
  return closest(choices, seconds, parse_shutter, 1.0);
}

std::optional<std::string> match_aperture(const std::vector<std::string>& choices, double f_number) {
  // f-numbers go by sqrt(2) per stop: one stop = a factor 2 in f-number squared.
  return closest(choices, f_number, parse_f_number, 2.0);
}

std::optional<std::string> match_iso(const std::vector<std::string>& choices, int iso) {
  for (const auto& c : choices) {
    std::string s = lower(trim(c));
    if (s.rfind("iso", 0) == 0) s = trim(s.substr(3));
    char* end = nullptr;
    long v = std::strtol(s.c_str(), &end, 10);
    if (end != s.c_str() && *end == '\0' && v == iso) return c;
  }
  return std::nullopt;
}

veneer::Expected<Gphoto2Options> parse_gphoto2_options(const nlohmann::json& s, const std::string& where) {
  Gphoto2Options o;
  if (!s.is_object()) return veneer::make_error(where + ": expected an object");
  static const char* known[] = {"backend", "model", "port", "manual_mode", "autofocus_off", "keep_on_card",
                                "reopen_delay_ms", "paired_jpeg_wait_ms", "still_size"};
  for (const auto& item : s.items()) {
    const std::string& key = item.key();  // a named variable: clang 14 cannot capture structured bindings
    if (std::find_if(std::begin(known), std::end(known), [&](const char* k) { return key == k; }) == std::end(known))
      return veneer::make_error(where + ": unknown field '" + key + "' for the gphoto2 camera");
  }
  for (auto [key, field] : {std::pair{"model", &o.model}, std::pair{"port", &o.port}}) {
    if (!s.contains(key)) continue;
    if (!s[key].is_string()) return veneer::make_error(where + "." + key + ": expected a string");
    *field = s[key].get<std::string>();
  }
  if (is_network_port(o.port)) {
    std::string host;
    int command = 0, event = 0;
    if (!parse_ptpip_port(o.port, host, command, event))
      return veneer::make_error(where + ".port: '" + o.port + "' is not a PTP/IP port like \"ptpip:192.168.1.20\" or "
                                "\"ptpip:192.168.1.20:15740\" (an IPv4 address; libgphoto2 does not resolve host names)");
    o.port = "ptpip:" + host + ":" + std::to_string(command) + ":" + std::to_string(event);
    if (o.model.empty()) o.model = "PTP/IP Camera";
  } else if (!o.port.empty() && o.port.rfind("usb:", 0) != 0) {
    return veneer::make_error(where + ".port: '" + o.port + "' is neither a USB port like \"usb:001,005\" nor a PTP/IP "
                              "port like \"ptpip:192.168.1.20\"");
  }
  for (auto [key, field] : {std::pair{"manual_mode", &o.manual_mode}, std::pair{"autofocus_off", &o.autofocus_off},
                            std::pair{"keep_on_card", &o.keep_on_card}}) {
    if (!s.contains(key)) continue;
    if (!s[key].is_boolean()) return veneer::make_error(where + "." + key + ": expected true or false");
    *field = s[key].get<bool>();
  }
  for (auto [key, field] : {std::pair{"reopen_delay_ms", &o.reopen_delay_ms},
                            std::pair{"paired_jpeg_wait_ms", &o.paired_jpeg_wait_ms}}) {
    if (!s.contains(key)) continue;
    if (!s[key].is_number_integer() || s[key].get<long long>() < 0 || s[key].get<long long>() > 60000)
      return veneer::make_error(where + "." + key + ": expected milliseconds 0..60000");
    *field = s[key].get<int>();
  }
  if (s.contains("still_size")) {
    const auto& v = s["still_size"];
    if (!v.is_array() || v.size() != 2 || !v[0].is_number_integer() || !v[1].is_number_integer() ||
        v[0].get<int>() < 16 || v[1].get<int>() < 16 || v[0].get<int>() > 20000 || v[1].get<int>() > 20000)
      return veneer::make_error(where + ".still_size: expected [width, height] in pixels (16..20000)");
    o.still_width = v[0].get<int>();
    o.still_height = v[1].get<int>();
  }
  return o;
}

// ------------------------------------------------------------------ camera

Gphoto2Camera::Gphoto2Camera(std::unique_ptr<Gphoto2Api> api, std::unique_ptr<UsbHotplug> hotplug,
                             Gphoto2Options options)
    : api_(std::move(api)), hotplug_(std::move(hotplug)), opt_(std::move(options)), network_(is_network_port(opt_.port)) {
  if (opt_.still_width > 0) live_size_ = cv::Size(opt_.still_width, opt_.still_height);
  reopen_thread_ = std::thread([this] { reopen_loop(); });
  if (hotplug_) {
    auto s = hotplug_->start([this](bool arrived, const UsbDeviceId& d) { usb_changed(arrived, d); });
    if (!s) VLOG_WARN("Camera", "no USB hotplug notification ({}); an unplugged camera is noticed at its next use", s.message());
  }
}

Gphoto2Camera::~Gphoto2Camera() {
  if (hotplug_) hotplug_->stop();
  {
    std::lock_guard<std::mutex> lock(reopen_mu_);
    stopping_ = true;
  }
  reopen_cv_.notify_all();
  if (reopen_thread_.joinable()) reopen_thread_.join();
  std::lock_guard<std::mutex> lock(session_);
  close_locked();
}

void Gphoto2Camera::set_connected(bool c) {
  if (connected_.exchange(c) != c) {
    VLOG_INFO("Camera", "camera {}", c ? "connected: " + model_ : "disconnected");
    if (on_connection_change) on_connection_change(c);
  }
}

std::string Gphoto2Camera::describe_error(int code, const std::string& doing) {
  switch (code) {
    case gp::io_usb_claim:
      return "the camera is held by another program (a desktop's auto-mounter such as gvfs-gphoto2-volume-monitor, "
             "or another gphoto2 session); quit it or unmount the camera, then try again";
    case gp::model_not_found:
    case gp::io_usb_find:
      if (is_network_port(opt_.port))
        return "no '" + opt_.model + "' driver in libgphoto2 for " + opt_.port + " (the generic one is \"PTP/IP Camera\")";
      return "no camera found over USB: is it connected, switched on and set to PTP (not mass storage)?";
    case gp::camera_busy:
      return doing + ": the camera is busy (autofocus could not lock, or it is still writing the last shot); "
             "switch the lens to MF";
    default:
      if (unplugged_) return doing + ": the camera was unplugged";
      if (is_network_port(opt_.port) && !open_)
        return doing + " failed: no PTP/IP camera answered at " + opt_.port.substr(6) + " (" + api_->error_text(code) +
               ", gphoto2 error " + std::to_string(code) + "): is it switched on, on this network, and waiting for a "
               "computer (its PC-remote / Wi-Fi pairing mode)?";
      return doing + " failed: " + api_->error_text(code) + " (gphoto2 error " + std::to_string(code) + ")";
  }
}

veneer::Status Gphoto2Camera::open() {
  std::lock_guard<std::mutex> lock(session_);
  return open_locked();
}

veneer::Status Gphoto2Camera::open_locked() {
  if (open_) return {};
  int r = api_->open(opt_.model, opt_.port);
  if (r < gp::ok) {
    set_connected(false);
    return veneer::make_error("gphoto2 camera: " + describe_error(r, "opening the camera"));
  }
  open_ = true;
  unplugged_ = false;
  model_ = api_->model();
  std::string port = api_->port_path();
  int bus = -1, address = -1;
  if (!parse_usb_port(port, bus, address)) bus = address = -1;
  bus_ = bus;
  address_ = address;
  VLOG_INFO("Camera", "opened {} on {}", model_, port);
  if (auto s = setup_locked(); !s) VLOG_WARN("Camera", "{}", s.message());
  set_connected(true);
  return {};
}

void Gphoto2Camera::close_locked() {
  if (!open_) return;
  api_->close();
  open_ = false;
}

std::string Gphoto2Camera::find_setting(const std::vector<std::string>& names, ConfigValue* value) {
  for (const auto& n : names) {
    ConfigValue v;
    if (note(api_->get_config(n, v)) >= gp::ok) {
      if (value) *value = v;
      return n;
    }
  }
  return "";
}

veneer::Status Gphoto2Camera::setup_locked() {
  std::string warnings;
  auto warn = [&](const std::string& w) { warnings += (warnings.empty() ? "" : "; ") + w; };
  // Shots go to the camera's RAM so the card does not fill up.
  if (!opt_.keep_on_card) {
    ConfigValue v;
    if (api_->get_config("capturetarget", v) >= gp::ok) {
      for (const auto& c : v.choices)
        if (lower(c).find("ram") != std::string::npos && c != v.value) api_->set_config("capturetarget", c);
    }
  }
  auto choose = [&](const std::vector<std::string>& names, const std::vector<std::string>& wanted, const char* what,
                    const char* hint) {
    for (const auto& n : names) {
      ConfigValue v;
      if (api_->get_config(n, v) < gp::ok) continue;
      for (const auto& w : wanted)
        if (lower(v.value) == lower(w)) return;
      std::optional<std::string> pick;
      for (const auto& w : wanted)
        for (const auto& c : v.choices)
          if (!pick && lower(c) == lower(w)) pick = c;
      if (v.readonly || !pick || api_->set_config(n, *pick) < gp::ok) {
        warn(std::string(what) + " is '" + v.value + "' and cannot be changed over " + (network_ ? "the network" : "USB") +
             ": " + hint);
      }
      return;
    }
  };
  if (opt_.manual_mode)
    choose({"autoexposuremode", "expprogram", "exposureprogram"}, {"Manual", "M"}, "exposure mode",
           "turn the mode dial to M");
  if (opt_.autofocus_off)
    choose({"focusmode", "focusmode2"}, {"Manual", "MF", "Manual Focus", "MF (fixed)"}, "focus mode",
           "set the lens switch to MF");
  if (!warnings.empty()) return veneer::make_error(model_ + ": " + warnings);
  return {};
}

veneer::Expected<CameraDescription> Gphoto2Camera::describe() {
  std::lock_guard<std::mutex> lock(session_);
  if (auto s = open_locked(); !s) return s.error();
  if (auto s = ensure_alive_locked("describing the camera"); !s) return s.error();
  lost_seen_ = false;
  auto d = describe_locked();
  if (!network_ || !lost_seen_) return d;
  if (auto s = reconnect_locked("describing the camera"); !s) return s.error();
  return describe_locked();
}

CameraDescription Gphoto2Camera::describe_locked() {
  CameraDescription d;
  d.model = model_;
  auto fill = [&](const std::vector<std::string>& names, std::vector<std::string>& out) {
    ConfigValue v;
    if (find_setting(names, &v).empty()) return;
    if (v.type == ConfigValue::Type::range) {
      char buf[64];
      std::snprintf(buf, sizeof buf, "%g..%g", double(v.min), double(v.max));
      out.emplace_back(buf);
    } else {
      out = v.choices;
    }
  };
  fill(shutter_setting_names(), d.shutter_values);
  fill(aperture_setting_names(), d.aperture_values);
  fill(iso_setting_names(), d.iso_values);
  return d;
}

veneer::Status Gphoto2Camera::set_one(
    const std::vector<std::string>& names, const char* what, const std::string& shown,
    const std::function<std::optional<std::string>(const std::vector<std::string>&)>& match) {
  ConfigValue v;
  std::string name = find_setting(names, &v);
  if (name.empty())
    return veneer::make_error(model_ + " has no " + what + " setting (looked for " + join(names) + ")");
  if (v.readonly)
    return veneer::make_error(model_ + ": " + what + " (" + name + ") is read-only now: turn the mode dial to M" +
                              (std::string(what) == "aperture" ? " and use a lens with an electronic aperture" : ""));
  std::optional<std::string> pick = match(v.choices);
  if (!pick)
    return veneer::make_error(std::string(what) + " " + shown + " is not offered by " + model_ + " (" + name +
                              " offers: " + join(v.choices) + ")");
  if (*pick == v.value) return {};
  int r = note(api_->set_config(name, *pick));
  if (r < gp::ok) return veneer::make_error(describe_error(r, std::string("setting ") + what + " to " + *pick));
  VLOG_DEBUG("Camera", "{} = {}", name, *pick);
  return {};
}

veneer::Status Gphoto2Camera::set_exposure(const Exposure& e) {
  std::lock_guard<std::mutex> lock(session_);
  if (auto s = open_locked(); !s) return s;
  if (auto s = ensure_alive_locked("setting the exposure"); !s) return s;
  lost_seen_ = false;
  auto s = set_exposure_locked(e);
  if (s || !network_ || !lost_seen_) return s;
  if (auto r = reconnect_locked("setting the exposure: " + s.message()); !r) return r;
  return set_exposure_locked(e);
}

veneer::Status Gphoto2Camera::set_exposure_locked(const Exposure& e) {
  if (e.aperture > 0) {
    char shown[32];
    std::snprintf(shown, sizeof shown, "f/%g", e.aperture);
    if (auto s = set_one(aperture_setting_names(), "aperture", shown,
                         [&](const auto& c) { return match_aperture(c, e.aperture); });
        !s)
      return s;
  }
  if (e.shutter_s > 0) {
    if (auto s = set_one(shutter_setting_names(), "shutter speed", shutter_text(e.shutter_s),
                         [&](const auto& c) { return match_shutter(c, e.shutter_s); });
        !s)
      return s;
  }
  if (e.iso > 0) {
    if (auto s = set_one(iso_setting_names(), "ISO", std::to_string(e.iso),
                         [&](const auto& c) { return match_iso(c, e.iso); });
        !s)
      return s;
  }
  return {};
}

veneer::Expected<Still> Gphoto2Camera::capture() {
  std::lock_guard<std::mutex> lock(session_);
  if (unplugged_) close_locked();
  if (auto s = open_locked(); !s) return s.error();
  auto still = capture_locked();
  if (still || !network_ || open_) return still;
  // The network connection was lost during the shot (capture_locked closed
  // the session). The lamps are still as the caller set them, so reconnecting
  // and taking the shot again gives the same picture; a shot the camera took
  // but could not deliver stays on its card.
  if (auto s = reconnect_locked(still.message()); !s) return s.error();
  return capture_locked();
}

veneer::Expected<Still> Gphoto2Camera::capture_locked() {
  auto lost = [&](int code, const std::string& doing) -> veneer::Error {
    // An I/O failure while the device is gone: drop the session, report it,
    // and let the hotplug path (USB) or the next use (network) reopen it.
    bool gone = unplugged_ || code == gp::io || code == gp::io_usb_find || code == gp::timeout ||
                (network_ && lost_code(code));
    std::string msg = describe_error(code, doing);
    if (gone) {
      close_locked();
      if (unplugged_) {
        msg = doing + " failed: the camera was unplugged";
        set_connected(false);
      } else if (network_) {
        msg = doing + " failed: the connection to the camera at " + opt_.port.substr(6) + " was lost (" +
              api_->error_text(code) + ", gphoto2 error " + std::to_string(code) + ")";
        set_connected(false);
      }
    }
    return veneer::make_error("gphoto2 camera: " + msg);
  };
  CameraFilePath shot;
  int r = api_->capture(shot);
  if (r < gp::ok || unplugged_) return lost(r < gp::ok ? r : gp::io, "capture");
  std::vector<unsigned char> main_file;
  r = api_->download(shot, main_file);
  if (r < gp::ok || unplugged_) return lost(r < gp::ok ? r : gp::io, "downloading " + shot.name);
  std::vector<CameraFilePath> taken{shot};

  std::vector<unsigned char> jpeg;
  if (is_raw_name(shot.name)) {
    // RAW+JPEG bodies announce the second file as an event right after.
    auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(opt_.paired_jpeg_wait_ms);
    while (jpeg.empty() && std::chrono::steady_clock::now() < until) {
      CameraFilePath added;
      bool got = false;
      int left = int(std::chrono::duration_cast<std::chrono::milliseconds>(until - std::chrono::steady_clock::now()).count());
      r = api_->wait_file_added(std::max(left, 1), added, got);
      if (r < gp::ok || unplugged_) return lost(r < gp::ok ? r : gp::io, "waiting for the paired JPEG");
      if (!got) continue;
      taken.push_back(added);
      if (is_jpeg_name(added.name)) {
        r = api_->download(added, jpeg);
        if (r < gp::ok || unplugged_) return lost(r < gp::ok ? r : gp::io, "downloading " + added.name);
      }
    }
    if (jpeg.empty()) {
      jpeg = embedded_jpeg(main_file);
      if (jpeg.empty())
        return veneer::make_error("gphoto2 camera: " + shot.name + " is RAW with no embedded JPEG and no paired JPEG "
                                  "arrived; set the camera to RAW+JPEG or JPEG");
      VLOG_DEBUG("Camera", "using the JPEG embedded in {}", shot.name);
    }
  } else {
    jpeg = main_file;
  }
  if (!opt_.keep_on_card)
    for (const auto& f : taken) api_->remove(f);  // best effort: RAM targets free themselves

  if (live_size_.area() == 0) {
    std::vector<unsigned char> frame;
    if (api_->preview(frame) >= gp::ok) {
      cv::Mat m = cv::imdecode(frame, cv::IMREAD_COLOR);
      if (!m.empty()) live_size_ = m.size();
    }
  }
  auto linear = decode_jpeg_linear(jpeg, live_size_);
  if (!linear) return veneer::make_error("gphoto2 camera: " + shot.name + ": " + linear.message());
  Still still;
  still.linear = std::move(*linear);
  still.original_name = shot.name;
  still.original = std::move(main_file);
  return still;
}

veneer::Expected<std::vector<unsigned char>> Gphoto2Camera::preview() {
  std::lock_guard<std::mutex> lock(session_);
  if (unplugged_) close_locked();
  if (auto s = open_locked(); !s) return s.error();
  std::vector<unsigned char> jpeg;
  int r = api_->preview(jpeg);
  if (r < gp::ok && network_ && lost_code(r)) {
    if (auto s = reconnect_locked("live view: " + describe_error(r, "live view")); !s) return s.error();
    r = api_->preview(jpeg);
  }
  if (r < gp::ok) {
    std::string msg = describe_error(r, "live view");
    if (unplugged_) {
      close_locked();
      set_connected(false);
    }
    return veneer::make_error("gphoto2 camera: " + msg);
  }
  if (live_size_.area() == 0) {
    cv::Mat m = cv::imdecode(jpeg, cv::IMREAD_COLOR);
    if (!m.empty()) live_size_ = m.size();
  }
  return jpeg;
}

bool Gphoto2Camera::lost_code(int code) const {
  // What libgphoto2's PTP/IP driver returns when the peer is gone: I/O errors,
  // timeouts, and a bare error when a read hits the end of the stream.
  return code == gp::io || code == gp::timeout || code == gp::error;
}

int Gphoto2Camera::note(int code) {
  if (code < gp::ok && lost_code(code)) lost_seen_ = true;
  return code;
}

veneer::Status Gphoto2Camera::ensure_alive_locked(const char* doing) {
  if (!network_ || !open_) return {};
  int r = api_->probe();
  if (r >= gp::ok || !lost_code(r)) return {};
  return reconnect_locked(std::string(doing) + ": the connection to the camera at " + opt_.port.substr(6) +
                          " was lost (" + api_->error_text(r) + ")");
}

veneer::Status Gphoto2Camera::reconnect_locked(const std::string& why) {
  close_locked();
  set_connected(false);
  VLOG_WARN("Camera", "{}; reconnecting to {} in {} ms", why, opt_.port, opt_.reopen_delay_ms);
  std::this_thread::sleep_for(std::chrono::milliseconds(opt_.reopen_delay_ms));
  lost_seen_ = false;
  if (auto s = open_locked(); !s) return veneer::make_error(why + "; reconnecting failed: " + s.message());
  VLOG_INFO("Camera", "reconnected to {}", opt_.port);
  return {};
}

void Gphoto2Camera::usb_changed(bool arrived, const UsbDeviceId& d) {
  if (!arrived) {
    bool ours = bus_ < 0 || (d.bus == bus_ && d.address == address_);
    if (connected_ && ours) {
      unplugged_ = true;  // a capture in flight fails with a clear message
      set_connected(false);
    }
    return;
  }
  if (!connected_) {
    std::lock_guard<std::mutex> lock(reopen_mu_);
    reopen_wanted_ = true;
    reopen_cv_.notify_all();
  }
}

void Gphoto2Camera::reopen_loop() {
  std::unique_lock<std::mutex> lock(reopen_mu_);
  for (;;) {
    reopen_cv_.wait(lock, [&] { return stopping_ || reopen_wanted_; });
    if (stopping_) return;
    reopen_wanted_ = false;
    reopen_busy_ = true;
    // Give the camera time to enumerate and finish its own start-up.
    if (reopen_cv_.wait_for(lock, std::chrono::milliseconds(opt_.reopen_delay_ms), [&] { return stopping_; })) return;
    lock.unlock();
    {
      std::lock_guard<std::mutex> session(session_);
      close_locked();
      auto s = open_locked();
      if (!s) VLOG_WARN("Camera", "reopen after USB arrival: {}", s.message());
    }
    lock.lock();
    reopen_busy_ = false;
    reopen_cv_.notify_all();
  }
}

bool Gphoto2Camera::wait_reopen_idle(int timeout_ms) {
  std::unique_lock<std::mutex> lock(reopen_mu_);
  return reopen_cv_.wait_for(lock, std::chrono::milliseconds(timeout_ms),
                             [&] { return !reopen_wanted_ && !reopen_busy_; });
}

}  // namespace veneerd::hw
