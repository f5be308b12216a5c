// Fuzz target: bytes -> decode_raw_linear (LibRaw behind the wrapper), at
// half and full size. A RAW file comes from a camera card or over the rig
// API: never trusted. A decoded photo must be CV_32FC3 with finite values.
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <string_view>

#include "veneer/io/raw.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  for (bool half : {true, false}) {
    veneer::io::RawOptions options;
    options.half_size = half;
    options.demosaic = veneer::io::Demosaic::bilinear;
    auto image = veneer::io::decode_raw_linear(bytes, options, "fuzz.dng");
    if (!image) continue;
    if (image->type() != CV_32FC3 || image->empty()) std::abort();
    if (!cv::checkRange(*image)) std::abort();
  }
  return 0;
}
