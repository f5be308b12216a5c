// What every lamps back-end shares: comparing states, and proving a wanted
// state by reading it back from the bridge.
#include "veneerd/devices/lamps.hpp"

#include <algorithm>
#include <cmath>
#include <chrono>
#include <sstream>
#include <thread>

#include "veneer/util/enum_names.hpp"
#include "veneer/util/log.hpp"

namespace veneerd {

namespace {

// Correlated colour temperature of an xy chromaticity (McCamy), in mired.
int xy_to_mired(double x, double y) {
  double n = (x - 0.3320) / (0.1858 - y);
  double kelvin = 449.0 * n * n * n + 3525.0 * n * n + 6823.3 * n + 5520.33;
  return std::clamp(static_cast<int>(std::lround(1e6 / std::max(kelvin, 1000.0))), 153, 500);
}

}  // namespace

constexpr veneer::EnumName<ColourMode> kColourModeNames[] = {
    {ColourMode::xy, "xy"}, {ColourMode::ct, "ct"}, {ColourMode::hs, "hs"}};

const char* colour_mode_name(ColourMode mode) { return veneer::name_of(kColourModeNames, mode, "?"); }

LampState rig_white(int brightness) {
  LampState s;
  s.on = true;
  s.brightness = std::clamp(brightness, 1, 254);
  s.mode = ColourMode::xy;
  s.x = 0.3227;
  s.y = 0.329;
  s.ct = xy_to_mired(s.x, s.y);
  return s;
}

bool same_colour(const LampState& a, const LampState& b) {
  if (a.brightness != b.brightness) return false;
  // A lamp without colour settings shows whatever colour it has.
  if (!(a.has_xy || a.has_ct) || !(b.has_xy || b.has_ct)) return true;
  const bool xy_both = a.has_xy && b.has_xy;
  auto ct_of = [](const LampState& s) { return s.mode == ColourMode::ct || !s.has_xy ? s.ct : xy_to_mired(s.x, s.y); };
  // Bridges round what they report (and some convert xy through RGB), so
  // colours match within what an eye would not tell apart.
  if (!xy_both) return std::abs(ct_of(a) - ct_of(b)) <= 5;
  if (a.mode != b.mode) return false;
  switch (a.mode) {
    case ColourMode::xy: return std::abs(a.x - b.x) <= 0.01 && std::abs(a.y - b.y) <= 0.01;
    case ColourMode::ct: return std::abs(a.ct - b.ct) <= 5;
    case ColourMode::hs: return std::abs(a.hue - b.hue) <= 500 && std::abs(a.sat - b.sat) <= 5;
  }
  return false;
}

bool same_light(const LampState& a, const LampState& b) {
  if (a.on != b.on) return false;
  return !a.on || same_colour(a, b);
}

std::string describe(const LampState& s) {
  std::ostringstream o;
  if (!s.reachable) o << "unreachable, ";
  if (!s.on) {
    o << "off";
    return o.str();
  }
  o << "on, bri " << s.brightness;
  if (s.has_xy || s.has_ct) {
    o.precision(4);
    switch (s.mode) {
      case ColourMode::xy: o << ", xy " << s.x << " " << s.y; break;
      case ColourMode::ct: o << ", ct " << s.ct << " mired"; break;
      case ColourMode::hs: o << ", hue " << s.hue << " sat " << s.sat; break;
    }
  }
  return o.str();
}

nlohmann::json to_json(const LampState& s) {
  return nlohmann::json{{"on", s.on},         {"bri", s.brightness}, {"colormode", colour_mode_name(s.mode)},
                        {"xy", {s.x, s.y}},   {"ct", s.ct},          {"hue", s.hue},
                        {"sat", s.sat},       {"reachable", s.reachable},
                        {"has_xy", s.has_xy}, {"has_ct", s.has_ct}};
}

veneer::Expected<LampState> lamp_state_from_json(const nlohmann::json& j) {
  if (!j.is_object()) return veneer::make_error("a lamp state must be an object");
  LampState s;
  try {
    s.on = j.at("on").get<bool>();
    s.brightness = std::clamp(j.at("bri").get<int>(), 1, 254);
    std::string mode = j.at("colormode").get<std::string>();
    if (mode == "xy") s.mode = ColourMode::xy;
    else if (mode == "ct") s.mode = ColourMode::ct;
    else if (mode == "hs") s.mode = ColourMode::hs;
    else return veneer::make_error("unknown colormode '" + mode + "'");
    s.x = j.at("xy").at(0).get<double>();
    s.y = j.at("xy").at(1).get<double>();
    s.ct = std::clamp(j.at("ct").get<int>(), 153, 500);
    s.hue = std::clamp(j.at("hue").get<int>(), 0, 65535);
    s.sat = std::clamp(j.at("sat").get<int>(), 0, 254);
    s.reachable = j.value("reachable", true);
    s.has_xy = j.value("has_xy", true);
    s.has_ct = j.value("has_ct", true);
  } catch (const nlohmann::json::exception& e) {
    return veneer::make_error(std::string("a lamp state field is missing or of the wrong type (") + e.what() + ")");
  }
  return s;
}

std::vector<int> Lamps::differing(const std::vector<LampState>& reading, const std::vector<LampState>& want) const {
  std::vector<int> out;
  for (std::size_t i = 0; i < want.size(); ++i) {
    if (i >= reading.size() || !reading[i].reachable || !same_light(reading[i], want[i])) out.push_back(static_cast<int>(i));
  }
  return out;
}

veneer::Expected<std::vector<LampState>> Lamps::ensure(const std::vector<LampState>& want,
                                                       std::optional<std::vector<LampState>> now, int attempts) {
  if (static_cast<int>(want.size()) != count())
    return veneer::make_error(name() + " lamps: " + std::to_string(want.size()) + " states given for " +
                              std::to_string(count()) + " lamps");
  std::vector<int> still;
  std::vector<LampState> reading;
  for (int attempt = 0; attempt < std::max(1, attempts); ++attempt) {
    if (!now) {
      auto r = read();
      if (!r) return r.error();
      reading = std::move(*r);
    } else {
      reading = std::move(*now);
      now.reset();
    }
    for (std::size_t i = 0; i < reading.size() && i < want.size(); ++i) {
      if (!reading[i].reachable)
        return veneer::make_error(label(static_cast<int>(i)) +
                                  " is unreachable (no power, or out of the bridge's range): the shot would be "
                                  "taken without it");
    }
    still = differing(reading, want);
    if (still.empty()) return reading;
    if (attempt > 0) {
      for (int i : still)
        VLOG_WARN("Lamps", "{} shows {} after it was commanded to {}: another client switched it; commanding again",
                  label(i), describe(reading[i]), describe(want[i]));
    }
    if (auto s = command(reading, want); !s) return s.error();
    // Read back; a bridge may show the change a little after its ack, so a
    // difference only counts once it outlasts confirm_ms().
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(confirm_ms());
    for (;;) {
      auto r = read();
      if (!r) return r.error();
      if (differing(*r, want).empty()) return *r;
      if (std::chrono::steady_clock::now() >= deadline) {
        now = std::move(*r);
        break;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(40));
    }
  }
  // `now` holds the last reading, taken confirm_ms() after the last commands.
  std::optional<std::vector<LampState>> last = std::move(now);
  if (!last) {
    auto r = read();
    if (!r) return r.error();
    last = std::move(*r);
  }
  auto* r = &*last;
  still = differing(*r, want);
  if (still.empty()) return *r;
  std::string names;
  for (int i : still) {
    if (!names.empty()) names += "; ";
    names += label(i) + " shows " + describe((*r)[i]) + ", wanted " + describe(want[i]);
  }
  return veneer::make_error("the lamps do not keep the state the rig commands (" + names + ") after " +
                            std::to_string(std::max(1, attempts)) +
                            " attempts: another client (the Hue app, a scene, a sensor or a wall switch) keeps "
                            "changing them");
}

veneer::Status Lamps::set(const std::vector<bool>& on, int brightness) {
  if (static_cast<int>(on.size()) != count())
    return veneer::make_error(name() + " lamps: " + std::to_string(on.size()) + " values given for " +
                              std::to_string(count()) + " lamps");
  std::vector<LampState> want(on.size(), rig_white(brightness));
  for (std::size_t i = 0; i < on.size(); ++i) want[i].on = on[i];
  auto r = ensure(want);
  if (!r) return r.error();
  return {};
}

veneer::Status Lamps::restore(const std::vector<LampState>& states) {
  std::vector<LampState> want = states;
  for (auto& w : want) {
    w.brightness = std::clamp(w.brightness, 1, 254);
    w.reachable = true;
  }
  auto r = ensure(want);
  if (!r) return r.error();
  return {};
}

}  // namespace veneerd
