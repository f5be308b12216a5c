#pragma once
// How a rig shows itself on the LAN (DNS-SD, part of the API contract; see
// proto/README.md "Finding rigs"): service type _veneer._tcp on the API port,
// instance name = the rig's name, TXT record
//   name=<rig name>  version=<veneerd version>  proto=<protocol version>
//   transport=tls1.3 certfp=<certificate fingerprint>   (or transport=tcp in plain mode)
#include <cstdint>
#include <map>
#include <string>

namespace veneer::wire {

inline constexpr const char* kServiceType = "_veneer._tcp";

// The rig's TXT record as key -> value.
// `fingerprint` empty: the rig serves plain TCP (transport=tcp, no fingerprint).
std::map<std::string, std::string> rig_txt(const std::string& rig_name, const std::string& version,
                                           const std::string& fingerprint = "");

// What a TXT record says of a rig; fields a rig left out stay empty / 0.
struct RigTxt {
  std::string name;
  std::string version;
  uint32_t protocol = 0;  // 0: not given or not a number
  std::string transport;    // "tls1.3", "tcp" ("" from a rig that predates TLS: plain TCP)
  std::string fingerprint;  // the certificate's, as the rig announces it (unauthenticated: compare, never trust alone)
};
RigTxt parse_rig_txt(const std::map<std::string, std::string>& txt);

// veneerd's version (the project version, from CMake).
const char* software_version();

}  // namespace veneer::wire
