#pragma once
// The PNG files a set is made of (8/16-bit grey or colour, not interlaced),
// decoded and encoded through libdeflate instead of zlib: its whole-buffer
// inflate is ~2x zlib's on the sensor noise of linear photos, and the rows go
// from filtered bytes to float BGR in one pass, with no 16-bit Mat between.
// Not part of the public API (image_io.hpp calls it; anything these do not
// take -- palette, interlaced, 1/2/4-bit -- goes through OpenCV as before).
#include <optional>
#include <string>
#include <string_view>

#include <opencv2/core.hpp>

#include "veneer/util/expected.hpp"

namespace veneer::io::detail {

// A PNG's bytes as CV_32FC3 BGR in [0, 1] (grey spread over the three
// channels, alpha dropped). nullopt when the file is of a kind this decoder
// leaves to OpenCV; an error naming `name` when it is damaged (bad chunk CRC,
// truncated, corrupt or short image data, unknown filter).
std::optional<Expected<cv::Mat>> decode_png_linear(std::string_view bytes, const std::string& name);

// A CV_16UC1/CV_16UC3 (BGR), CV_8UC1/CV_8UC3 or CV_32FC1/CV_32FC3 image as
// PNG bytes (a float image as 16-bit: [0, 1] to 0..65535, rounded, clamped,
// NaN as 0, in the same pass as the rows' byte order): deflated by libdeflate
// at `level` (0 = stored, 1 = fastest .. 12), every row Sub-filtered when
// compressed, unfiltered when stored.
std::string encode_png(const cv::Mat& image, int level = 1);

}  // namespace veneer::io::detail
