#include "live_frame.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>

namespace veneer::sim {

namespace {

uint8_t srgb_encode(float linear) {
  const float c = std::clamp(linear, 0.0f, 1.0f);
  const float s = c <= 0.0031308f ? 12.92f * c : 1.055f * std::pow(c, 1.0f / 2.4f) - 0.055f;
  return static_cast<uint8_t>(std::lround(s * 255.0f));
}

// 12-bit steps in linear, each to its sRGB byte.
const std::array<uint8_t, 4096>& srgb_table() {
  static const std::array<uint8_t, 4096> table = [] {
    std::array<uint8_t, 4096> t{};
    for (int i = 0; i < 4096; ++i) t[static_cast<size_t>(i)] = srgb_encode(i / 4095.0f);
    return t;
  }();
  return table;
}

}  // namespace

cv::Mat encode_live_frame(const cv::Mat& linear) {
  const auto& lut = srgb_table();
  cv::Mat bgr8(linear.size(), CV_8UC3);
  for (int y = 0; y < linear.rows; ++y) {
    const float* src = linear.ptr<float>(y);
    uint8_t* dst = bgr8.ptr<uint8_t>(y);
    for (int x = 0; x < linear.cols * 3; ++x)
      dst[x] = lut[static_cast<size_t>(std::clamp(src[x], 0.0f, 1.0f) * 4095.0f + 0.5f)];
  }
  return bgr8;
}

}  // namespace veneer::sim
