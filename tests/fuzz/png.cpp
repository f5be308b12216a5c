// Fuzz target: bytes -> decode_linear_image, whose PNG files go through the
// libdeflate decoder (io/png_codec). A PNG either decodes to a non-empty
// float BGR picture whose every value is finite and in [0, 1], or gives an
// error; nothing crashes, hangs or runs out of memory. (Other kinds it takes,
// PFM above all, hold any float: only that they decode or fail is checked.)
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <string_view>

#include "veneer/io/image_io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  auto image = veneer::io::decode_linear_image(bytes, "fuzz.png");
  if (!image) return 0;
  if (image->empty() || image->type() != CV_32FC3) std::abort();
  if (size < 8 || std::memcmp(data, "\x89PNG\r\n\x1a\n", 8) != 0) return 0;
  for (auto it = image->begin<cv::Vec3f>(); it != image->end<cv::Vec3f>(); ++it)
    for (int c = 0; c < 3; ++c)
      if (!std::isfinite((*it)[c]) || (*it)[c] < 0.f || (*it)[c] > 1.f) std::abort();
  return 0;
}
