#pragma once
// Lamps backend "hue" (real hardware): a Philips Hue bridge over its v1 REST API
// (libcurl, through hw/http_client.hpp). The simulated rig points it at the
// bridge emulator (sim/hue_emulator.hpp), so the real client runs in every test.
//
// What the bridge is like, and what this class does about it:
//  - ~10 light commands/s and 1 group command/s, 429/503 beyond that or with
//    more than ~3 requests in flight: commands are paced by sliding windows
//    below those limits, at most 3 are in flight (never two for one lamp, so
//    they take effect in the order sent), and 429/503 are retried with back-off;
//  - its lamps are shared: the Hue app, scenes and sensors switch them at any
//    time, so what to send is decided from a reading of the bridge
//    (Lamps::ensure reads, commands the difference and reads back), never from
//    a record of what this class sent earlier;
//  - it rejects bri and colour sent to a lamp that is off unless "on" is in
//    the same body: every "on" command carries on, bri, the colour in the
//    wanted mode (xy, ct or hue/sat) and transitiontime 0; a lamp to be
//    switched off that should keep another colour gets that colour first,
//    while it is still on;
//  - it acknowledges before the lamp has changed: command() waits settle_ms
//    after the last ack;
//  - "all off" uses the group when one is configured and two or more lamps
//    need it.
//
// Config section (JSON):
//   {"bridge": "127.0.0.1:8080", "key": "<whitelisted user>",
//    "lamps": ["1","2",...]   Hue light ids in ring-position order,
//    "group": "1"             optional, a group holding exactly the ring lamps, for "all off",
//    "settle_ms": 150, "timeout_ms": 2000, "confirm_ms": 1000,
//    "light_rate": 8, "group_rate": 0.9, "max_in_flight": 3}
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "veneer/util/expected.hpp"
#include "veneerd/devices/lamps.hpp"

namespace veneerd::hw {

struct HueLampsOptions {
  std::string bridge;               // "host:port" or "host" (port 80)
  std::string key;                  // the bridge user ("username" of the v1 API)
  std::vector<std::string> lamps;   // Hue light ids, ring-position order
  std::string group;                // group id for "all off"; empty = none
  int settle_ms = 150;              // wait after the last ack [ms]
  int timeout_ms = 2000;            // per command, retries included [ms]
  int confirm_ms = 1000;            // a commanded change may take this long to show in the bridge's readings [ms]
  double light_rate = 8.0;          // light commands per second we allow ourselves (bridge: ~10)
  double group_rate = 0.9;          // group commands per second (bridge: 1)
  int max_in_flight = 3;            // concurrent requests (bridge: ~3)
  veneer::Status check() const;
  static veneer::Expected<HueLampsOptions> from_json(const nlohmann::json& section);
  nlohmann::json to_json() const;
};

struct HueLampsStats {
  uint64_t requests = 0;        // HTTP requests sent (retries included)
  uint64_t light_commands = 0;  // accepted PUT .../lights/<id>/state
  uint64_t group_commands = 0;  // accepted PUT .../groups/<g>/action
  uint64_t refused = 0;         // 429/503 answers seen (each was retried)
  uint64_t retries = 0;         // requests sent again (refused or transport errors)
  uint64_t paced_waits = 0;     // times a command waited for the rate window
};

// One parsed entry of the bridge's answer array.
struct HueResult {
  bool success = false;
  int error_type = 0;           // Hue error type (1 unauthorized, 3 not available, 201 not modifiable...)
  std::string address;          // e.g. "/lights/3/state/bri"
  std::string description;
};
// Parses [{"success":{...}}, {"error":{"type":..,"address":..,"description":..}}].
veneer::Expected<std::vector<HueResult>> parse_hue_results(const std::string& body);

class HueLamps : public Lamps {
 public:
  static veneer::Expected<std::unique_ptr<HueLamps>> create(const HueLampsOptions& options);
  ~HueLamps() override;

  std::string name() const override { return "hue"; }
  int count() const override;
  std::string label(int i) const override;
  int confirm_ms() const override { return options().confirm_ms; }
  veneer::Expected<std::vector<LampState>> read() override;
  veneer::Status command(const std::vector<LampState>& now, const std::vector<LampState>& want) override;
  // The bridge's answer to GET /config with this key: its name and API
  // version, or why not (unreachable, key refused with the fix).
  veneer::Expected<std::string> check_bridge();
  HueLampsStats stats() const;
  const HueLampsOptions& options() const;

 private:
  struct Impl;
  explicit HueLamps(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace veneerd::hw
