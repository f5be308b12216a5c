// Fuzz target: set.json text -> parse_manifest (no files touched). A manifest
// that parses must survive a round trip through manifest_json unchanged in its
// lights and size.
#include <cstdint>
#include <cstdlib>
#include <string>

#include "veneer/io/imageset.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  auto manifest = veneer::io::parse_manifest(text, "/fuzz/set");
  if (!manifest) {
    if (manifest.message().empty()) std::abort();  // every refusal says why
    return 0;
  }
  auto again = veneer::io::parse_manifest(veneer::io::manifest_json(manifest->set), "/fuzz/set");
  if (!again || again->set.lights.size() != manifest->set.lights.size() || again->set.size != manifest->set.size)
    std::abort();
  for (size_t i = 0; i < manifest->set.lights.size(); ++i) {
    if (again->set.lights[i].direction != manifest->set.lights[i].direction) std::abort();
  }
  return 0;
}
