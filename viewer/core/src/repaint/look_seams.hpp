#pragma once
// The shaded look's seam feathering (look.hpp), private to repaint.
#include <cstddef>

#include <opencv2/core.hpp>

#include "veneer/util/expected.hpp"
#include "veneer/util/progress.hpp"

namespace veneer::repaint::detail {

struct SeamInputs {
  float log_floor = 1e-6f;  // log T is taken of max(T, log_floor) per channel
  cv::Mat xy;              // the map (CV_32FC2, -1 unmapped)
  cv::Mat source_field;    // log of the source's texture at the coarse shading's scale (CV_32FC3, source size)
  cv::Mat source_mask;     // CV_8UC1, where source_field holds
  cv::Mat destination_field;  // log of the destination's coarse shading term (CV_32FC1)
  double feather = 8;      // px: the screening's reach
  int iterations = 80;     // conjugate-gradient steps per channel at most
};

// log T re-solved: min sum over neighbour pairs (u_q - u_p - g_pq)^2 +
// sum_p (u_p - log T_p)^2 / feather^2, g_pq = log T's own difference where
// the matches continue each other (|m(q) - m(p) - (q - p)| <= 1 px), else the
// source's differences around both matches plus the destination field's;
// `texture` (T, CV_32FC3 of the map's size; only its mapped pixels are read)
// is multiplied by exp(u - log T) where mapped. `seams` counts the pairs of
// the second kind. What it holds is per mapped pixel, a few tens of bytes:
// no image of log T or of u beside T (issue 42: at 5600x3750 those were
// 250 MB each).
Status feather_seams(const SeamInputs& in, cv::Mat& texture, std::size_t& seams, const Progress& progress);

}  // namespace veneer::repaint::detail
