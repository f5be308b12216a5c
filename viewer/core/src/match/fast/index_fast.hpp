#pragma once
// Internal: the fast engine's indices (see fast.hpp).
#include <algorithm>
#include <atomic>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "veneer/match/fast.hpp"
#include "veneer/match/index.hpp"

namespace veneer::match::fast {

// Exact nearest neighbours of 3-D points through an octahedral lookup over the
// sphere of directions (index_fast.cpp explains why it is exact). Points far
// from unit length, or dims != 3, are served by an internal kd-tree.
class OctGridIndex final : public NearestIndex {
 public:
  explicit OctGridIndex(int cells_per_side = 0, bool lookup = false);  // 0 = chosen from the point count
  // lookup = true: knn with k = 1 is the lookup (nearest_slot, exact = false)
  ~OctGridIndex() override;
  void build(const float* points, int n, int dims) override;
  void knn(const float* query, int k, int* ids, float* sq_dists) const override;
  std::string name() const override { return lookup_ ? "lookup" : "grid"; }
  // knn, seeded with `hint` (a source id likely to be near; k = 1 only).
  void nearest_from(const float* query, int k, int* ids, float* sq_dists, int hint) const;
  // k = 1 for a scan of near-unit queries: `slot` carries the previous
  // result's place in the index from call to call (-1 at the start); false
  // when this query needs knn() (far from unit length, or a wide search).
  // exact = false is the lookup: the best among the query's own cell's
  // entries and the previous result (when the cell has entries), which misses
  // a nearer point just across a cell edge (bench_match measures the cost).
  bool nearest_slot(const float* query, int& slot, int& id, float& sq, bool exact = true) const;

 private:
  bool nearest1(const float* query, int& slot, int& id, float& sq, bool exact) const;
  bool lookup_ = false;
  int fixed_side_ = 0, side_ = 0, n_ = 0, dims_ = 0;
  float eps_ = 0;
  const float* points_ = nullptr;
  std::vector<float> xs_, ys_, zs_;  // points sorted by cell (SoA)
  std::vector<int> ids_;
  std::vector<int> slot_of_;  // id -> its place in the sorted arrays
  std::vector<int> near_;  // uv cell -> the nearest uv cell with points (itself when it has some)
  std::vector<float> gain_col_, gain_row_;  // per column / row of cells: the bound's stretch (index_fast.cpp)
  std::vector<int> start_;  // side^2 uv cells x 2 layers (adjacent), CSR offsets
  // The k = 1 search's copy of the sorted arrays when some crowded run holds
  // equal points (a face of a box: thousands of identical normals), each kept
  // once with its lowest id (which wins their ties); empty when none does.
  struct Runs {
    int n = 0;
    std::vector<float> xs, ys, zs;
    std::vector<int> ids, start, slot_of;  // slot_of: id -> the place of its kept equal
  };
  Runs unique_;
  void build_unique();
  // What the k = 1 search reads: the deduplicated arrays when there are
  // some, else the full ones (set at the end of build()).
  struct View {
    float *xs = nullptr, *ys = nullptr, *zs = nullptr;
    int* ids = nullptr;
    const int* start = nullptr;
    int* slot_of = nullptr;
    int n = 0;
  };
  View k1_;
  // Crowded runs of the k = 1 arrays (a dense cluster of normals: a face of
  // a box seen with noise) sorted by a finer S x S grid inside their cell,
  // row by row, so that a search reads only the sub-cells within reach of its
  // best so far (index_fast.cpp).
  struct SubGrids {
    std::vector<int> at;        // node -> its S x S + 1 sub-cell starts in `start`; -1: not crowded
    std::vector<int> side;      // node -> S
    std::vector<int> start;     // places in the k = 1 arrays
    std::vector<int> near;      // (same offsets as start) sub-cell -> the nearest one with points
    std::vector<char> row_has;  // cell row -> holds a crowded node
  };
  SubGrids sub_;
  void build_subgrids();
  // A node with its own sub-grid.
  __attribute__((always_inline)) bool crowded(int node) const { return !sub_.at.empty() && sub_.at[node] >= 0; }
  // Crowded node `node` of cell (cx, cy): the sub-cell with points nearest
  // the one holding the uv point (u, v) (the nearest sub-cell when (u, v) is
  // outside the cell), as its place among the node's sub-cells.
  __attribute__((always_inline)) int nearest_sub(int node, int cx, int cy, float u, float v) const {
    const int S = sub_.side[node];
    const float scale = 0.5f * static_cast<float>(side_);
    const int sx = std::clamp(static_cast<int>(((u + 1.0f) * scale - cx) * S), 0, S - 1);
    const int sy = std::clamp(static_cast<int>(((v + 1.0f) * scale - cy) * S), 0, S - 1);
    return sub_.near[sub_.at[node] + sy * S + sx];
  }
  // Equal points a crowded run kept once (unique_): id -> the next higher id
  // of the same point, -1 at the end; empty when none were merged. A list of
  // k > 1 takes a kept point's equals after it, lowest ids first.
  std::vector<int> eq_next_;
  // 3-D bounding boxes, SoA (an empty box spans +inf..-inf), with 8 empty
  // ones of padding: of every node with points, of every sub-cell (the
  // offsets of sub_.start) and of every tile of 8 x 8 sub-cells. A wide
  // search (a query far from a few dense clusters) reads the boxes nearest
  // first instead of the empty cells between them: at once when few nodes
  // have points, else once its rings have crossed as many cells as there are
  // such nodes. Made at the first search that needs them (most sources never
  // do), once per build.
  struct Boxes {
    std::vector<float> lo[3], hi[3];
    void reset(size_t n);
    void set(size_t at, const View& v, int b, int e);  // box `at`: of points [b, e) of v
  };
  struct BoxSet {
    Boxes node, sub, tile;
    std::vector<int> node_of;  // node box -> its node
    std::vector<int> tile_at;  // node -> its first tile box (row by row); -1: not crowded
  };
  int occupied_ = 0;  // nodes with points
  mutable BoxSet boxes_;
  mutable std::atomic<bool> boxes_made_{false};
  mutable std::mutex boxes_mutex_;
  const BoxSet& boxes() const;
  std::unique_ptr<NearestIndex> fallback_;
};

std::unique_ptr<NearestIndex> make_kdtree();

}  // namespace veneer::match::fast
