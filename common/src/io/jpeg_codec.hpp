#pragma once
// JPEGs decoded by libjpeg itself (libjpeg-turbo), where the build has it
// (VENEER_HAVE_LIBJPEG): the live view's reduced decodes need no image codec
// library opened (issue 48; io/codecs.hpp). Not part of the public API.
#include <optional>
#include <string>
#include <string_view>

#include <opencv2/core.hpp>

#include "veneer/util/expected.hpp"

namespace veneer::io::detail {

// A JPEG's bytes as CV_8UC3 BGR, decoded at 1/`factor` of its size (1, 2, 4
// or 8: libjpeg's DCT scaling, as cv::IMREAD_REDUCED_COLOR_<factor> with the
// EXIF orientation ignored); an error naming `name` when it is damaged;
// nullopt when this build decodes JPEGs through OpenCV only.
std::optional<Expected<cv::Mat>> decode_jpeg8(std::string_view bytes, int factor, const std::string& name);

}  // namespace veneer::io::detail
