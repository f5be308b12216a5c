// Fuzz target: finding the JPEG inside a RAW file the camera delivered, and
// decoding it (a file from a USB device is outside input too).
#include <cstddef>
#include <cstdint>
#include <vector>

#include "veneerd/hw/gphoto2.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  std::vector<unsigned char> raw(data, data + size);
  auto jpeg = veneerd::hw::embedded_jpeg(raw);
  if (!jpeg.empty() && jpeg.size() < (1u << 20)) (void)veneerd::hw::decode_jpeg_linear(jpeg, cv::Size(64, 64));
  return 0;
}
