#pragma once
// What a live view delivers from a linear render: 8-bit BGR through the sRGB
// curve at a fixed exposure (motion.cpp, light_path.cpp).
#include <opencv2/core.hpp>

namespace veneer::sim {

// linear CV_32FC3 BGR (clipped to [0, 1]) -> CV_8UC3 sRGB.
cv::Mat encode_live_frame(const cv::Mat& linear);

}  // namespace veneer::sim
