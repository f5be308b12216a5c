// Fuzz target: bytes -> read_pfm_bytes. A file that reads must write back to
// a file that reads to the same bits.
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <string_view>

#include "veneer/io/image_io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  for (bool xyz : {true, false}) {
    auto image = veneer::io::read_pfm_bytes(bytes, xyz, "fuzz.pfm");
    if (!image) continue;
    auto again = veneer::io::read_pfm_bytes(veneer::io::encode_pfm(*image, xyz), xyz, "again.pfm");
    if (!again || again->size() != image->size() || again->type() != image->type()) std::abort();
    const size_t n = image->total() * image->elemSize();
    if (std::memcmp(again->data, image->data, n) != 0) std::abort();
  }
  return 0;
}
