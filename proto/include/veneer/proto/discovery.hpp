#pragma once
// How a rig shows itself on the LAN (DNS-SD, part of the API contract; see
// proto/README.md "Finding rigs"): service type _veneer._tcp on the API port,
// instance name = the rig's name, TXT record
//   name=<rig name>  version=<veneerd version>  proto=<protocol version>
#include <cstdint>
#include <map>
#include <string>

namespace veneer::wire {

inline constexpr const char* kServiceType = "_veneer._tcp";

// The rig's TXT record as key -> value.
std::map<std::string, std::string> rig_txt(const std::string& rig_name, const std::string& version);

// What a TXT record says of a rig; fields a rig left out stay empty / 0.
struct RigTxt {
  std::string name;
  std::string version;
  uint32_t protocol = 0;  // 0: not given or not a number
};
RigTxt parse_rig_txt(const std::map<std::string, std::string>& txt);

// veneerd's version (the project version, from CMake).
const char* software_version();

}  // namespace veneer::wire
