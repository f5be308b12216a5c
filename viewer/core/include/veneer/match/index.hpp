#pragma once
// Nearest-neighbour search over feature vectors, behind one interface so that
// the faithful FLANN index, exact brute force and the fast engine (octahedral
// grid / nanoflann) are interchangeable and testable against each other.
#include <memory>
#include <string>
#include <vector>

namespace veneer::match {

class NearestIndex {
 public:
  virtual ~NearestIndex() = default;
  // `points`: n rows of `dims` floats, row-major. The index may keep a pointer
  // to them: the caller keeps them alive while the index lives.
  virtual void build(const float* points, int n, int dims) = 0;
  // k nearest by squared Euclidean distance, sorted ascending; writes k ids
  // (-1 when fewer exist) and distances.
  virtual void knn(const float* query, int k, int* ids, float* sq_dists) const = 0;
  // The same, for a caller that knows k points within sqrt(radius_sq) of the
  // query (say, from a cheaper search): an index may prune with it from the
  // start. The result is knn()'s.
  virtual void knn_within(const float* query, int k, float radius_sq, int* ids, float* sq_dists) const {
    (void)radius_sq;
    knn(query, k, ids, sq_dists);
  }
  virtual std::string name() const = 0;
};

// "linear" (exact), "flann" (randomized kd-trees, FLANN defaults), and the fast
// engine's "grid" / "kdtree" when built in.
std::unique_ptr<NearestIndex> make_index(const std::string& kind);

}  // namespace veneer::match
