// Fuzz target: a well-formed PNG around the fuzzer's header fields and rows
// -> decode_linear_image (io/png_codec through libdeflate). The first 13
// bytes are IHDR's fields (width, height, depth, colour type, compression,
// filter, interlace) as they are; the rest are the scanlines (filter byte +
// samples), deflated here and wrapped with the right CRCs, so the fuzzer
// reaches the unfiltering and the conversion instead of stopping at a CRC.
// Invariant: a decoded picture is non-empty float BGR with every value
// finite and in [0, 1]; damaged or unsupported files give an error.
#include <zlib.h>

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>
#include <vector>

#include "veneer/io/image_io.hpp"

namespace {

void put32(std::string& s, uint32_t v) {
  for (int i = 3; i >= 0; --i) s.push_back(static_cast<char>((v >> (8 * i)) & 0xff));
}

void chunk(std::string& png, const char* type, const std::string& data) {
  put32(png, static_cast<uint32_t>(data.size()));
  const std::string body = std::string(type, 4) + data;
  png += body;
  put32(png, static_cast<uint32_t>(crc32(0, reinterpret_cast<const Bytef*>(body.data()), static_cast<uInt>(body.size()))));
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 13 || size > (1u << 20)) return 0;
  const std::string ihdr(reinterpret_cast<const char*>(data), 13);
  std::vector<Bytef> deflated(compressBound(static_cast<uLong>(size - 13)));
  uLongf out_len = static_cast<uLongf>(deflated.size());
  if (compress2(deflated.data(), &out_len, data + 13, static_cast<uLong>(size - 13), 1) != Z_OK) return 0;
  std::string png("\x89PNG\r\n\x1a\n", 8);
  chunk(png, "IHDR", ihdr);
  chunk(png, "IDAT", std::string(reinterpret_cast<const char*>(deflated.data()), out_len));
  chunk(png, "IEND", "");
  auto image = veneer::io::decode_linear_image(png, "fuzz.png");
  if (!image) return 0;
  if (image->empty() || image->type() != CV_32FC3) std::abort();
  for (auto it = image->begin<cv::Vec3f>(); it != image->end<cv::Vec3f>(); ++it)
    for (int c = 0; c < 3; ++c)
      if (!std::isfinite((*it)[c]) || (*it)[c] < 0.f || (*it)[c] > 1.f) std::abort();
  return 0;
}
