#include "veneer/proto/discovery.hpp"

#include <charconv>

#include "veneer/proto/framing.hpp"

namespace veneer::wire {

std::map<std::string, std::string> rig_txt(const std::string& rig_name, const std::string& version,
                                           const std::string& fingerprint) {
  std::map<std::string, std::string> txt{
      {"name", rig_name}, {"version", version}, {"proto", std::to_string(kProtocolVersion)}};
  if (fingerprint.empty()) {
    txt["transport"] = "tcp";
  } else {
    txt["transport"] = "tls1.3";
    txt["certfp"] = fingerprint;  // keys of at most 9 characters (RFC 6763 6.4)
  }
  return txt;
}

RigTxt parse_rig_txt(const std::map<std::string, std::string>& txt) {
  RigTxt r;
  if (auto it = txt.find("name"); it != txt.end()) r.name = it->second;
  if (auto it = txt.find("version"); it != txt.end()) r.version = it->second;
  if (auto it = txt.find("transport"); it != txt.end()) r.transport = it->second;
  if (auto it = txt.find("certfp"); it != txt.end()) r.fingerprint = it->second;
  if (auto it = txt.find("proto"); it != txt.end()) {
    uint32_t v = 0;
    const char* end = it->second.data() + it->second.size();
    auto [p, ec] = std::from_chars(it->second.data(), end, v);
    if (ec == std::errc() && p == end) r.protocol = v;
  }
  return r;
}

const char* software_version() { return VENEER_VERSION; }

}  // namespace veneer::wire
