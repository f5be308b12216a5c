#pragma once
// Internal to the fast engine's indices (index_fast.cpp, index_query.cpp,
// index_kdtree.cpp): the k-best keeper, the octahedral map and the search
// constants they share.
#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>
#include <vector>

#include "object.hpp"  // TopK

namespace veneer::match::fast::detail {

inline constexpr float kInf = std::numeric_limits<float>::infinity();

// Keeps the k best (distance, id) pairs, ties to the lower id. Small k: a
// sorted array (TopK); large k: a max-heap sorted once at the end (finish()).
struct Best : TopK {
  bool heap;
  std::vector<std::pair<float, int>> h;
  Best(int k_, int* ids_, float* d_) : TopK(k_, ids_, d_), heap(k_ > 16) {
    if (heap) h.reserve(k);
  }
  __attribute__((always_inline)) float worst() const {
    if (heap) return static_cast<int>(h.size()) < k ? kInf : h.front().first;
    return TopK::worst();
  }
  __attribute__((always_inline)) int worst_id() const {
    if (heap) return static_cast<int>(h.size()) < k ? std::numeric_limits<int>::max() : h.front().second;
    return filled < k ? std::numeric_limits<int>::max() : ids[k - 1];
  }
  __attribute__((always_inline)) void add(float dist, int id) {
    if (heap) {
      const std::pair<float, int> e(dist, id);
      if (static_cast<int>(h.size()) < k) {
        h.push_back(e);
        std::push_heap(h.begin(), h.end());
      } else if (e < h.front()) {
        std::pop_heap(h.begin(), h.end());
        h.back() = e;
        std::push_heap(h.begin(), h.end());
      }
      return;
    }
    TopK::add(dist, id);
  }
  void finish() {
    if (!heap) return;
    std::sort_heap(h.begin(), h.end());
    for (size_t j = 0; j < h.size(); ++j) d[j] = h[j].first, ids[j] = h[j].second;
  }
};



// Most nodes with points for which a wide search reads their 3-D boxes at
// once instead of rings of cells (nearest_from).
constexpr long kFewBoxes = 256;

// Largest box of cells visited directly (else ring by ring): 16-49 measured
// alike on bull <- orange, 0 (rings only) 25-30 % slower.
constexpr int kBoxCells = 25;

// Largest box of cells the k = 1 path reads as rows of runs (else the cell
// by cell search of nearest_from).
constexpr int kRunCells = 49;

inline void oct_uv(float x, float y, float z, float& u, float& v) {
  const float s = std::fabs(x) + std::fabs(y) + std::fabs(z);
  u = x / s;
  v = y / s;
}

}  // namespace veneer::match::fast::detail
