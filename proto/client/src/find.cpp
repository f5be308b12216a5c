// Finding rigs on the LAN: DNS-SD browse for _veneer._tcp (veneer_dnssd, Avahi).
#include <algorithm>

#include "veneer/dnssd/dnssd.hpp"
#include "veneer/proto/discovery.hpp"
#include "veneer/rig/client.hpp"

namespace veneer::rig {

std::string FoundRig::endpoint() const {
  const bool v6 = address.find(':') != std::string::npos;
  return (v6 ? "[" + address + "]" : address) + ":" + std::to_string(port);
}

std::string FoundRig::describe() const {
  std::string s = name + "  " + endpoint() + "  (";
  s += host.empty() ? "no host name" : host;
  if (!version.empty()) s += ", veneerd " + version;
  if (protocol) s += ", protocol " + std::to_string(protocol);
  if (!fingerprint.empty()) s += ", fingerprint " + fingerprint;
  if (transport == "tcp") s += ", PLAIN TCP";
  return s + ")";
}

Expected<std::vector<FoundRig>> find_rigs(int timeout_ms) {
  auto services = dnssd::browse(wire::kServiceType, timeout_ms);
  if (!services) return services.error();
  std::vector<FoundRig> rigs;
  for (const auto& s : *services) {
    const auto txt = wire::parse_rig_txt(s.txt);
    FoundRig r;
    r.instance = s.name;
    r.name = txt.name.empty() ? s.name : txt.name;
    r.host = s.host;
    r.address = s.address;
    r.port = s.port;
    r.version = txt.version;
    r.protocol = txt.protocol;
    r.transport = txt.transport.empty() ? "tcp" : txt.transport;
    r.fingerprint = txt.fingerprint;
    rigs.push_back(std::move(r));
  }
  std::stable_sort(rigs.begin(), rigs.end(), [](const FoundRig& a, const FoundRig& b) {
    const bool a6 = a.address.find(':') != std::string::npos, b6 = b.address.find(':') != std::string::npos;
    return std::tie(a.name, a6) < std::tie(b.name, b6);
  });
  return rigs;
}

}  // namespace veneer::rig
