#pragma once
// A Hue bridge emulator for the simulated rig and the tests: an HTTP/1.1 server
// on loopback (its own threads) that answers the v1 REST calls the real bridge
// answers, with the bridge's JSON success/error bodies, its rate limits and its
// ack-before-change behaviour, and that can be told to misbehave.
//
//   GET  /api/<key>/lights            all lamps
//   GET  /api/<key>/lights/<id>       one lamp
//   PUT  /api/<key>/lights/<id>/state {"on","bri","xy"|"ct"|"hue"+"sat","bri_inc","transitiontime",...}
// Lamps keep a colour mode (colormode xy, ct or hs, set by the last colour
// parameter) and report xy for every mode, as a bridge does.
//   GET  /api/<key>/groups            groups ("0" = every lamp)
//   GET  /api/<key>/groups/<g>
//   PUT  /api/<key>/groups/<g>/action
//   GET  /api/<key>/config            bridge config (name, bridgeid, apiversion)
//   POST /api  {"devicetype": ".."}   pairing (needs press_link_button())
// Errors: unauthorized user (type 1), resource not available (3), body not
// parsable (2), parameter not available (6), invalid value (7), parameter not
// modifiable while the lamp is off (201), link button not pressed (101).
// Rate limits (when enforced): more than `light_limit` light commands in the
// last second or more than `group_limit` group commands -> 429; more than
// `max_in_flight` requests being served at once -> 503.
#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "veneer/util/expected.hpp"
#include "veneerd/sim/http_request.hpp"
#include "veneerd/devices/lamps.hpp"

namespace veneerd {

class FaultPlan;

struct HueEmulatorOptions {
  int lamps = 7;                     // lamps "1".."N", named "Ring 1".."Ring N"
  std::string key = "veneer-sim";    // the one whitelisted user
  int apply_delay_ms = 50;           // a change shows this long after its ack [ms]
  int latency_ms = 0;                // added before every answer [ms]
  bool enforce_limits = true;
  int light_limit = 10;              // light commands per second
  int group_limit = 1;               // group commands per second
  int max_in_flight = 3;             // concurrent requests
  int max_connections = 64;          // open sockets; more are closed at once
};

struct HueEmulatorCounters {
  uint64_t requests = 0;          // complete requests received
  uint64_t served = 0;            // answered 2xx
  uint64_t light_commands = 0;    // accepted PUT lights/<id>/state
  uint64_t group_commands = 0;    // accepted PUT groups/<g>/action
  uint64_t refused_rate = 0;      // 429: over the per-second limits
  uint64_t refused_busy = 0;      // 503: too many in flight
  uint64_t injected = 0;          // answers replaced by an injected fault
  uint64_t dropped = 0;           // connections closed without an answer
  uint64_t bad_requests = 0;      // malformed HTTP (400/411/413/431/501...)
  uint64_t max_in_flight_seen = 0;
};

struct EmulatedLamp {
  std::string id;
  std::string name;
  LampState state;                // as applied (what a query shows now)
};

class HueBridgeEmulator {
 public:
  explicit HueBridgeEmulator(HueEmulatorOptions options = {});
  ~HueBridgeEmulator();  // stops
  HueBridgeEmulator(const HueBridgeEmulator&) = delete;
  HueBridgeEmulator& operator=(const HueBridgeEmulator&) = delete;

  // Listens on host:port (port 0 = any free port) and serves from its own threads.
  veneer::Status start(const std::string& host = "127.0.0.1", uint16_t port = 0);
  void stop();
  bool running() const;
  uint16_t port() const;
  std::string address() const;  // "127.0.0.1:<port>"
  const HueEmulatorOptions& options() const;

  // --- the bridge's state -------------------------------------------------
  std::vector<EmulatedLamp> lamps() const;                       // applied state now
  std::optional<LampState> lamp(const std::string& id) const;
  std::vector<bool> on_pattern() const;                          // lamps "1".."N" on?
  void set_lamp(const std::string& id, const LampState& state);  // as another app would
  // Another app's change to lamp `id`, landing just after the `light_commands`-th
  // light command accepted from now on (to switch or colour a lamp mid-set at a
  // known step). Colour modes: state.mode with its values, as a client would set.
  void interfere_after(int light_commands, const std::string& id, const LampState& state);
  void set_reachable(const std::string& id, bool reachable);
  void press_link_button();                                      // next pairing succeeds (30 s)

  // --- faults and timing --------------------------------------------------
  void set_latency(std::chrono::milliseconds latency);
  void set_apply_delay(std::chrono::milliseconds delay);
  void set_enforce_limits(bool enforce);
  // The next `count` requests are answered with HTTP `status` (e.g. 503, 500)
  // and a short body instead of being served.
  void fail_next(int count, int status);
  // The next `count` state/action PUTs are answered 200 with a Hue error array
  // of `type` (e.g. 201, 901 internal error) for their parameters.
  void hue_error_next(int count, int type);
  // The next `count` requests have their connection closed without an answer.
  void drop_next(int count);
  // Closes every open connection now (keep-alive sockets included).
  void drop_connections();
  // Faults drawn per request from `plan` (bridge.429, bridge.503,
  // bridge.timeout, bridge.drop, lamp.unreachable; fault_plan.hpp), besides
  // the ones above; null = none.
  void set_fault_plan(std::shared_ptr<FaultPlan> plan);

  HueEmulatorCounters counters() const;
  void reset_counters();

  // Serves one parsed request without the network (used by the socket threads
  // and by the HTTP fuzz target). Rate limits and in-flight counting apply.
  HttpResponse handle(const HttpRequest& request);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace veneerd
