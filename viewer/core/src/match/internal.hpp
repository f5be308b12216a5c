#pragma once
// Shared helpers of the faithful matchers (not part of the public API).
#include <functional>
#include <string>

#include "veneer/match/features.hpp"
#include "veneer/match/matcher.hpp"
#include "veneer/util/expected.hpp"
#include "veneer/util/progress.hpp"

namespace veneer::match::detail {

// Runs fn(begin, end) over [0, n) in chunks on `threads` threads (0 = all),
// reporting progress between chunks (fraction mapped into [from, to]) and
// stopping with an error when cancelled.
Status parallel_chunks(int n, int threads, const Progress& progress, const std::string& stage, double from,
                       double to, const std::function<void(int, int)>& fn);

// Exact k nearest of `query` among `points` (n rows of dims), ascending by
// squared distance, ties to the lower id. Writes k ids (-1 past n) and distances.
void exact_knn(const float* points, int n, int dims, const float* query, int k, int* ids, float* sq_dists);

// An empty map for a destination of `size`: xy = -1, distance = 0.
Map empty_map(cv::Size size);

// Writes destination row `d` matched to source row `s` with squared distance `sq`.
inline void set_match(Map& map, const FeatureSet& dst, const FeatureSet& src, int d, int s, float sq) {
  const cv::Point p = dst.pixels[d];
  const cv::Point q = src.pixels[s];
  map.xy.at<cv::Vec2f>(p.y, p.x) = cv::Vec2f(static_cast<float>(q.x), static_cast<float>(q.y));
  map.distance.at<float>(p.y, p.x) = map_distance(sq, dst.patch);
}

Error cancelled_error(const std::string& stage);

}  // namespace veneer::match::detail
