#pragma once
// DNS-SD (mDNS service discovery) through Avahi's client library: browse for a
// service type on the LAN, or advertise one. Shared by the rig (advertises
// _veneer._tcp, finds Hue bridges as _hue._tcp) and the rig client (finds rigs).
//
// Avahi talks to avahi-daemon over the system D-Bus. Where neither runs (CI,
// containers, many laptops) nothing fails: browse() returns an error saying so
// and Advertiser::start() returns one too; callers log it once and go on.
//
//   auto found = veneer::dnssd::browse("_veneer._tcp", 2000);
//   if (!found) VLOG_INFO("Rig", "DNS-SD: {}", found.message());
//
//   auto reach = veneer::dnssd::reach_of("192.168.1.20");   // where the server listens
//   auto ad = veneer::dnssd::Advertiser::start({"my-rig", "_veneer._tcp", 7878, txt, *reach});
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "veneer/util/expected.hpp"

namespace veneer::dnssd {

using Txt = std::map<std::string, std::string>;

// One resolved service instance.
struct Service {
  std::string name;       // instance name ("veneer-rig")
  std::string type;       // "_veneer._tcp"
  std::string domain;     // "local"
  std::string host;       // "rig.local"
  std::string address;    // "192.168.1.20" or an IPv6 address
  bool ipv6 = false;
  uint16_t port = 0;
  std::string interface;  // network interface name, when known
  Txt txt;                // TXT record as key -> value
};

// The TXT record's strings ("key=value") for `txt`, checked against RFC 6763:
// keys are 1-9 printable ASCII characters without '=', each string at most 255
// bytes. An error names the offending key.
Expected<std::vector<std::string>> txt_strings(const Txt& txt);
// The inverse: "key=value" strings -> map ("key" alone maps to ""). Keys are
// case-insensitive in DNS-SD and come back lower-cased; the first of a
// repeated key wins.
Txt parse_txt(const std::vector<std::string>& strings);
// A service type must look like "_name._tcp" or "_name._udp".
Status check_service_type(const std::string& type);
// An instance name is 1-63 bytes of UTF-8 without control characters.
Status check_instance_name(const std::string& name);

// Browse `type` for about `timeout_ms` (less when Avahi says it has listed all
// it knows) and resolve each instance, to an address of the family it was
// announced in (an IPv4 announcement gives an IPv4 address). Services seen on
// several interfaces or address families come back once per (name, address). Error: no daemon or
// D-Bus ("DNS-SD unavailable: ..."), or a bad type.
Expected<std::vector<Service>> browse(const std::string& type, int timeout_ms = 2000);

enum class Family { any, ipv4, ipv6 };
const char* family_name(Family family);  // "IPv4 and IPv6", "IPv4", "IPv6"

// Where a service is advertised: on every interface or on one, over both
// address families or one. A browser resolves the service to the addresses
// its host has on that interface in that family, so this must match where
// the server listens, or some advertised addresses answer nothing.
struct Reach {
  unsigned interface = 0;      // interface index (if_nametoindex); 0 = every interface
  std::string interface_name;  // its name, for messages ("" for every interface)
  Family family = Family::any;
  std::string describe() const;  // "every interface, IPv4" / "eth0, IPv6"
};

// Where a server bound to `address` (an IP literal, as given to bind()) can
// be reached: "0.0.0.0" every interface over IPv4; "::" every interface over
// both families when the socket also takes IPv4 (`dual_stack`, Linux's
// default), else IPv6 only; any other address the one interface that holds
// it, in that address's family (an IPv4-mapped IPv6 address is IPv4). An
// IPv6 link-local address may carry its scope ("fe80::1%eth0").
// Error: not an IP address, or no interface holds it.
Expected<Reach> reach_of(const std::string& address, bool dual_stack = true);

struct Advertisement {
  std::string name;  // instance name; Avahi picks "name #2" on a collision
  std::string type;  // "_veneer._tcp"
  uint16_t port = 0;
  Txt txt;
  Reach reach;       // default: every interface, both families
};

// Keeps one service advertised until destroyed (Avahi's threaded poll).
class Advertiser {
 public:
  static Expected<std::unique_ptr<Advertiser>> start(const Advertisement& ad);
  ~Advertiser();
  Advertiser(const Advertiser&) = delete;
  Advertiser& operator=(const Advertiser&) = delete;
  // The name currently advertised (changes on a collision).
  std::string name() const;

  struct Impl;

 private:
  explicit Advertiser(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace veneer::dnssd
