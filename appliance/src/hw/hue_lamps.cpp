// Lamps backend "hue" (see hue_lamps.hpp for the bridge facts it is built around).
#include "veneerd/hw/hue_lamps.hpp"

#include <algorithm>
#include <cmath>
#include <deque>
#include <mutex>
#include <optional>
#include <thread>

#include "http_client.hpp"
#include "veneer/util/log.hpp"

namespace veneerd::hw {

using Clock = std::chrono::steady_clock;
using json = nlohmann::json;
using detail::HttpCall;
using detail::HttpClient;
using detail::HttpResult;

namespace {

constexpr const char* kLog = "Lamps";

// At most `count` events in any `window` (the bridge counts per second).
class SlidingWindow {
 public:
  SlidingWindow(double rate_per_s) {
    count_ = std::max(1, static_cast<int>(std::floor(rate_per_s + 1e-9)));
    // The bridge stamps arrivals, not our sends: a quarter second of slack
    // absorbs network and scheduling jitter that would bunch them up.
    window_ = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(count_ / rate_per_s + 0.25));
  }
  // When the next event may happen (now or later).
  Clock::time_point next_allowed(Clock::time_point now) {
    while (!times_.empty() && times_.front() + window_ <= now) times_.pop_front();
    if (static_cast<int>(times_.size()) < count_) return now;
    return times_.front() + window_;
  }
  void record(Clock::time_point t) { times_.push_back(t); }

 private:
  int count_ = 1;
  Clock::duration window_{};
  std::deque<Clock::time_point> times_;
};

std::string ms(Clock::duration d) {
  return std::to_string(std::chrono::duration_cast<std::chrono::milliseconds>(d).count()) + " ms";
}

}  // namespace

// --- options ---------------------------------------------------------------

veneer::Status HueLampsOptions::check() const {
  if (bridge.empty()) return veneer::make_error("hue lamps: 'bridge' (host:port) is empty");
  if (bridge.find_first_of(" /?#@") != std::string::npos)
    return veneer::make_error("hue lamps: 'bridge' must be host or host:port, got '" + bridge + "'");
  if (key.empty()) return veneer::make_error("hue lamps: 'key' (the bridge user) is empty");
  if (key.find_first_of(" /?#") != std::string::npos) return veneer::make_error("hue lamps: 'key' has invalid characters");
  if (lamps.empty()) return veneer::make_error("hue lamps: 'lamps' lists no lamp ids");
  for (std::size_t i = 0; i < lamps.size(); ++i) {
    if (lamps[i].empty() || lamps[i].find_first_of(" /?#") != std::string::npos)
      return veneer::make_error("hue lamps: lamps[" + std::to_string(i) + "] = '" + lamps[i] + "' is not a Hue light id");
    for (std::size_t j = 0; j < i; ++j)
      if (lamps[j] == lamps[i]) return veneer::make_error("hue lamps: lamp id '" + lamps[i] + "' is listed twice");
  }
  if (!group.empty() && group.find_first_of(" /?#") != std::string::npos)
    return veneer::make_error("hue lamps: 'group' = '" + group + "' is not a group id");
  if (settle_ms < 0 || settle_ms > 10000) return veneer::make_error("hue lamps: 'settle_ms' must be 0..10000, got " + std::to_string(settle_ms));
  if (confirm_ms < 0 || confirm_ms > 60000) return veneer::make_error("hue lamps: 'confirm_ms' must be 0..60000, got " + std::to_string(confirm_ms));
  if (timeout_ms < 50 || timeout_ms > 60000) return veneer::make_error("hue lamps: 'timeout_ms' must be 50..60000, got " + std::to_string(timeout_ms));
  if (!(light_rate > 0 && light_rate <= 50)) return veneer::make_error("hue lamps: 'light_rate' must be in (0, 50]");
  if (!(group_rate > 0 && group_rate <= 10)) return veneer::make_error("hue lamps: 'group_rate' must be in (0, 10]");
  if (max_in_flight < 1 || max_in_flight > 16) return veneer::make_error("hue lamps: 'max_in_flight' must be 1..16");
  return {};
}

veneer::Expected<HueLampsOptions> HueLampsOptions::from_json(const json& s) {
  if (!s.is_object()) return veneer::make_error("hue lamps: config section must be a JSON object");
  HueLampsOptions o;
  auto get_string = [&](const char* key, std::string& out) -> veneer::Status {
    if (!s.contains(key)) return {};
    if (s[key].is_string()) out = s[key].get<std::string>();
    else if (s[key].is_number_integer()) out = std::to_string(s[key].get<int64_t>());
    else return veneer::make_error(std::string("hue lamps: '") + key + "' must be a string");
    return {};
  };
  auto get_int = [&](const char* key, int& out) -> veneer::Status {
    if (!s.contains(key)) return {};
    if (!s[key].is_number_integer()) return veneer::make_error(std::string("hue lamps: '") + key + "' must be an integer");
    out = static_cast<int>(std::clamp<int64_t>(s[key].get<int64_t>(), -1, 1 << 30));
    return {};
  };
  auto get_double = [&](const char* key, double& out) -> veneer::Status {
    if (!s.contains(key)) return {};
    if (!s[key].is_number()) return veneer::make_error(std::string("hue lamps: '") + key + "' must be a number");
    out = s[key].get<double>();
    return {};
  };
  for (auto st : {get_string("bridge", o.bridge), get_string("key", o.key), get_string("group", o.group),
                  get_int("settle_ms", o.settle_ms), get_int("timeout_ms", o.timeout_ms),
                  get_int("confirm_ms", o.confirm_ms),
                  get_double("light_rate", o.light_rate), get_double("group_rate", o.group_rate),
                  get_int("max_in_flight", o.max_in_flight)})
    if (!st) return st.error();
  if (s.contains("lamps")) {
    if (!s["lamps"].is_array()) return veneer::make_error("hue lamps: 'lamps' must be an array of light ids");
    for (const auto& v : s["lamps"]) {
      if (v.is_string()) o.lamps.push_back(v.get<std::string>());
      else if (v.is_number_integer()) o.lamps.push_back(std::to_string(v.get<int64_t>()));
      else return veneer::make_error("hue lamps: 'lamps' entries must be light ids, got " + v.dump());
    }
  }
  if (auto st = o.check(); !st) return st.error();
  return o;
}

json HueLampsOptions::to_json() const {
  json j{{"bridge", bridge},         {"key", key},
         {"lamps", lamps},           {"settle_ms", settle_ms},
         {"timeout_ms", timeout_ms}, {"confirm_ms", confirm_ms}, {"light_rate", light_rate},
         {"group_rate", group_rate}, {"max_in_flight", max_in_flight}};
  if (!group.empty()) j["group"] = group;
  return j;
}

veneer::Expected<std::vector<HueResult>> parse_hue_results(const std::string& body) {
  json j = json::parse(body, nullptr, false);
  if (j.is_discarded()) return veneer::make_error("bridge answer is not JSON: '" + body.substr(0, 120) + "'");
  if (!j.is_array()) return veneer::make_error("bridge answer is not a result array: '" + body.substr(0, 120) + "'");
  std::vector<HueResult> out;
  for (const auto& entry : j) {
    HueResult r;
    if (!entry.is_object()) return veneer::make_error("bridge result entry is not an object: " + entry.dump());
    if (auto it = entry.find("success"); it != entry.end()) {
      r.success = true;
      if (it->is_object() && !it->empty()) r.address = it->begin().key();
    } else if (auto e = entry.find("error"); e != entry.end() && e->is_object()) {
      if (auto t = e->find("type"); t != e->end() && t->is_number_integer()) r.error_type = t->get<int>();
      if (auto a = e->find("address"); a != e->end() && a->is_string()) r.address = a->get<std::string>();
      if (auto d = e->find("description"); d != e->end() && d->is_string()) r.description = d->get<std::string>();
    } else {
      return veneer::make_error("bridge result entry is neither success nor error: " + entry.dump());
    }
    out.push_back(std::move(r));
  }
  return out;
}

// --- the backend -----------------------------------------------------------

struct HueLamps::Impl {
  HueLampsOptions options;
  std::string base;  // http://host:port/api/<key>
  std::mutex mutex;
  HttpClient client;
  SlidingWindow light_window;
  SlidingWindow group_window;
  HueLampsStats stats;

  explicit Impl(const HueLampsOptions& o)
      : options(o), light_window(o.light_rate), group_window(o.group_rate) {
    base = "http://" + o.bridge + "/api/" + o.key;
  }

  std::string lamp_label(int i) const {
    return "lamp " + std::to_string(i + 1) + " (Hue id " + options.lamps[i] + ")";
  }

  std::string key_refused() const {
    return "the Hue bridge " + options.bridge + " refused the key '" + options.key +
           "' (error 1, unauthorized user): pair the rig again with `veneerd hue pair --address " + options.bridge +
           "` (press the bridge's link button) and put the key it prints into the config's lamps.key";
  }

  struct Command {
    std::string path;   // "/lights/3/state"
    json body;
    bool group = false;
    int lamp = -1;      // ring index, -1 for group
    int attempts = 0;
    Clock::time_point deadline{};
    Clock::time_point not_before{};
    int ticket = 0;
    bool done = false;
    bool paced = false;  // counted in stats.paced_waits
    std::string last_error;  // why the last attempt did not count
  };

  std::string who(const Command& c) const {
    return c.lamp >= 0 ? lamp_label(c.lamp) : "group '" + options.group + "'";
  }

  veneer::Status explain_results(const Command& c, const std::vector<HueResult>& results) {
    for (const auto& r : results) {
      if (r.success) continue;
      if (r.error_type == 1) return veneer::make_error(key_refused());
      if (r.error_type == 3)
        return veneer::make_error(who(c) + ": the bridge " + options.bridge + " has no such resource (error 3, " +
                                  r.description + ")");
      return veneer::make_error(who(c) + ": bridge error " + std::to_string(r.error_type) + " at " + r.address + ": " +
                                r.description);
    }
    if (results.empty()) return veneer::make_error(who(c) + ": the bridge answered an empty result array");
    return {};
  }

  // Sends every command, paced and retried; returns when all are acked or one failed.
  veneer::Status run(std::vector<Command> commands) {
    if (commands.empty()) return {};
    const auto timeout = std::chrono::milliseconds(options.timeout_ms);
    std::size_t done_count = 0;
    veneer::Status failure;
    std::deque<Command*> queue;
    for (auto& c : commands) queue.push_back(&c);
    std::vector<Command*> active;

    while (done_count < commands.size() && failure.ok()) {
      auto now = Clock::now();
      Clock::time_point wake = now + std::chrono::milliseconds(50);
      // Start what the limits allow, in order.
      // A lamp's commands go one at a time, in order: two in flight could
      // overtake each other (its colour landing after its "off").
      std::vector<int> lamp_busy;
      for (Command* a : active) lamp_busy.push_back(a->lamp);
      for (auto it = queue.begin(); it != queue.end() && client.active() < options.max_in_flight;) {
        Command* c = *it;
        if (c->lamp >= 0 && std::find(lamp_busy.begin(), lamp_busy.end(), c->lamp) != lamp_busy.end()) {
          ++it;
          continue;
        }
        lamp_busy.push_back(c->lamp);
        if (c->attempts == 0) c->deadline = now + timeout;
        if (now >= c->deadline) {
          failure = veneer::make_error(who(*c) + ": the Hue bridge " + options.bridge + " did not acknowledge PUT " +
                                       c->path + " within " + ms(timeout) + " (" + std::to_string(c->attempts) +
                                       " attempts, last: " + c->last_error + ")");
          break;
        }
        Clock::time_point allowed = std::max(c->not_before, (c->group ? group_window : light_window).next_allowed(now));
        if (allowed > now) {
          if (c->attempts == 0 && !c->paced && allowed > c->not_before) {
            c->paced = true;
            ++stats.paced_waits;
          }
          wake = std::min(wake, allowed);
          ++it;
          continue;
        }
        (c->group ? group_window : light_window).record(now);
        if (c->attempts > 0) ++stats.retries;
        ++c->attempts;
        ++stats.requests;
        long remaining = static_cast<long>(std::chrono::duration_cast<std::chrono::milliseconds>(c->deadline - now).count());
        c->ticket = client.start(HttpCall{"PUT", base + c->path, c->body.dump(), std::max(1L, remaining)});
        active.push_back(c);
        it = queue.erase(it);
      }
      if (!failure.ok()) break;
      auto wait = std::chrono::duration_cast<std::chrono::milliseconds>(wake - Clock::now());
      auto finished = client.poll(std::clamp(wait, std::chrono::milliseconds(0), std::chrono::milliseconds(50)));
      if (client.active() == 0 && finished.empty() && wait.count() > 0 && !queue.empty())
        std::this_thread::sleep_for(std::min(wait, std::chrono::milliseconds(50)));
      for (auto& [ticket, result] : finished) {
        auto ait = std::find_if(active.begin(), active.end(), [&, t = ticket](Command* c) { return c->ticket == t; });
        if (ait == active.end()) continue;
        Command* c = *ait;
        active.erase(ait);
        auto t = Clock::now();
        bool retry = false;
        std::string why;
        if (!result.transport_ok) {
          retry = true;
          why = result.error;
        } else if (result.status == 429 || result.status == 503) {
          ++stats.refused;
          retry = true;
          why = "HTTP " + std::to_string(result.status);
        } else if (result.status != 200) {
          failure = veneer::make_error(who(*c) + ": the Hue bridge " + options.bridge + " answered HTTP " +
                                       std::to_string(result.status) + " to PUT " + c->path + ": " +
                                       result.body.substr(0, 120));
          break;
        } else {
          auto parsed = parse_hue_results(result.body);
          if (!parsed) {
            failure = veneer::make_error(who(*c) + ": " + parsed.message());
            break;
          }
          if (auto st = explain_results(*c, *parsed); !st) {
            failure = st;
            break;
          }
          if (c->group) ++stats.group_commands;
          else ++stats.light_commands;
          c->done = true;
          ++done_count;
          continue;
        }
        if (retry) {
          // Back-off 100, 200, 400, 800 ms ... while the deadline allows.
          auto backoff = std::chrono::milliseconds(100 << std::min(c->attempts - 1, 4));
          if (t + backoff >= c->deadline) {
            failure = veneer::make_error(who(*c) + ": the Hue bridge " + options.bridge + " did not acknowledge PUT " +
                                         c->path + " within " + ms(timeout) + " (" + std::to_string(c->attempts) +
                                         " attempts, last: " + why + ")");
            break;
          }
          VLOG_DEBUG(kLog, "{}: {} — retrying in {} ms", who(*c), why, backoff.count());
          c->last_error = why;
          c->not_before = t + backoff;
          queue.push_front(c);
        }
      }
    }
    if (!failure.ok()) {
      client.cancel_all();  // whatever was in flight may or may not have happened: the next reading tells
      VLOG_WARN(kLog, "{}", failure.message());
    }
    return failure;
  }

  veneer::Expected<json> get(const std::string& path) {
    ++stats.requests;
    auto deadline = Clock::now() + std::chrono::milliseconds(options.timeout_ms);
    for (int attempt = 0;; ++attempt) {
      long remaining = static_cast<long>(std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count());
      HttpResult r = client.perform(HttpCall{"GET", base + path, "", std::max(1L, remaining)});
      bool retry = !r.transport_ok || r.status == 429 || r.status == 503;
      if (r.transport_ok && (r.status == 429 || r.status == 503)) ++stats.refused;
      if (!retry) {
        if (r.status != 200)
          return veneer::make_error("the Hue bridge " + options.bridge + " answered HTTP " + std::to_string(r.status) +
                                    " to GET " + path);
        json j = json::parse(r.body, nullptr, false);
        if (j.is_discarded()) return veneer::make_error("the Hue bridge " + options.bridge + " sent non-JSON for GET " + path);
        if (j.is_array()) {  // an error array
          auto parsed = parse_hue_results(r.body);
          if (parsed) {
            for (const auto& e : *parsed) {
              if (e.error_type == 1) return veneer::make_error(key_refused());
              if (!e.success)
                return veneer::make_error("Hue bridge " + options.bridge + ": error " + std::to_string(e.error_type) +
                                          " for GET " + path + ": " + e.description);
            }
          }
          return veneer::make_error("the Hue bridge " + options.bridge + " sent an unexpected array for GET " + path);
        }
        return j;
      }
      auto backoff = std::chrono::milliseconds(100 << std::min(attempt, 4));
      if (Clock::now() + backoff >= deadline)
        return veneer::make_error("the Hue bridge " + options.bridge + " did not answer GET " + path + " within " +
                                  std::to_string(options.timeout_ms) + " ms (" +
                                  (r.transport_ok ? "HTTP " + std::to_string(r.status) : r.error) + ")" +
                                  (r.transport_ok ? "" : ": is it powered and on the network at that address? "
                                                         "`veneerd hue discover` finds it"));
      ++stats.retries;
      std::this_thread::sleep_for(backoff);
    }
  }

  veneer::Expected<std::vector<LampState>> read_all() {
    auto lights = get("/lights");
    if (!lights) return lights.error();
    if (!lights->is_object()) return veneer::make_error("the Hue bridge " + options.bridge + " sent a malformed /lights answer");
    std::vector<LampState> out;
    for (std::size_t i = 0; i < options.lamps.size(); ++i) {
      int idx = static_cast<int>(i);
      auto it = lights->find(options.lamps[i]);
      if (it == lights->end() || !it->is_object())
        return veneer::make_error(lamp_label(idx) + " is not known to the Hue bridge " + options.bridge +
                                  ": list its lamps with `veneerd hue lamps --address " + options.bridge +
                                  " --key KEY` and correct the config's lamps.lamps");
      auto st_it = it->find("state");
      if (st_it == it->end() || !st_it->is_object())
        return veneer::make_error(lamp_label(idx) + ": the bridge reports no state");
      const json& st = *st_it;
      LampState s;
      auto integer = [&](const char* key, int lo, int hi, int& out_value) {
        auto f = st.find(key);
        if (f == st.end() || !f->is_number()) return false;
        out_value = static_cast<int>(std::clamp<double>(std::round(f->get<double>()), lo, hi));
        return true;
      };
      if (auto f = st.find("on"); f != st.end() && f->is_boolean()) s.on = f->get<bool>();
      integer("bri", 1, 254, s.brightness);
      s.has_xy = false;
      if (auto f = st.find("xy"); f != st.end() && f->is_array() && f->size() == 2 && (*f)[0].is_number() &&
                                  (*f)[1].is_number()) {
        s.x = (*f)[0].get<double>();
        s.y = (*f)[1].get<double>();
        s.has_xy = true;
      }
      s.has_ct = integer("ct", 153, 500, s.ct);
      bool has_hs = integer("hue", 0, 65535, s.hue) && integer("sat", 0, 254, s.sat);
      std::string mode;
      if (auto f = st.find("colormode"); f != st.end() && f->is_string()) mode = f->get<std::string>();
      if (mode == "ct" && s.has_ct) s.mode = ColourMode::ct;
      else if (mode == "hs" && has_hs) s.mode = ColourMode::hs;
      else if (s.has_xy) s.mode = ColourMode::xy;
      else if (s.has_ct) s.mode = ColourMode::ct;
      if (auto f = st.find("reachable"); f != st.end() && f->is_boolean()) s.reachable = f->get<bool>();
      out.push_back(s);
    }
    return out;
  }

  // The colour part of a body, in the wanted mode (ct on a lamp without xy).
  static void put_colour(json& body, const LampState& want, const LampState& lamp) {
    if (!lamp.has_xy && !lamp.has_ct) return;
    ColourMode mode = want.mode;
    if (!lamp.has_xy && mode != ColourMode::ct) mode = ColourMode::ct;
    switch (mode) {
      case ColourMode::xy: body["xy"] = {want.x, want.y}; break;
      case ColourMode::ct: body["ct"] = std::clamp(want.ct, 153, 500); break;
      case ColourMode::hs:
        body["hue"] = std::clamp(want.hue, 0, 65535);
        body["sat"] = std::clamp(want.sat, 0, 254);
        break;
    }
  }

  Command light_command(int i, json body) {
    Command c;
    c.path = "/lights/" + options.lamps[i] + "/state";
    c.lamp = i;
    c.body = std::move(body);
    return c;
  }

  veneer::Status command(const std::vector<LampState>& now, const std::vector<LampState>& want) {
    if (want.size() != options.lamps.size() || now.size() != options.lamps.size())
      return veneer::make_error("hue lamps: " + std::to_string(want.size()) + " states for " +
                                std::to_string(options.lamps.size()) + " lamps");
    std::vector<Command> commands;
    std::vector<int> plain_off;  // lamps that only need switching off
    for (std::size_t k = 0; k < want.size(); ++k) {
      int i = static_cast<int>(k);
      const LampState& w = want[k];
      const LampState& n = now[k];
      if (w.on) {
        if (n.on && same_colour(n, w)) continue;
        json body{{"on", true}, {"bri", std::clamp(w.brightness, 1, 254)}};
        put_colour(body, w, n);
        body["transitiontime"] = 0;
        commands.push_back(light_command(i, std::move(body)));
      } else if (n.on) {
        if (!same_colour(n, w)) {
          // While it is still on: the look its owner expects when it next comes on.
          json body{{"bri", std::clamp(w.brightness, 1, 254)}};
          put_colour(body, w, n);
          body["transitiontime"] = 0;
          commands.push_back(light_command(i, std::move(body)));
          commands.push_back(light_command(i, json{{"on", false}, {"transitiontime", 0}}));
        } else {
          plain_off.push_back(i);
        }
      }
    }
    const bool all_off = std::none_of(want.begin(), want.end(), [](const LampState& w) { return w.on; });
    auto now_t = Clock::now();
    if (all_off && !options.group.empty() && plain_off.size() >= 2 && commands.empty() &&
        group_window.next_allowed(now_t) <= now_t) {
      Command c;
      c.path = "/groups/" + options.group + "/action";
      c.group = true;
      c.body = json{{"on", false}, {"transitiontime", 0}};
      std::vector<Command> group;
      group.push_back(std::move(c));
      if (auto st = run(std::move(group)); st) {
        std::this_thread::sleep_for(std::chrono::milliseconds(options.settle_ms));
        return {};
      }
      VLOG_WARN(kLog, "group '{}' off failed; switching lamps off one by one", options.group);
    }
    for (int i : plain_off) commands.push_back(light_command(i, json{{"on", false}, {"transitiontime", 0}}));
    if (commands.empty()) return {};
    if (auto st = run(std::move(commands)); !st) return st;
    std::this_thread::sleep_for(std::chrono::milliseconds(options.settle_ms));
    return {};
  }
};

HueLamps::HueLamps(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
HueLamps::~HueLamps() = default;

veneer::Expected<std::unique_ptr<HueLamps>> HueLamps::create(const HueLampsOptions& options) {
  if (auto st = options.check(); !st) return st.error();
  return std::unique_ptr<HueLamps>(new HueLamps(std::make_unique<Impl>(options)));
}

int HueLamps::count() const { return static_cast<int>(impl_->options.lamps.size()); }
const HueLampsOptions& HueLamps::options() const { return impl_->options; }
std::string HueLamps::label(int i) const {
  if (i < 0 || i >= count()) return Lamps::label(i);
  return impl_->lamp_label(i);
}

veneer::Expected<std::vector<LampState>> HueLamps::read() {
  std::lock_guard lock(impl_->mutex);
  return impl_->read_all();
}

veneer::Status HueLamps::command(const std::vector<LampState>& now, const std::vector<LampState>& want) {
  std::lock_guard lock(impl_->mutex);
  return impl_->command(now, want);
}

veneer::Expected<std::string> HueLamps::check_bridge() {
  std::lock_guard lock(impl_->mutex);
  auto config = impl_->get("/config");
  if (!config) return config.error();
  // A bridge answers /config without a valid key too, with only a few fields:
  // the whitelist (or the lights) tell a known user.
  auto lights = impl_->get("/lights");
  if (!lights) return lights.error();
  std::string name = config->is_object() && config->contains("name") && (*config)["name"].is_string()
                         ? (*config)["name"].get<std::string>()
                         : "Hue bridge";
  std::string api = config->is_object() && config->contains("apiversion") && (*config)["apiversion"].is_string()
                        ? (*config)["apiversion"].get<std::string>()
                        : "?";
  return name + " at " + impl_->options.bridge + " (API " + api + ")";
}

HueLampsStats HueLamps::stats() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->stats;
}

}  // namespace veneerd::hw
