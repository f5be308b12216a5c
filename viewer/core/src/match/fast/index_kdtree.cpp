// The fast engine's kd-tree index (nanoflann): exact, any dimension; the
// octahedral grid's fallback for points off the unit sphere.
#include <memory>
#include <vector>

#include <nanoflann.hpp>

#include "index_detail.hpp"
#include "index_fast.hpp"

namespace veneer::match::fast {

using namespace detail;

namespace {

// ---------------------------------------------------------------------------
// kd-tree (nanoflann): exact, any dimension.
struct Cloud {
  const float* pts = nullptr;
  size_t n = 0;
  int dims = 0;
  size_t kdtree_get_point_count() const { return n; }
  float kdtree_get_pt(size_t i, size_t d) const { return pts[i * static_cast<size_t>(dims) + d]; }
  template <class Box>
  bool kdtree_get_bbox(Box&) const {
    return false;
  }
};

// Squared L2 accumulated dimension by dimension from 0, as squared_distance().
template <class T, class DataSource>
struct L2Ordered {
  using ElementType = T;
  using DistanceType = T;
  const DataSource& data;
  explicit L2Ordered(const DataSource& d) : data(d) {}
  T evalMetric(const T* a, size_t b, size_t size) const {
    T s = 0;
    const T* p = data.pts + b * static_cast<size_t>(data.dims);
    for (size_t i = 0; i < size; ++i) {
      T t = a[i] - p[i];
      s += t * t;
    }
    return s;
  }
  template <typename U, typename V>
  T accum_dist(const U a, const V b, const size_t) const {
    return (a - b) * (a - b);
  }
};

using Tree = nanoflann::KDTreeSingleIndexAdaptor<L2Ordered<float, Cloud>, Cloud, -1, uint32_t>;

class KdTreeIndex final : public NearestIndex {
 public:
  void build(const float* points, int n, int dims) override {
    cloud_.pts = points;
    cloud_.n = static_cast<size_t>(std::max(0, n));
    cloud_.dims = dims;
    tree_.reset();
    if (n <= 0) return;
    tree_ = std::make_unique<Tree>(dims, cloud_, nanoflann::KDTreeSingleIndexAdaptorParams(12));
  }
  void knn(const float* query, int k, int* ids, float* sq_dists) const override {
    search(query, k, std::numeric_limits<float>::max(), ids, sq_dists);
  }
  // The tree prunes with the radius from the first node: every point within
  // it is a candidate, and the k nearest are among them.
  void knn_within(const float* query, int k, float radius_sq, int* ids, float* sq_dists) const override {
    search(query, k, radius_sq, ids, sq_dists);
  }
  std::string name() const override { return "kdtree"; }

 private:
  // The result set nanoflann fills: the k best by (distance, id), ties to the
  // lower id as the brute force, whatever order the tree visits them in.
  // nanoflann offers a point only when it is strictly nearer than
  // worstDist(), and reads a subtree while its bound is at most that, so
  // worstDist() is one float past the k-th best: a point tying with it is
  // still offered (asking for a few more and re-sorting missed the lowest id
  // among many equal distances). Points at or past the radius never are.
  struct TieSet {
    Best& best;
    float radius_sq;
    float worstDist() const { return std::min(radius_sq, std::nextafter(best.worst(), kInf)); }
    bool addPoint(float dist, uint32_t id) {
      best.add(dist, static_cast<int>(id));
      return true;
    }
    bool full() const { return best.worst() < kInf; }
  };
  void search(const float* query, int k, float radius_sq, int* ids, float* sq_dists) const {
    Best best(k, ids, sq_dists);
    if (!tree_ || k <= 0) return;
    TieSet set{best, radius_sq};
    tree_->findNeighbors(set, query, nanoflann::SearchParams(32, 0.0f, false));
    best.finish();
  }
  Cloud cloud_;
  std::unique_ptr<Tree> tree_;
};


}  // namespace

std::unique_ptr<NearestIndex> make_kdtree() { return std::make_unique<KdTreeIndex>(); }

}  // namespace veneer::match::fast
