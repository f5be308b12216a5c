#pragma once
// Setting up the Hue bridge for a rig: find the bridge, pair with it by the
// link-button flow to get an application key, list its lamps, and flash each
// lamp in turn so the owner can write the ring order into the config.
// Talks the bridge's v1 REST API with libcurl (hue_setup.cpp only).
//
// Discovery: a manual address always works; mDNS (_hue._tcp) is browsed through
// Avahi's client library (veneer_dnssd) when avahi-daemon runs; the bridge's cloud discovery
// (discovery.meethue.com) only when asked for, since rigs often run offline.
// Every candidate is confirmed by its /api/config answer.
#include <functional>
#include <iosfwd>
#include <string>
#include <vector>

#include "veneer/util/expected.hpp"

namespace veneerd::hw {

struct BridgeInfo {
  std::string address;  // host[:port]
  std::string name, bridgeid, modelid, apiversion, mac;
};

struct BridgeLamp {
  std::string id, name, type, modelid;
  bool on = false, reachable = true;
};

// Parses a bridge's /api/config answer (network input: checked, never trusted).
veneer::Expected<BridgeInfo> parse_bridge_config(const std::string& body);
// Parses a bridge's /api/<key>/lights answer.
veneer::Expected<std::vector<BridgeLamp>> parse_bridge_lights(const std::string& body);
// The Hue error in an answer like [{"error":{"type":101,...}}]; type 0 = none.
struct HueError {
  int type = 0;
  std::string description;
};
HueError parse_hue_error(const std::string& body);

// GET http://<address>/api/config (no key needed on a real bridge).
veneer::Expected<BridgeInfo> probe_bridge(const std::string& address, long timeout_ms = 2000);

struct DiscoverOptions {
  std::vector<std::string> addresses;  // manual addresses, tried first
  bool mdns = true;                    // DNS-SD browse for _hue._tcp (Avahi), when avahi-daemon runs
  int mdns_timeout_ms = 2000;          // how long to browse
  bool cloud = false;                  // https://discovery.meethue.com
  long timeout_ms = 2000;
};
// Every bridge that answered; `notes` receives one line per source tried.
std::vector<BridgeInfo> discover_bridges(const DiscoverOptions& options, std::vector<std::string>* notes = nullptr);

// One pairing attempt: POST /api {"devicetype": ...}.
struct PairAttempt {
  enum class Outcome { paired, press_link_button, failed } outcome = Outcome::failed;
  std::string key;      // the application key when paired
  std::string message;  // what went wrong otherwise
};
PairAttempt pair_once(const std::string& address, const std::string& devicetype = "veneer#rig");
// Repeats pair_once every `interval_ms` until paired, failed or `timeout_ms`;
// `tell` is called once when the link button must be pressed.
veneer::Expected<std::string> pair_bridge(const std::string& address, long timeout_ms, long interval_ms,
                                          const std::function<void(const std::string&)>& tell,
                                          const std::string& devicetype = "veneer#rig");

veneer::Expected<std::vector<BridgeLamp>> list_bridge_lamps(const std::string& address, const std::string& key);

// Flashes each lamp ("alert": "select", one breathe cycle) in turn, `gap_ms`
// apart, calling `announce(lamp, position)` just before its flash.
veneer::Status flash_lamps_in_turn(const std::string& address, const std::string& key,
                                   const std::vector<std::string>& ids, long gap_ms,
                                   const std::function<void(const std::string& id, int position)>& announce);

// `veneerd hue <discover|pair|lamps|flash> ...` — the subcommand behind the
// daemon's CLI (argv[0] = "hue"). Exit code 0 ok, 1 failure, 2 usage.
//   hue discover [--address A]... [--cloud] [--no-mdns]
//   hue pair --address A [--timeout S]
//   hue lamps --address A --key K
//   hue flash --address A --key K [--lamps 3,4,5] [--gap-ms 2500]
int hue_command(const std::vector<std::string>& args, std::ostream& out, std::ostream& err);

}  // namespace veneerd::hw
