#pragma once
// Pixel conversions the io decoders share (image_io.cpp, photo_decode.cpp,
// reduced.cpp; not part of the public API).
#include <array>
#include <string>
#include <string_view>

#include <opencv2/core.hpp>

#include "veneer/util/expected.hpp"

namespace veneer::io::detail {

// A JPEG's first three bytes (SOI and the next marker's 0xFF).
bool has_jpeg_magic(std::string_view b);
// 8-bit sRGB code value -> linear, the camera JPEG's inverse transfer curve.
const std::array<float, 256>& srgb_to_linear_lut();
// 8-bit sRGB BGR (CV_8UC3) -> linear CV_32FC3 BGR through that curve.
cv::Mat srgb8_to_linear(const cv::Mat& bgr8);
// cv::imdecode of `bytes` with `flags`: OpenCV's exception becomes the error
// "<name>: cannot decode<kind>: ..." (kind e.g. " JPEG"); a file it cannot read
// gives an empty Mat, for the caller to name.
Expected<cv::Mat> imdecode_bytes(std::string_view bytes, int flags, const std::string& name, const char* kind = "");
// A decoded 8/16-bit or float Mat of 1..4 channels as CV_32FC3 BGR in [0,1]
// (grey repeated, alpha dropped); errors name `name`.
Expected<cv::Mat> to_linear_bgr(const cv::Mat& raw, const std::string& name);

}  // namespace veneer::io::detail
