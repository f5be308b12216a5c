#pragma once
// Internal: the k nearest source rows of every destination row by the full
// feature distance (patches included), through the fast indices.
#include <functional>
#include <string>
#include <vector>

#include "object.hpp"
#include "veneer/match/fast.hpp"

namespace veneer::match::fast {

class OctGridIndex;

struct NearestLists {
  int k = 1;
  std::vector<int> ids;   // rows x k, ascending by (distance, id); -1 past the source's size
  std::vector<float> sq;  // squared feature distances
  // Set by the caller (1x1 searches over 3 values): called with each block of
  // rows [b, e) as soon as it is filled, while it is still in cache.
  // (only the direct searches do: `rows_reported` says whether it was called)
  std::function<void(int, int)> on_rows;
  bool rows_reported = false;
};

// `index_kind` "grid" / "kdtree" for 3-value 1x1 features; patches and
// longer vectors go through the lower-bound projection (fast.hpp).
Status nearest_lists(const Object& dst, const Object& src, int k, const std::string& index_kind, int threads,
                     const Progress& progress, NearestLists& out, Stats* stats);

// Per row, the patch's coefficients on orthonormal spatial functions, per
// channel: the mean (times P), and for P > 1 unless `means_only` the x and y
// ramps; rows of `per_row` = (1 or 3) x channels values. Orthonormal, so the
// distance of two rows' coefficients is a lower bound of their patch distance.
void patch_moments(const Object& o, int threads, std::vector<float>& out, int& per_row, bool means_only = false);

// The nearest source row of each destination row by the centre values (3
// per pixel), whatever the patch size: the octahedral grid, exact, or with
// exact = false its lookup (the query's own cell and the previous result;
// rarely misses a nearer row across a cell edge, see default_index()), about
// 3x faster. PatchMatch's start: for patches its iterations refine it anyway;
// at 1x1 it is nearly the answer, so exact.
Status nearest_centres(const Object& dst, const Object& src, int threads, const Progress& progress,
                       std::vector<int>& ids, bool exact);

// The same over a grid already built from the source, for the destination
// rows `rows` (`count` of them; nullptr: rows 0 .. count - 1): ids[r] and, if
// sq is given, sq[r] for each row r asked, the rest untouched. Rows are
// taken in fixed runs of the list, so the answers do not depend on threads.
Status nearest_rows(const OctGridIndex& grid, const Object& dst, const int* rows, int count, int threads,
                    const Progress& progress, int* ids, float* sq, bool exact);

}  // namespace veneer::match::fast
