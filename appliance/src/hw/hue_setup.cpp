// Hue bridge setup: discovery, pairing, lamp list, flashing (HTTP through
// http_client.hpp, the daemon's one libcurl wrapper).
#include "veneerd/hw/hue_setup.hpp"

#include <chrono>
#include <cstdio>
#include <memory>
#include <ostream>
#include <sstream>
#include <thread>

#include <nlohmann/json.hpp>

#include "veneer/dnssd/dnssd.hpp"
#include "veneer/util/log.hpp"
#include "http_client.hpp"
#include "veneerd/hw/hue_lamps.hpp"

namespace veneerd::hw {

using nlohmann::json;

namespace {

struct HttpAnswer {
  bool ok = false;  // an HTTP answer arrived
  long status = 0;
  std::string body;
  std::string error;
};

// One blocking request through the daemon's libcurl wrapper (http_client.hpp).
HttpAnswer http(const std::string& method, const std::string& url, const std::string& body, long timeout_ms) {
  detail::HttpClient client;
  detail::HttpResult r = client.perform({method, url, body, timeout_ms});
  return {r.transport_ok, r.status, std::move(r.body), std::move(r.error)};
}

std::string url_of(const std::string& address, const std::string& path) {
  std::string base = address;
  if (base.rfind("http://", 0) != 0 && base.rfind("https://", 0) != 0) base = "http://" + base;
  while (!base.empty() && base.back() == '/') base.pop_back();
  return base + path;
}

std::string str(const json& j, const char* key) {
  auto it = j.find(key);
  return it != j.end() && it->is_string() ? it->get<std::string>() : "";
}

veneer::Status answer_ok(const HttpAnswer& a, const std::string& address, const std::string& what) {
  if (!a.ok) return veneer::make_error("Hue bridge " + address + ": " + what + ": no answer (" + a.error + ")");
  if (a.status != 200)
    return veneer::make_error("Hue bridge " + address + ": " + what + ": HTTP " + std::to_string(a.status));
  HueError e = parse_hue_error(a.body);
  if (e.type == 1)
    return veneer::make_error("Hue bridge " + address +
                              ": the key is not paired with this bridge: press its link button, run `veneerd hue pair "
                              "--address " + address + "` and put the key it prints into the config's lamps.key");
  if (e.type != 0)
    return veneer::make_error("Hue bridge " + address + ": " + what + ": " + e.description + " (Hue error " +
                              std::to_string(e.type) + ")");
  return {};
}

}  // namespace

HueError parse_hue_error(const std::string& body) {
  HueError e;
  json j = json::parse(body, nullptr, false);
  if (j.is_discarded()) return e;
  if (j.is_array() && !j.empty()) j = j[0];
  if (!j.is_object()) return e;
  auto it = j.find("error");
  if (it == j.end() || !it->is_object()) return e;
  auto t = it->find("type");
  if (t != it->end() && t->is_number_integer()) e.type = int(std::clamp<long long>(t->get<long long>(), -1, 1 << 20));
  if (e.type == 0) e.type = -1;
  e.description = str(*it, "description");
  return e;
}

veneer::Expected<BridgeInfo> parse_bridge_config(const std::string& body) {
  json j = json::parse(body, nullptr, false);
  if (j.is_discarded()) return veneer::make_error("the answer is not JSON");
  HueError e = parse_hue_error(body);
  if (e.type != 0) return veneer::make_error("the bridge answered with Hue error " + std::to_string(e.type) + ": " + e.description);
  if (!j.is_object()) return veneer::make_error("the answer is not a JSON object");
  BridgeInfo b;
  b.name = str(j, "name");
  b.bridgeid = str(j, "bridgeid");
  b.modelid = str(j, "modelid");
  b.apiversion = str(j, "apiversion");
  b.mac = str(j, "mac");
  if (b.bridgeid.empty() && b.apiversion.empty())
    return veneer::make_error("the answer has neither bridgeid nor apiversion: not a Hue bridge");
  return b;
}

veneer::Expected<std::vector<BridgeLamp>> parse_bridge_lights(const std::string& body) {
  json j = json::parse(body, nullptr, false);
  if (j.is_discarded()) return veneer::make_error("the lamp list is not JSON");
  HueError e = parse_hue_error(body);
  if (e.type != 0) return veneer::make_error("Hue error " + std::to_string(e.type) + ": " + e.description);
  if (!j.is_object()) return veneer::make_error("the lamp list is not a JSON object");
  std::vector<BridgeLamp> out;
  for (auto it = j.begin(); it != j.end(); ++it) {
    if (!it->is_object()) continue;
    BridgeLamp l;
    l.id = it.key();
    l.name = str(*it, "name");
    l.type = str(*it, "type");
    l.modelid = str(*it, "modelid");
    auto st = it->find("state");
    if (st != it->end() && st->is_object()) {
      if (auto on = st->find("on"); on != st->end() && on->is_boolean()) l.on = on->get<bool>();
      if (auto r = st->find("reachable"); r != st->end() && r->is_boolean()) l.reachable = r->get<bool>();
    }
    out.push_back(std::move(l));
  }
  // Numeric ids in numeric order ("2" before "10").
  std::sort(out.begin(), out.end(), [](const BridgeLamp& a, const BridgeLamp& b) {
    return a.id.size() != b.id.size() ? a.id.size() < b.id.size() : a.id < b.id;
  });
  return out;
}

veneer::Expected<BridgeInfo> probe_bridge(const std::string& address, long timeout_ms) {
  HttpAnswer a = http("GET", url_of(address, "/api/config"), "", timeout_ms);
  if (!a.ok) return veneer::make_error("no Hue bridge answers at " + address + " (" + a.error + ")");
  if (a.status != 200)
    return veneer::make_error(address + " answered HTTP " + std::to_string(a.status) + " to /api/config: not a Hue bridge");
  HueError e = parse_hue_error(a.body);
  if (e.type == 1) {
    // Some firmware (and the emulator) want a key even for the short config;
    // answering in the bridge's error format still identifies a bridge.
    BridgeInfo b;
    b.address = address;
    b.name = "Hue bridge";
    return b;
  }
  auto b = parse_bridge_config(a.body);
  if (!b) return veneer::make_error(address + ": " + b.message());
  b->address = address;
  return b;
}

std::vector<BridgeInfo> discover_bridges(const DiscoverOptions& o, std::vector<std::string>* notes) {
  std::vector<BridgeInfo> found;
  auto note = [&](const std::string& s) {
    if (notes) notes->push_back(s);
  };
  auto add = [&](const std::string& address, const std::string& source) {
    for (const auto& f : found)
      if (f.address == address) return;
    auto b = probe_bridge(address, o.timeout_ms);
    if (b) {
      found.push_back(*b);
      note(source + ": bridge at " + address);
    } else {
      note(source + ": " + b.message());
    }
  };
  for (const auto& a : o.addresses) add(a, "manual address");
  if (o.mdns) {
    // DNS-SD through Avahi's client library (needs avahi-daemon on the system bus).
    auto services = veneer::dnssd::browse("_hue._tcp", o.mdns_timeout_ms);
    if (!services) {
      note("mDNS: " + services.message());
    } else {
      int seen = 0;
      for (const auto& s : *services) {
        if (s.ipv6) continue;  // the bridge answers on IPv4; its IPv6 record is the same bridge
        ++seen;
        add(s.address + (s.port == 80 || s.port == 0 ? "" : ":" + std::to_string(s.port)), "mDNS");
      }
      if (seen == 0) note("mDNS: no _hue._tcp service on the network");
    }
  }
  if (o.cloud) {
    HttpAnswer a = http("GET", "https://discovery.meethue.com/", "", o.timeout_ms);
    json j = a.ok ? json::parse(a.body, nullptr, false) : json();
    if (!a.ok) note("cloud discovery: no answer (" + a.error + ")");
    else if (!j.is_array()) note("cloud discovery: unexpected answer");
    else
      for (const auto& e : j)
        if (e.is_object() && !str(e, "internalipaddress").empty()) add(str(e, "internalipaddress"), "cloud discovery");
  }
  return found;
}

PairAttempt pair_once(const std::string& address, const std::string& devicetype) {
  PairAttempt p;
  HttpAnswer a = http("POST", url_of(address, "/api"), json{{"devicetype", devicetype}}.dump(), 3000);
  if (!a.ok) {
    p.message = "no Hue bridge answers at " + address + " (" + a.error + ")";
    return p;
  }
  json j = json::parse(a.body, nullptr, false);
  if (a.status == 200 && j.is_array() && !j.empty() && j[0].is_object() && j[0].contains("success") &&
      j[0]["success"].is_object() && !str(j[0]["success"], "username").empty()) {
    p.outcome = PairAttempt::Outcome::paired;
    p.key = str(j[0]["success"], "username");
    return p;
  }
  HueError e = parse_hue_error(a.body);
  if (e.type == 101) {
    p.outcome = PairAttempt::Outcome::press_link_button;
    p.message = "press the round link button on the Hue bridge";
    return p;
  }
  p.message = "pairing with " + address + " failed: " +
              (e.type ? e.description + " (Hue error " + std::to_string(e.type) + ")" : "HTTP " + std::to_string(a.status));
  return p;
}

veneer::Expected<std::string> pair_bridge(const std::string& address, long timeout_ms, long interval_ms,
                                          const std::function<void(const std::string&)>& tell,
                                          const std::string& devicetype) {
  auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
  bool told = false;
  for (;;) {
    PairAttempt p = pair_once(address, devicetype);
    if (p.outcome == PairAttempt::Outcome::paired) return p.key;
    if (p.outcome == PairAttempt::Outcome::failed) return veneer::make_error(p.message);
    if (!told && tell) tell("Press the round link button on the Hue bridge at " + address + " now (waiting up to " +
                            std::to_string(timeout_ms / 1000) + " s)...");
    told = true;
    if (std::chrono::steady_clock::now() + std::chrono::milliseconds(interval_ms) > until)
      return veneer::make_error("the link button on the Hue bridge at " + address + " was not pressed within " +
                                std::to_string(timeout_ms / 1000) + " s");
    std::this_thread::sleep_for(std::chrono::milliseconds(interval_ms));
  }
}

veneer::Expected<std::vector<BridgeLamp>> list_bridge_lamps(const std::string& address, const std::string& key) {
  HttpAnswer a = http("GET", url_of(address, "/api/" + key + "/lights"), "", 3000);
  if (auto s = answer_ok(a, address, "listing lamps"); !s) return s.error();
  auto lamps = parse_bridge_lights(a.body);
  if (!lamps) return veneer::make_error("Hue bridge " + address + ": " + lamps.message());
  return lamps;
}

veneer::Status flash_lamps_in_turn(const std::string& address, const std::string& key,
                                   const std::vector<std::string>& ids, long gap_ms,
                                   const std::function<void(const std::string&, int)>& announce) {
  if (ids.empty()) return {};
  // The owner's states first: every lamp goes back as it was after its flash,
  // also when a later flash fails.
  HueLampsOptions o;
  o.bridge = address;
  o.key = key;
  o.lamps = ids;
  o.settle_ms = 0;
  o.timeout_ms = 3000;
  auto lamps = HueLamps::create(o);
  if (!lamps) return lamps.error();
  auto owner = (*lamps)->read();
  if (!owner) return owner.error();
  veneer::Status status;
  for (size_t i = 0; i < ids.size() && status.ok(); ++i) {
    if (announce) announce(ids[i], int(i));
    // "on" in the same body: a lamp that is off would not show the alert.
    HttpAnswer a = http("PUT", url_of(address, "/api/" + key + "/lights/" + ids[i] + "/state"),
                        json{{"on", true}, {"alert", "select"}}.dump(), 3000);
    status = answer_ok(a, address, "flashing lamp " + ids[i]);
    if (status && i + 1 < ids.size()) std::this_thread::sleep_for(std::chrono::milliseconds(gap_ms));
    // One breathe cycle takes about a second; then the lamp goes back.
    if (status && i + 1 == ids.size()) std::this_thread::sleep_for(std::chrono::milliseconds(std::min(gap_ms, 1000L)));
    auto now = (*lamps)->read();
    if (!now) return now.error();
    std::vector<LampState> want = *now;
    want[i] = (*owner)[i];
    if (auto r = (*lamps)->ensure(want, *now); !r) return veneer::make_error("giving lamp " + ids[i] + " back: " + r.message());
  }
  return status;
}

// ------------------------------------------------------------------ CLI

namespace {

const char* kHueUsage =
    "usage: veneerd hue discover [--address A]... [--cloud] [--no-mdns]\n"
    "       veneerd hue pair --address A [--timeout S]\n"
    "       veneerd hue lamps --address A --key K\n"
    "       veneerd hue flash --address A --key K [--lamps 1,2,3] [--gap-ms 2500]\n";

const char* kHueHelp =
    "veneerd hue: set up the Philips Hue bridge that drives the rig's lamps.\n"
    "\n"
    "  discover  find bridges on the LAN (mDNS, then --address candidates, then with\n"
    "            --cloud the vendor's discovery service); prints address, name, id, API version\n"
    "  pair      press the link button on the bridge, then run this within --timeout\n"
    "            seconds (default 60); prints the key for the config's lamps.key\n"
    "  lamps     list the bridge's lamps: id, name, type, on/off/unreachable\n"
    "  flash     flash each lamp (or those in --lamps) in turn, --gap-ms apart, so you\n"
    "            can tell which socket of the ring holds which id; every lamp goes back\n"
    "            to its state after its flash\n"
    "\n"
    "Then write the ids into the config in ring order (position 1 = top, clockwise):\n"
    "  \"lamps\": {\"backend\": \"hue\", \"bridge\": \"A\", \"key\": \"K\", \"lamps\": [\"3\", \"4\", ...]}\n"
    "\n";

}  // namespace

int hue_command(const std::vector<std::string>& args, std::ostream& out, std::ostream& err) {
  auto usage = [&](const std::string& why) {
    err << "veneerd hue: " << why << "\n" << kHueUsage << "(veneerd hue --help explains each)\n";
    return 2;
  };
  for (const auto& a : args) {
    if (a == "--help" || a == "-h" || a == "help") {
      out << kHueHelp << kHueUsage;
      return 0;
    }
  }
  size_t i = (!args.empty() && args[0] == "hue") ? 1 : 0;
  if (i >= args.size()) return usage("missing subcommand");
  std::string cmd = args[i++];
  std::vector<std::string> addresses;
  std::string key, lamps_text;
  bool cloud = false, mdns = true;
  long timeout_s = 60, gap_ms = 2500;
  for (; i < args.size(); ++i) {
    const std::string& a = args[i];
    auto value = [&](std::string& v) {
      if (i + 1 >= args.size()) return false;
      v = args[++i];
      return true;
    };
    std::string v;
    if (a == "--address") {
      if (!value(v)) return usage("--address needs a value");
      addresses.push_back(v);
    } else if (a == "--key") {
      if (!value(key)) return usage("--key needs a value");
    } else if (a == "--lamps") {
      if (!value(lamps_text)) return usage("--lamps needs a value");
    } else if (a == "--timeout" || a == "--gap-ms") {
      if (!value(v)) return usage(a + " needs a value");
      char* end = nullptr;
      long n = std::strtol(v.c_str(), &end, 10);
      if (end == v.c_str() || *end || n < 0 || n > 3600000) return usage(a + ": '" + v + "' is not a number");
      (a == "--timeout" ? timeout_s : gap_ms) = n;
    } else if (a == "--cloud") {
      cloud = true;
    } else if (a == "--no-mdns") {
      mdns = false;
    } else {
      return usage("unknown option '" + a + "'");
    }
  }
  if (cmd == "discover") {
    DiscoverOptions o;
    o.addresses = addresses;
    o.cloud = cloud;
    o.mdns = mdns;
    std::vector<std::string> notes;
    auto found = discover_bridges(o, &notes);
    for (const auto& n : notes) err << "  " << n << "\n";
    for (const auto& b : found)
      out << b.address << "  " << b.name << (b.bridgeid.empty() ? "" : "  id " + b.bridgeid)
          << (b.apiversion.empty() ? "" : "  api " + b.apiversion) << "\n";
    if (found.empty()) {
      err << "veneerd hue: no Hue bridge found; give its address with --address (the router's list of clients shows it)\n";
      return 1;
    }
    return 0;
  }
  if (addresses.size() != 1) return usage(cmd + " needs exactly one --address");
  const std::string& address = addresses[0];
  if (cmd == "pair") {
    auto k = pair_bridge(address, timeout_s * 1000, 1000, [&](const std::string& m) { err << m << std::endl; });
    if (!k) {
      err << "veneerd hue: " << k.message() << "\n";
      return 1;
    }
    out << *k << "\n";
    err << "Paired. Put this key into the config: \"lamps\": {\"backend\": \"hue\", \"bridge\": \"" << address
        << "\", \"key\": \"" << *k << "\", ...}\n";
    return 0;
  }
  if (key.empty()) return usage(cmd + " needs --key (from `veneerd hue pair`)");
  auto lamps = list_bridge_lamps(address, key);
  if (!lamps) {
    err << "veneerd hue: " << lamps.message() << "\n";
    return 1;
  }
  if (cmd == "lamps") {
    for (const auto& l : *lamps)
      out << l.id << "\t" << l.name << "\t" << (l.type.empty() ? "-" : l.type) << "\t"
          << (l.reachable ? (l.on ? "on" : "off") : "unreachable") << "\n";
    return 0;
  }
  if (cmd == "flash") {
    std::vector<std::string> ids;
    if (lamps_text.empty()) {
      for (const auto& l : *lamps) ids.push_back(l.id);
    } else {
      std::stringstream ss(lamps_text);
      std::string id;
      while (std::getline(ss, id, ','))
        if (!id.empty()) ids.push_back(id);
    }
    for (const auto& id : ids) {
      bool known = false;
      for (const auto& l : *lamps) known = known || l.id == id;
      if (!known) {
        err << "veneerd hue: the bridge has no lamp " << id << "\n";
        return 1;
      }
    }
    auto s = flash_lamps_in_turn(address, key, ids, gap_ms, [&](const std::string& id, int pos) {
      std::string name;
      for (const auto& l : *lamps)
        if (l.id == id) name = l.name;
      out << "flashing lamp " << id << " (" << name << ") — " << pos + 1 << " of " << ids.size() << std::endl;
    });
    if (!s) {
      err << "veneerd hue: " << s.message() << "\n";
      return 1;
    }
    out << "Write the lamp ids into \"lamps\": {\"lamps\": [...]} in ring order (position 1 first).\n";
    return 0;
  }
  return usage("unknown subcommand '" + cmd + "'");
}

}  // namespace veneerd::hw
