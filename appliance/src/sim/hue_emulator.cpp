// The Hue bridge emulator: plain POSIX sockets, one thread per connection
// (a bridge has a handful of clients), the HTTP parser from http_request.cpp,
// and the v1 REST semantics the lamps backend relies on.
#include "veneerd/sim/hue_emulator.hpp"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <atomic>
#include <cerrno>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <list>
#include <map>
#include <mutex>
#include <set>
#include <thread>

#include <nlohmann/json.hpp>

#include "veneer/util/log.hpp"
#include "veneerd/sim/fault_plan.hpp"

namespace veneerd {

using Clock = std::chrono::steady_clock;
using json = nlohmann::ordered_json;  // answers keep the order of the request body, as the bridge's do

namespace {

constexpr const char* kLog = "HueEmulator";

struct Pending {
  Clock::time_point apply_at;
  LampState state;
};

struct LampSlot {
  std::string id;
  std::string name;
  LampState applied;
  std::deque<Pending> pending;  // ordered by apply_at
  LampState target() const { return pending.empty() ? applied : pending.back().state; }
};

// The chromaticity a lamp shows in ct mode: the Planckian locus (Kim et al.'s
// cubic fit), as a bridge reports xy for every mode.
void xy_of_ct(int mired, double& x, double& y) {
  double t = 1e6 / std::clamp(mired, 153, 500);
  double t2 = t * t, t3 = t2 * t;
  x = t <= 4000 ? -0.2661239e9 / t3 - 0.2343589e6 / t2 + 0.8776956e3 / t + 0.179910
                : -3.0258469e9 / t3 + 2.1070379e6 / t2 + 0.2226347e3 / t + 0.240390;
  double x2 = x * x, x3 = x2 * x;
  y = t <= 2222 ? -1.1063814 * x3 - 1.34811020 * x2 + 2.18555832 * x - 0.20219683
      : t <= 4000 ? -0.9549476 * x3 - 1.37418593 * x2 + 2.09137015 * x - 0.16748867
                  : 3.0817580 * x3 - 5.87338670 * x2 + 3.75112997 * x - 0.37001483;
}

// The chromaticity of hue/sat mode: the HSV colour in linear sRGB primaries.
void xy_of_hs(int hue, int sat, double& x, double& y) {
  double h = std::clamp(hue, 0, 65535) / 65536.0 * 6.0, s = std::clamp(sat, 0, 254) / 254.0;
  int sector = static_cast<int>(h);
  double f = h - sector, p = 1 - s, q = 1 - s * f, t = 1 - s * (1 - f);
  double r = 1, g = 1, b = 1;
  switch (sector % 6) {
    case 0: r = 1, g = t, b = p; break;
    case 1: r = q, g = 1, b = p; break;
    case 2: r = p, g = 1, b = t; break;
    case 3: r = p, g = q, b = 1; break;
    case 4: r = t, g = p, b = 1; break;
    default: r = 1, g = p, b = q; break;
  }
  double X = 0.4124 * r + 0.3576 * g + 0.1805 * b, Y = 0.2126 * r + 0.7152 * g + 0.0722 * b,
         Z = 0.0193 * r + 0.1192 * g + 0.9505 * b;
  double sum = std::max(X + Y + Z, 1e-9);
  x = X / sum;
  y = Y / sum;
}

// A state given whole (another app, a test): xy follows its colour mode.
LampState with_reported_xy(LampState s) {
  if (s.mode == ColourMode::ct) xy_of_ct(s.ct, s.x, s.y);
  if (s.mode == ColourMode::hs) xy_of_hs(s.hue, s.sat, s.x, s.y);
  return s;
}

json state_json(const LampState& s) {
  return json{{"on", s.on},
              {"bri", s.brightness},
              {"hue", s.hue},
              {"sat", s.sat},
              {"effect", "none"},
              {"xy", {std::round(s.x * 1e4) / 1e4, std::round(s.y * 1e4) / 1e4}},
              {"ct", s.ct},
              {"alert", "none"},
              {"colormode", colour_mode_name(s.mode)},
              {"mode", "homeautomation"},
              {"reachable", s.reachable}};
}

json error_entry(int type, const std::string& address, const std::string& description) {
  return json{{"error", {{"type", type}, {"address", address}, {"description", description}}}};
}

HttpResponse json_response(const json& body, int status = 200) {
  HttpResponse r;
  r.status = status;
  r.body = body.dump();
  return r;
}

HttpResponse single_error(int type, const std::string& address, const std::string& description) {
  return json_response(json::array({error_entry(type, address, description)}));
}

// Nesting depth of a JSON text, strings skipped; bounds what the parser sees.
int nesting_depth(const std::string& s) {
  int depth = 0, max_depth = 0;
  bool in_string = false, escape = false;
  for (char c : s) {
    if (in_string) {
      if (escape) escape = false;
      else if (c == '\\') escape = true;
      else if (c == '"') in_string = false;
      continue;
    }
    if (c == '"') in_string = true;
    else if (c == '[' || c == '{') max_depth = std::max(max_depth, ++depth);
    else if (c == ']' || c == '}') --depth;
  }
  return max_depth;
}

std::vector<std::string> split_path(const std::string& target) {
  std::string path = target.substr(0, target.find('?'));
  std::vector<std::string> parts;
  std::size_t pos = 0;
  while (pos <= path.size()) {
    std::size_t next = path.find('/', pos);
    if (next == std::string::npos) next = path.size();
    if (next > pos) parts.push_back(path.substr(pos, next - pos));
    pos = next + 1;
  }
  return parts;
}

bool send_all(int fd, const std::string& data) {
  std::size_t sent = 0;
  while (sent < data.size()) {
    ssize_t n = ::send(fd, data.data() + sent, data.size() - sent, MSG_NOSIGNAL);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return false;
    sent += static_cast<std::size_t>(n);
  }
  return true;
}

}  // namespace

struct HueBridgeEmulator::Impl {
  HueEmulatorOptions options;

  // Bridge state.
  mutable std::mutex mutex;
  std::vector<LampSlot> lamps;
  std::set<std::string> users;
  Clock::time_point link_pressed_until{};
  std::deque<Clock::time_point> light_window, group_window;
  std::chrono::milliseconds latency{0};
  std::chrono::milliseconds apply_delay{50};
  bool enforce = true;
  int fail_count = 0, fail_status = 503;
  int hue_error_count = 0, hue_error_type = 901;
  int drop_count = 0;
  std::shared_ptr<FaultPlan> faults;  // drawn per request (fault_plan.hpp); null = none
  std::map<std::string, Clock::time_point> unreachable_until;  // lamps a lamp.unreachable fault took away
  struct Interference {
    int after = 0;  // light commands still to come before it
    std::string id;
    LampState state;
  };
  std::vector<Interference> interferences;
  HueEmulatorCounters counters;
  std::atomic<int> in_flight{0};
  uint64_t user_serial = 0;

  // Server.
  int listen_fd = -1;
  uint16_t port = 0;
  std::atomic<bool> stopping{false};
  std::thread acceptor;
  struct Connection {
    int fd = -1;
    std::thread thread;
    std::atomic<bool> finished{false};
  };
  std::mutex conn_mutex;
  std::list<Connection> connections;
  std::condition_variable stop_cv;  // wakes latency sleeps on stop
  std::mutex stop_mutex;

  explicit Impl(HueEmulatorOptions o) : options(std::move(o)) {
    latency = std::chrono::milliseconds(options.latency_ms);
    apply_delay = std::chrono::milliseconds(options.apply_delay_ms);
    enforce = options.enforce_limits;
    users.insert(options.key);
    for (int i = 1; i <= options.lamps; ++i) {
      LampSlot slot;
      slot.id = std::to_string(i);
      slot.name = "Ring " + slot.id;
      slot.applied.on = false;
      lamps.push_back(std::move(slot));
    }
  }

  // Caller holds `mutex`.
  void apply_due(Clock::time_point now) {
    for (auto it = unreachable_until.begin(); it != unreachable_until.end();) {
      if (it->second > now) {
        ++it;
        continue;
      }
      if (LampSlot* l = find_lamp(it->first)) l->applied.reachable = true;
      it = unreachable_until.erase(it);
    }
    for (auto& lamp : lamps) {
      while (!lamp.pending.empty() && lamp.pending.front().apply_at <= now) {
        bool reachable = lamp.applied.reachable;
        lamp.applied = lamp.pending.front().state;
        lamp.applied.reachable = reachable;
        lamp.pending.pop_front();
      }
    }
  }

  LampSlot* find_lamp(const std::string& id) {
    for (auto& lamp : lamps)
      if (lamp.id == id) return &lamp;
    return nullptr;
  }

  json light_json(const LampSlot& lamp) const {
    return json{{"state", state_json(lamp.applied)},
                {"type", "Extended color light"},
                {"name", lamp.name},
                {"modelid", "LCT015"},
                {"manufacturername", "Signify Netherlands B.V."},
                {"productname", "Hue color lamp"},
                {"uniqueid", "00:17:88:01:00:00:00:" + std::string(lamp.id.size() < 2 ? "0" : "") + lamp.id + "-0b"},
                {"swversion", "1.93.7"}};
  }

  json group_json(const std::string& id) const {
    json lights = json::array();
    bool all_on = !lamps.empty(), any_on = false;
    for (const auto& lamp : lamps) {
      lights.push_back(lamp.id);
      all_on = all_on && lamp.applied.on;
      any_on = any_on || lamp.applied.on;
    }
    LampState first = lamps.empty() ? LampState{} : lamps.front().applied;
    return json{{"name", id == "0" ? "Group 0" : "Ring"},
                {"lights", lights},
                {"type", id == "0" ? "LightGroup" : "Room"},
                {"state", {{"all_on", all_on}, {"any_on", any_on}}},
                {"action", state_json(first)}};
  }

  json config_json() const {
    json whitelist = json::object();
    for (const auto& u : users) whitelist[u] = {{"name", "veneer#rig"}};
    return json{{"name", "Veneer bridge emulator"},
                {"bridgeid", "001788FFFE0VE4EE"},
                {"modelid", "BSB002"},
                {"apiversion", "1.56.0"},
                {"swversion", "1956097030"},
                {"ipaddress", "127.0.0.1"},
                {"linkbutton", Clock::now() < link_pressed_until},
                {"whitelist", whitelist}};
  }

  // Applies one state body to `base` (the lamp's commanded state). Returns the
  // answer entries; `changed` says whether anything is to be applied.
  json apply_body(const json& body, const std::string& prefix, LampState& state, bool check_off) {
    json out = json::array();
    bool on_after = state.on;
    if (auto it = body.find("on"); it != body.end() && it->is_boolean()) on_after = it->get<bool>();
    for (auto it = body.begin(); it != body.end(); ++it) {
      const std::string& key = it.key();
      const json& v = it.value();
      std::string address = prefix + "/" + key;
      auto invalid = [&] {
        out.push_back(error_entry(7, address, "invalid value, " + v.dump() + ", for parameter, " + key));
      };
      bool colour_param = key == "bri" || key == "xy" || key == "hue" || key == "sat" || key == "ct" ||
                          key == "bri_inc" || key == "effect";
      if (colour_param && check_off && !on_after) {
        out.push_back(error_entry(201, address, "parameter, " + key + ", is not modifiable. Device is set to off."));
        continue;
      }
      if (key == "on") {
        if (!v.is_boolean()) { invalid(); continue; }
        state.on = v.get<bool>();
        out.push_back(json{{"success", {{address, state.on}}}});
      } else if (key == "bri") {
        if (!v.is_number_integer() || v.get<int64_t>() < 1 || v.get<int64_t>() > 254) { invalid(); continue; }
        state.brightness = static_cast<int>(v.get<int64_t>());
        out.push_back(json{{"success", {{address, state.brightness}}}});
      } else if (key == "xy") {
        if (!v.is_array() || v.size() != 2 || !v[0].is_number() || !v[1].is_number()) { invalid(); continue; }
        double x = v[0].get<double>(), y = v[1].get<double>();
        if (!(x >= 0 && x <= 1 && y >= 0 && y <= 1)) { invalid(); continue; }
        state.x = x;
        state.y = y;
        state.mode = ColourMode::xy;
        out.push_back(json{{"success", {{address, json::array({x, y})}}}});
      } else if (key == "transitiontime") {
        if (!v.is_number_integer() || v.get<int64_t>() < 0 || v.get<int64_t>() > 65535) { invalid(); continue; }
        out.push_back(json{{"success", {{address, v}}}});
      } else if (key == "ct") {
        if (!v.is_number_integer() || v.get<int64_t>() < 153 || v.get<int64_t>() > 500) { invalid(); continue; }
        state.ct = static_cast<int>(v.get<int64_t>());
        state.mode = ColourMode::ct;
        xy_of_ct(state.ct, state.x, state.y);
        out.push_back(json{{"success", {{address, state.ct}}}});
      } else if (key == "hue" || key == "sat") {
        const int64_t hi = key == "hue" ? 65535 : 254;
        if (!v.is_number_integer() || v.get<int64_t>() < 0 || v.get<int64_t>() > hi) { invalid(); continue; }
        (key == "hue" ? state.hue : state.sat) = static_cast<int>(v.get<int64_t>());
        state.mode = ColourMode::hs;
        xy_of_hs(state.hue, state.sat, state.x, state.y);
        out.push_back(json{{"success", {{address, v}}}});
      } else if (key == "bri_inc") {
        if (!v.is_number_integer()) { invalid(); continue; }
        state.brightness = static_cast<int>(std::clamp<int64_t>(state.brightness + v.get<int64_t>(), 1, 254));
        out.push_back(json{{"success", {{address, v}}}});
      } else if (key == "alert" || key == "effect") {
        if (!v.is_string()) { invalid(); continue; }
        out.push_back(json{{"success", {{address, v}}}});
      } else {
        out.push_back(error_entry(6, address, "parameter, " + key + ", not available"));
      }
    }
    return out;
  }

  json injected_errors(const json& body, const std::string& prefix) {
    json out = json::array();
    for (auto it = body.begin(); it != body.end(); ++it)
      out.push_back(error_entry(hue_error_type, prefix + "/" + it.key(),
                                hue_error_type == 901 ? "Internal error, 404"
                                                      : "error " + std::to_string(hue_error_type) + " (injected)"));
    if (out.empty()) out.push_back(error_entry(hue_error_type, prefix, "injected error"));
    return out;
  }

  // Serves a request whose rate and in-flight checks have passed. Caller holds `mutex`.
  HttpResponse route(const HttpRequest& req, bool& counted_light, bool& counted_group) {
    auto now = Clock::now();
    apply_due(now);
    std::vector<std::string> parts = split_path(req.target);
    if (parts.empty() || parts[0] != "api") {
      HttpResponse r;
      r.status = 404;
      r.content_type = "text/html";
      r.body = "<html><body>Not found</body></html>";
      return r;
    }
    const std::string& m = req.method;
    json body;
    bool needs_body = m == "PUT" || m == "POST";
    if (needs_body) {
      if (nesting_depth(req.body) > 16) return single_error(2, "/", "body contains invalid json");
      body = json::parse(req.body, nullptr, false);
      if (body.is_discarded() || !body.is_object()) return single_error(2, "/", "body contains invalid json");
    }
    if (parts.size() == 1) {
      if (m != "POST") return single_error(4, "/", "method, " + m + ", not available for resource, /");
      if (!body.contains("devicetype") || !body["devicetype"].is_string())
        return single_error(5, "/", "invalid/missing parameters in body");
      if (now >= link_pressed_until) return single_error(101, "", "link button not pressed");
      std::string user = "veneer-user-" + std::to_string(++user_serial);
      users.insert(user);
      return json_response(json::array({json{{"success", {{"username", user}}}}}));
    }
    const std::string& user = parts[1];
    std::string rest;
    for (std::size_t i = 2; i < parts.size(); ++i) rest += "/" + parts[i];
    if (!users.count(user)) return single_error(1, rest.empty() ? "/" : rest, "unauthorized user");
    auto not_available = [&] { return single_error(3, rest, "resource, " + rest + ", not available"); };
    auto bad_method = [&] {
      return single_error(4, rest, "method, " + m + ", not available for resource, " + rest);
    };

    if (parts.size() == 2) {
      if (m != "GET") return bad_method();
      json lights = json::object();
      for (const auto& lamp : lamps) lights[lamp.id] = light_json(lamp);
      return json_response(json{{"lights", lights}, {"groups", {{"1", group_json("1")}}}, {"config", config_json()}});
    }
    const std::string& kind = parts[2];
    if (kind == "config" && parts.size() == 3) {
      if (m != "GET") return bad_method();
      return json_response(config_json());
    }
    if (kind == "lights") {
      if (parts.size() == 3) {
        if (m != "GET") return bad_method();
        json lights = json::object();
        for (const auto& lamp : lamps) lights[lamp.id] = light_json(lamp);
        return json_response(lights);
      }
      LampSlot* lamp = find_lamp(parts[3]);
      if (!lamp) return not_available();
      if (parts.size() == 4) {
        if (m != "GET") return bad_method();
        return json_response(light_json(*lamp));
      }
      if (parts.size() == 5 && parts[4] == "state") {
        if (m != "PUT") return bad_method();
        std::string prefix = "/lights/" + lamp->id + "/state";
        if (hue_error_count > 0) {
          --hue_error_count;
          ++counters.injected;
          return json_response(injected_errors(body, prefix));
        }
        counted_light = true;
        LampState target = lamp->target();
        json answer = apply_body(body, prefix, target, true);
        lamp->pending.push_back({now + apply_delay, target});
        // Another client's change, scheduled to land right after this command.
        for (auto it = interferences.begin(); it != interferences.end();) {
          if (--it->after > 0) {
            ++it;
            continue;
          }
          if (LampSlot* other = find_lamp(it->id)) {
            LampState st = it->state;
            st.reachable = other->target().reachable;
            other->pending.push_back({now + apply_delay, st});
          }
          it = interferences.erase(it);
        }
        return json_response(answer);
      }
      return not_available();
    }
    if (kind == "groups") {
      if (parts.size() == 3) {
        if (m != "GET") return bad_method();
        return json_response(json{{"1", group_json("1")}});
      }
      const std::string& gid = parts[3];
      if (gid != "0" && gid != "1") return not_available();
      if (parts.size() == 4) {
        if (m != "GET") return bad_method();
        return json_response(group_json(gid));
      }
      if (parts.size() == 5 && parts[4] == "action") {
        if (m != "PUT") return bad_method();
        std::string prefix = "/groups/" + gid + "/action";
        if (hue_error_count > 0) {
          --hue_error_count;
          ++counters.injected;
          return json_response(injected_errors(body, prefix));
        }
        counted_group = true;
        json answer = json::array();
        for (auto& lamp : lamps) {
          LampState target = lamp.target();
          answer = apply_body(body, prefix, target, false);
          lamp.pending.push_back({now + apply_delay, target});
        }
        return json_response(answer);
      }
      return not_available();
    }
    return not_available();
  }

  bool sleep_interruptible(std::chrono::milliseconds d) {
    if (d.count() <= 0) return !stopping;
    std::unique_lock lock(stop_mutex);
    return !stop_cv.wait_for(lock, d, [&] { return stopping.load(); });
  }

  HttpResponse handle(const HttpRequest& req) {
    auto arrival = Clock::now();
    int now_in_flight = ++in_flight;
    struct Leave {
      std::atomic<int>& n;
      ~Leave() { --n; }
    } leave{in_flight};

    std::vector<std::string> parts = split_path(req.target);
    bool is_light_cmd = req.method == "PUT" && parts.size() == 5 && parts[2] == "lights" && parts[4] == "state";
    bool is_group_cmd = req.method == "PUT" && parts.size() == 5 && parts[2] == "groups" && parts[4] == "action";
    std::chrono::milliseconds wait{0};
    {
      std::lock_guard lock(mutex);
      ++counters.requests;
      counters.max_in_flight_seen = std::max<uint64_t>(counters.max_in_flight_seen, now_in_flight);
      int injected_status = 0;
      if (fail_count > 0) {
        --fail_count;
        injected_status = fail_status;
      } else if (faults && faults->draw(Fault::bridge_503)) {
        injected_status = 503;
      } else if (faults && faults->draw(Fault::bridge_429)) {
        injected_status = 429;
      }
      if (injected_status != 0) {
        ++counters.injected;
        HttpResponse r;
        r.status = injected_status;
        r.content_type = "text/plain";
        r.body = std::string(http_reason(injected_status)) + " (injected)";
        return r;
      }
      if (faults && !lamps.empty() && faults->draw(Fault::lamp_unreachable)) {
        // A lamp out of reach (switched off at the wall, out of Zigbee range) for a while.
        LampSlot& l = lamps[faults->pick(Fault::lamp_unreachable, static_cast<uint32_t>(lamps.size()))];
        l.applied.reachable = false;
        unreachable_until[l.id] = arrival + std::chrono::milliseconds(faults->sizes().lamp_unreachable_ms);
        ++counters.injected;
      }
      if (enforce && now_in_flight > options.max_in_flight) {
        ++counters.refused_busy;
        HttpResponse r;
        r.status = 503;
        r.content_type = "text/plain";
        r.body = "Service Unavailable: too many requests in flight";
        return r;
      }
      if (enforce && (is_light_cmd || is_group_cmd)) {
        auto& window = is_light_cmd ? light_window : group_window;
        int limit = is_light_cmd ? options.light_limit : options.group_limit;
        while (!window.empty() && window.front() <= arrival - std::chrono::seconds(1)) window.pop_front();
        if (static_cast<int>(window.size()) >= limit) {
          ++counters.refused_rate;
          return json_response(json::array({error_entry(901, req.target, "Too many requests")}), 429);
        }
        window.push_back(arrival);  // reserved now; released below if the command is not accepted
      }
      wait = latency;
      if (faults && faults->draw(Fault::bridge_timeout)) {
        wait += std::chrono::milliseconds(faults->sizes().bridge_timeout_ms);
        ++counters.injected;
      }
    }
    sleep_interruptible(wait);
    std::lock_guard lock(mutex);
    bool counted_light = false, counted_group = false;
    HttpResponse r = route(req, counted_light, counted_group);
    if (counted_light) ++counters.light_commands;
    if (counted_group) ++counters.group_commands;
    if (enforce && ((is_light_cmd && !counted_light) || (is_group_cmd && !counted_group))) {
      auto& window = is_light_cmd ? light_window : group_window;
      auto it = std::find(window.begin(), window.end(), arrival);
      if (it != window.end()) window.erase(it);
    }
    if (r.status / 100 == 2) ++counters.served;
    return r;
  }

  // --- sockets ------------------------------------------------------------

  void serve_connection(Connection* conn) {
    int fd = conn->fd;
    HttpRequestParser parser;
    char buf[8192];
    auto last_activity = Clock::now();
    bool open = true;
    while (open && !stopping) {
      pollfd p{fd, POLLIN, 0};
      int pr = ::poll(&p, 1, 100);
      if (pr < 0 && errno != EINTR) break;
      if (pr <= 0) {
        auto idle = Clock::now() - last_activity;
        if (parser.buffered() > 0 && idle > std::chrono::seconds(10)) {
          HttpResponse r;
          r.status = 408;
          r.close = true;
          send_all(fd, r.serialize(false));
          break;
        }
        if (idle > std::chrono::seconds(60)) break;
        continue;
      }
      ssize_t n = ::recv(fd, buf, sizeof buf, 0);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) break;
      last_activity = Clock::now();
      auto state = parser.feed(std::string_view(buf, static_cast<std::size_t>(n)));
      while (open && state == HttpRequestParser::State::complete) {
        HttpRequest req = parser.take();
        bool drop = false;
        {
          std::lock_guard lock(mutex);
          if (drop_count > 0 || (faults && faults->draw(Fault::bridge_drop))) {
            if (drop_count > 0) --drop_count;
            ++counters.requests;
            ++counters.dropped;
            drop = true;
          }
        }
        if (drop) {
          open = false;
          break;
        }
        HttpResponse r = handle(req);
        bool keep = req.keep_alive() && !r.close;
        if (!send_all(fd, r.serialize(keep)) || !keep) open = false;
        state = parser.state();
      }
      if (open && state == HttpRequestParser::State::error) {
        {
          std::lock_guard lock(mutex);
          ++counters.bad_requests;
        }
        HttpResponse r;
        r.status = parser.error_status();
        r.content_type = "text/plain";
        r.body = parser.error_reason();
        r.close = true;
        send_all(fd, r.serialize(false));
        open = false;
      }
    }
    ::shutdown(fd, SHUT_RDWR);
    conn->finished = true;
  }

  void reap(bool all) {
    std::list<Connection> done;
    {
      std::lock_guard lock(conn_mutex);
      for (auto it = connections.begin(); it != connections.end();) {
        if (all || it->finished) {
          auto next = std::next(it);
          done.splice(done.end(), connections, it);
          it = next;
        } else {
          ++it;
        }
      }
    }
    for (auto& c : done) {
      if (c.thread.joinable()) c.thread.join();
      ::close(c.fd);
    }
  }

  void accept_loop() {
    while (!stopping) {
      pollfd p{listen_fd, POLLIN, 0};
      int pr = ::poll(&p, 1, 100);
      reap(false);
      if (pr <= 0) continue;
      int fd = ::accept(listen_fd, nullptr, nullptr);
      if (fd < 0) continue;
      int one = 1;
      ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
      std::lock_guard lock(conn_mutex);
      if (static_cast<int>(connections.size()) >= options.max_connections) {
        ::close(fd);
        std::lock_guard state_lock(mutex);
        ++counters.dropped;
        continue;
      }
      connections.emplace_back();
      Connection* c = &connections.back();
      c->fd = fd;
      c->thread = std::thread([this, c] { serve_connection(c); });
    }
  }
};

HueBridgeEmulator::HueBridgeEmulator(HueEmulatorOptions options)
    : impl_(std::make_unique<Impl>(std::move(options))) {}

HueBridgeEmulator::~HueBridgeEmulator() { stop(); }

veneer::Status HueBridgeEmulator::start(const std::string& host, uint16_t port) {
  if (running()) return veneer::make_error("Hue bridge emulator already listening on " + address());
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(port);
  if (::inet_pton(AF_INET, host.c_str(), &addr.sin_addr) != 1)
    return veneer::make_error("Hue bridge emulator: '" + host + "' is not an IPv4 address");
  int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return veneer::make_error(std::string("Hue bridge emulator: socket(): ") + std::strerror(errno));
  int one = 1;
  ::setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
  if (::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0 || ::listen(fd, 64) != 0) {
    std::string why = std::strerror(errno);
    ::close(fd);
    return veneer::make_error("Hue bridge emulator: cannot listen on " + host + ":" + std::to_string(port) + ": " + why);
  }
  socklen_t len = sizeof addr;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len);
  impl_->listen_fd = fd;
  impl_->port = ntohs(addr.sin_port);
  impl_->stopping = false;
  impl_->acceptor = std::thread([this] { impl_->accept_loop(); });
  VLOG_INFO(kLog, "Hue bridge emulator listening on {} ({} lamps, key '{}')", address(), impl_->options.lamps,
            impl_->options.key);
  return {};
}

void HueBridgeEmulator::stop() {
  if (impl_->listen_fd < 0) return;
  {
    std::lock_guard lock(impl_->stop_mutex);
    impl_->stopping = true;
  }
  impl_->stop_cv.notify_all();
  if (impl_->acceptor.joinable()) impl_->acceptor.join();
  {
    std::lock_guard lock(impl_->conn_mutex);
    for (auto& c : impl_->connections) ::shutdown(c.fd, SHUT_RDWR);
  }
  impl_->reap(true);
  ::close(impl_->listen_fd);
  impl_->listen_fd = -1;
}

bool HueBridgeEmulator::running() const { return impl_->listen_fd >= 0; }
uint16_t HueBridgeEmulator::port() const { return impl_->port; }
std::string HueBridgeEmulator::address() const { return "127.0.0.1:" + std::to_string(impl_->port); }
const HueEmulatorOptions& HueBridgeEmulator::options() const { return impl_->options; }

std::vector<EmulatedLamp> HueBridgeEmulator::lamps() const {
  std::lock_guard lock(impl_->mutex);
  impl_->apply_due(Clock::now());
  std::vector<EmulatedLamp> out;
  for (const auto& l : impl_->lamps) out.push_back({l.id, l.name, l.applied});
  return out;
}

std::optional<LampState> HueBridgeEmulator::lamp(const std::string& id) const {
  std::lock_guard lock(impl_->mutex);
  impl_->apply_due(Clock::now());
  for (const auto& l : impl_->lamps)
    if (l.id == id) return l.applied;
  return std::nullopt;
}

std::vector<bool> HueBridgeEmulator::on_pattern() const {
  std::vector<bool> out;
  for (const auto& l : lamps()) out.push_back(l.state.on);
  return out;
}

void HueBridgeEmulator::set_lamp(const std::string& id, const LampState& state) {
  std::lock_guard lock(impl_->mutex);
  if (LampSlot* l = impl_->find_lamp(id)) {
    l->pending.clear();
    l->applied = with_reported_xy(state);
  }
}

void HueBridgeEmulator::interfere_after(int light_commands, const std::string& id, const LampState& state) {
  std::lock_guard lock(impl_->mutex);
  impl_->interferences.push_back({std::max(1, light_commands), id, with_reported_xy(state)});
}

void HueBridgeEmulator::set_reachable(const std::string& id, bool reachable) {
  std::lock_guard lock(impl_->mutex);
  if (LampSlot* l = impl_->find_lamp(id)) l->applied.reachable = reachable;
}

void HueBridgeEmulator::press_link_button() {
  std::lock_guard lock(impl_->mutex);
  impl_->link_pressed_until = Clock::now() + std::chrono::seconds(30);
}

void HueBridgeEmulator::set_latency(std::chrono::milliseconds latency) {
  std::lock_guard lock(impl_->mutex);
  impl_->latency = latency;
}

void HueBridgeEmulator::set_apply_delay(std::chrono::milliseconds delay) {
  std::lock_guard lock(impl_->mutex);
  impl_->apply_delay = delay;
}

void HueBridgeEmulator::set_enforce_limits(bool enforce) {
  std::lock_guard lock(impl_->mutex);
  impl_->enforce = enforce;
}

void HueBridgeEmulator::fail_next(int count, int status) {
  std::lock_guard lock(impl_->mutex);
  impl_->fail_count = count;
  impl_->fail_status = status;
}

void HueBridgeEmulator::hue_error_next(int count, int type) {
  std::lock_guard lock(impl_->mutex);
  impl_->hue_error_count = count;
  impl_->hue_error_type = type;
}

void HueBridgeEmulator::set_fault_plan(std::shared_ptr<FaultPlan> plan) {
  std::lock_guard lock(impl_->mutex);
  impl_->faults = std::move(plan);
}

void HueBridgeEmulator::drop_next(int count) {
  std::lock_guard lock(impl_->mutex);
  impl_->drop_count = count;
}

void HueBridgeEmulator::drop_connections() {
  std::lock_guard lock(impl_->conn_mutex);
  for (auto& c : impl_->connections) ::shutdown(c.fd, SHUT_RDWR);
}

HueEmulatorCounters HueBridgeEmulator::counters() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->counters;
}

void HueBridgeEmulator::reset_counters() {
  std::lock_guard lock(impl_->mutex);
  impl_->counters = {};
}

HttpResponse HueBridgeEmulator::handle(const HttpRequest& request) { return impl_->handle(request); }

}  // namespace veneerd
