// Fuzz target: the Hue setup's parsers of bridge answers (/api/config, the
// lamp list, error bodies) — network input from whatever answers at an address.
#include <cstddef>
#include <cstdint>
#include <string>

#include "veneerd/hw/hue_setup.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  std::string body(reinterpret_cast<const char*>(data), size);
  (void)veneerd::hw::parse_bridge_config(body);
  (void)veneerd::hw::parse_bridge_lights(body);
  (void)veneerd::hw::parse_hue_error(body);
  return 0;
}
