#pragma once
// Internal: candidate lists (thesis eq. 4.2) for 3-value 1x1 features without
// materialising the sorted K-nearest lists (candidates.cpp).
#include <vector>

#include <opencv2/core.hpp>

#include "object.hpp"
#include "veneer/util/expected.hpp"
#include "veneer/util/progress.hpp"

namespace veneer::match::fast {

// True when choose_candidates3 serves the pair: 3 values per pixel, 1x1, all
// finite.
bool candidates3_applies(const Object& dst, const Object& src);

// For every destination row d: among the k source rows nearest to it by the
// squared distance of their 3 values (ties to the lower id), the one whose
// pixel is nearest to targets[d] (ties to the earlier candidate in (distance,
// id) order). Writes chosen[d] (source row) and chosen_sq[d] (its squared
// value distance); exactly the faithful method's choice. Needs dst.channels
// == src.channels == 3 and patch 1. `tested` (optional): mean value distances
// computed per destination row.
Status choose_candidates3(const Object& dst, const Object& src, int k, const std::vector<cv::Point2f>& targets,
                          int threads, const Progress& progress, std::vector<int>& chosen,
                          std::vector<float>& chosen_sq, double* tested);

}  // namespace veneer::match::fast
