// Config validation for the hardware back-ends and `veneerd --check-hardware`.
#include "veneerd/hw/check.hpp"

#include <ostream>

#include "veneerd/hw/gphoto2.hpp"
#include "veneerd/hw/gpio.hpp"
#include "veneerd/hw/hue_setup.hpp"
#include "veneerd/hw/uvc.hpp"

namespace veneerd {

using nlohmann::json;

namespace {

const char* known_backends(const std::string& kind) {
  if (kind == "camera") return "simulated, gphoto2, uvc";
  if (kind == "trigger") return "simulated, gpio";
  if (kind == "led") return "simulated, gpio, none";
  if (kind == "lamps") return "hue";
  return "";
}

// The section as the back-end sees it: the shared "gpio" block fills in what
// the trigger / led sections do not say (as config.cpp does).
json effective_section(const json& doc, const std::string& kind) {
  json s = doc.contains(kind) && doc[kind].is_object() ? doc[kind] : json::object();
  if ((kind == "trigger" || kind == "led") && doc.contains("gpio") && doc["gpio"].is_object())
    for (const auto& [k, v] : doc["gpio"].items())
      if (!s.contains(k)) s[k] = v;
  return s;
}

std::string backend_of(const json& doc, const std::string& kind, const char* fallback) {
  if (!doc.contains(kind) || !doc[kind].is_object()) return fallback;
  const json& s = doc[kind];
  return s.contains("backend") && s["backend"].is_string() ? s["backend"].get<std::string>() : fallback;
}

}  // namespace

veneer::Status validate_device_section(const std::string& kind, const json& s) {
  if (!s.is_object()) return veneer::make_error(kind + ": expected an object");
  if (!s.contains("backend")) return veneer::make_error(kind + ".backend: missing (one of " + known_backends(kind) + ")");
  if (!s["backend"].is_string()) return veneer::make_error(kind + ".backend: expected a string");
  std::string b = s["backend"].get<std::string>();
  if (kind == "camera") {
    if (b == "simulated") return {};
    if (b == "gphoto2") {
      auto o = hw::parse_gphoto2_options(s, kind);
      return o ? veneer::Status() : veneer::Status(o.error());
    }
    if (b == "uvc") {
      auto o = hw::parse_uvc_options(s, kind);
      return o ? veneer::Status() : veneer::Status(o.error());
    }
  } else if (kind == "trigger") {
    if (b == "simulated") return {};
    if (b == "gpio") {
      auto l = hw::parse_gpio_line(s, kind, "button_line");
      if (!l) return l.error();
      auto t = hw::parse_gpio_timing(s, kind);
      return t ? veneer::Status() : veneer::Status(t.error());
    }
  } else if (kind == "led") {
    if (b == "simulated" || b == "none") return {};
    if (b == "gpio") {
      auto l = hw::parse_gpio_line(s, kind, "led_line");
      return l ? veneer::Status() : veneer::Status(l.error());
    }
  } else if (kind == "lamps") {
    if (b == "hue") return {};
  } else {
    return veneer::make_error("unknown device kind '" + kind + "'");
  }
  return veneer::make_error(kind + ".backend: unknown backend '" + b + "' (known: " + known_backends(kind) + ")");
}

veneer::Status validate_hardware_config(const json& doc) {
  if (!doc.is_object()) return veneer::make_error("config: expected a JSON object");
  for (const char* kind : {"camera", "trigger", "led"}) {
    if (!doc.contains(kind)) continue;
    if (auto s = validate_device_section(kind, effective_section(doc, kind)); !s) return s;
  }
  return {};
}

int check_hardware(std::ostream& out, const json& doc) {
  int missing = 0;
  auto ok = [&](const std::string& s) { out << "  ok       " << s << "\n"; };
  auto bad = [&](const std::string& s) {
    out << "  MISSING  " << s << "\n";
    ++missing;
  };
  auto info = [&](const std::string& s) { out << "           " << s << "\n"; };

  if (auto s = validate_hardware_config(doc); !s) {
    out << "config\n";
    bad(s.message());
  }

  // Camera.
  std::string cam = backend_of(doc, "camera", "simulated");
  out << "camera (backend " << cam << ")\n";
  if (cam == "gphoto2" || cam == "simulated") {
    auto api = hw::make_libgphoto2_api();
    std::vector<hw::DetectedCamera> found;
    int r = api->autodetect(found);
    if (r < hw::gp::ok) info("camera detection failed: " + api->error_text(r));
    for (const auto& c : found) info("detected " + c.model + " on " + c.port);
    if (cam == "gphoto2") {
      auto opt = hw::parse_gphoto2_options(effective_section(doc, "camera"), "camera");
      if (!found.empty() && opt) {
        hw::Gphoto2Options o = *opt;
        o.reopen_delay_ms = 0;
        hw::Gphoto2Camera camera(std::move(api), nullptr, o);
        auto d = camera.describe();
        if (d) {
          ok("camera " + d->model);
          auto list = [](const std::vector<std::string>& v) {
            std::string s;
            for (const auto& x : v) s += (s.empty() ? "" : " ") + x;
            return s.empty() ? std::string("(none offered)") : s;
          };
          info("shutter speeds: " + list(d->shutter_values));
          info("apertures:      " + list(d->aperture_values));
          info("ISO:            " + list(d->iso_values));
        } else {
          bad(d.message());
        }
      } else if (found.empty()) {
        bad("no camera found over USB: connect it, switch it on and set it to PTP");
      }
    } else if (found.empty()) {
      info("no USB camera connected (not needed: the camera is simulated)");
    }
  } else if (cam == "uvc") {
    auto opt = hw::parse_uvc_options(effective_section(doc, "camera"), "camera");
    if (opt) {
      hw::UvcCamera camera(*opt);
      if (auto s = camera.open(); s) ok("webcam " + opt->device + " opens");
      else bad(s.message());
    }
  }

  // Lamps.
  json lamps = doc.contains("lamps") && doc["lamps"].is_object() ? doc["lamps"] : json::object();
  std::string bridge = lamps.value("bridge", "");
  std::string key = lamps.value("key", "");
  out << "lamps (Hue bridge" << (bridge.empty() ? "" : " " + bridge) << ")\n";
  if (bridge.empty()) {
    bad("lamps.bridge: no bridge address in the config (find it with `veneerd hue discover`)");
  } else {
    auto b = hw::probe_bridge(bridge, 2000);
    if (!b) {
      bad(b.message());
    } else {
      ok("bridge " + b->name + (b->bridgeid.empty() ? "" : " (" + b->bridgeid + ")") +
         (b->apiversion.empty() ? "" : ", API " + b->apiversion));
      if (key.empty()) {
        bad("lamps.key: no application key (pair with `veneerd hue pair --address " + bridge + "`)");
      } else {
        auto l = hw::list_bridge_lamps(bridge, key);
        if (!l) {
          bad(l.message());
        } else {
          for (const auto& lamp : *l)
            info("lamp " + lamp.id + " \"" + lamp.name + "\"" + (lamp.reachable ? "" : " (unreachable)"));
          std::vector<std::string> wanted;
          if (lamps.contains("lamps") && lamps["lamps"].is_array())
            for (const auto& id : lamps["lamps"])
              if (id.is_string()) wanted.push_back(id.get<std::string>());
          for (size_t i = 0; i < wanted.size(); ++i) {
            const hw::BridgeLamp* hit = nullptr;
            for (const auto& lamp : *l)
              if (lamp.id == wanted[i]) hit = &lamp;
            std::string pos = "ring position " + std::to_string(i + 1) + ": lamp " + wanted[i];
            if (!hit) bad(pos + " is not on the bridge (the lamps above are; correct lamps.lamps, `veneerd hue flash` shows which is where)");
            else if (!hit->reachable) bad(pos + " is unreachable (switched off at the wall?)");
            else ok(pos + " \"" + hit->name + "\"");
          }
          if (wanted.empty()) info("lamps.lamps not set: list the ring order (see `veneerd hue flash`)");
        }
      }
    }
  }

  // GPIO.
  std::string trig = backend_of(doc, "trigger", "simulated");
  std::string led = backend_of(doc, "led", "none");
  out << "gpio (trigger " << trig << ", led " << led << ")\n";
  auto chips = hw::list_gpio_chips();
  for (const auto& c : chips) info(c.path + " \"" + c.label + "\", " + std::to_string(c.lines) + " lines");
  if (chips.empty()) info("no GPIO chips (/dev/gpiochip*) on this machine");
  auto check_line = [&](const std::string& kind, const char* alt) {
    json s = effective_section(doc, kind);
    auto line = hw::parse_gpio_line(s, kind, alt);
    if (!line) return;  // reported by the validation above
    std::string where = line->describe();
    bool found = false;
    for (const auto& c : chips) {
      bool chip_match = line->chip.empty() || line->chip == c.name || line->chip == c.path || line->chip == c.label;
      if (!chip_match) continue;
      if (line->offset >= 0) {
        if (unsigned(line->offset) < c.lines) found = true;
        else {
          bad(kind + ": line offset " + std::to_string(line->offset) + " out of range on " + c.name + " (" +
              std::to_string(c.lines) + " lines)");
          return;
        }
      } else {
        for (const auto& n : c.line_names) found = found || n == line->line;
      }
      if (found) {
        ok(kind + " line " + where + " on " + c.name);
        return;
      }
    }
    bad(kind + ": GPIO line " + where + " not found" + (chips.empty() ? " (no GPIO chips on this machine)" : ""));
  };
  if (trig == "gpio") check_line("trigger", "button_line");
  if (led == "gpio") check_line("led", "led_line");

  out << (missing ? std::to_string(missing) + " required item(s) missing\n" : std::string("all required hardware found\n"));
  return missing ? 1 : 0;
}

}  // namespace veneerd
