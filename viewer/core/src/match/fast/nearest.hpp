#pragma once
// Internal: the k nearest source rows of every destination row by the full
// feature distance (patches included), through the fast indices.
#include <string>
#include <vector>

#include "object.hpp"
#include "veneer/match/fast.hpp"

namespace veneer::match::fast {

struct NearestLists {
  int k = 1;
  std::vector<int> ids;   // rows x k, ascending by (distance, id); -1 past the source's size
  std::vector<float> sq;  // squared feature distances
};

// `index_kind` "grid" / "kdtree" for 3-value 1x1 features; patches and
// longer vectors go through the lower-bound projection (fast.hpp).
Status nearest_lists(const Object& dst, const Object& src, int k, const std::string& index_kind, int threads,
                     const Progress& progress, NearestLists& out, Stats* stats);

}  // namespace veneer::match::fast
