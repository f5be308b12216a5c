// Fuzz target: walking a TIFF/DNG's IFDs for its embedded JPEG preview
// (find_dng_preview; the rig serves the range it finds from files a camera
// may have written).
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "veneer/io/dng.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  auto found = veneer::io::find_dng_preview(bytes, size, "fuzz.dng");
  if (found && (found->offset + found->length > size || found->length < 4)) __builtin_trap();
  return 0;
}
