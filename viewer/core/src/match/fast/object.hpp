#pragma once
// Internal: one object in the fast engine's layout. For patches (P > 1)
// every row's patch is P runs of P*C floats in `box`, box_stride floats apart:
// a patch that lies wholly on the object is read in place from the dense copy
// of the values over the bounding box, and only patches touching the object's
// rim (whose mirrored pixels follow features.hpp's rule) are stored, side by
// side in bands of P rows appended below it. One offset per row (patch_at)
// finds either. Rows are the object's pixels in scan order, as in FeatureSet,
// so ids and tie-breaks agree with the faithful methods.
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/match/matcher.hpp"
#include "veneer/util/expected.hpp"
#include "veneer/util/progress.hpp"

namespace veneer::match::fast {

// std::allocator whose resize leaves floats as they come (not zeroed): for
// buffers that are written before they are read (Object::box, a few MB).
template <class T>
struct UninitialisedAllocator : std::allocator<T> {
  template <class U>
  struct rebind {
    using other = UninitialisedAllocator<U>;
  };
  UninitialisedAllocator() = default;
  template <class U>
  UninitialisedAllocator(const UninitialisedAllocator<U>&) noexcept {}
  template <class U, class... Args>
  void construct(U* p, Args&&... args) {
    if constexpr (sizeof...(Args) == 0)
      ::new (static_cast<void*>(p)) U;
    else
      ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
};

struct Object {
  int channels = 0;  // values per pixel (3 for normals, lamps for intensities)
  int patch = 1;     // patch side
  int dims = 0;      // channels * patch^2
  cv::Size size;
  cv::Mat values;                 // CV_32FC(channels); read only at object pixels
  std::vector<cv::Point> pixels;  // row -> pixel
  cv::Mat row_of;                 // CV_32S pixel -> row (-1 off the object)
  cv::Rect bbox;
  std::vector<float> flat;        // rows x channels, the centre values (contiguous)
  std::vector<int> slot;          // row -> index of its stored rim patch, -1 = interior (read in place)
  // patch > 1: the values over bbox, copied densely (rows of box_stride floats,
  // an odd number of cache lines so that a patch's rows do not share cache
  // sets as the full image's 12 KB rows do), then the rim patches' bands
  std::vector<float, UninitialisedAllocator<float>> box;
  size_t box_stride = 0;
  std::vector<uint32_t> patch_at;  // patch > 1: row -> offset of its patch's first float in box

  int rows() const { return static_cast<int>(pixels.size()); }
  int row_at(int x, int y) const {
    if (x < 0 || y < 0 || x >= size.width || y >= size.height) return -1;
    return row_of.at<int>(y, x);
  }
  // First patch row of `row` and the stride between patch rows (in floats).
  const float* patch_ptr(int row, size_t& stride) const {
    if (patch == 1) {  // the pixel's own values
      stride = static_cast<size_t>(channels);
      return flat.data() + static_cast<size_t>(row) * channels;
    }
    stride = box_stride;
    return box.data() + patch_at[row];
  }
  // The patch of `row` as one contiguous vector (features.hpp's layout).
  void gather(int row, float* out) const {
    size_t stride;
    const float* p = patch_ptr(row, stride);
    const int w = patch * channels;
    for (int i = 0; i < patch; ++i)
      for (int j = 0; j < w; ++j) *out++ = p[i * stride + j];
  }
};

// Squared distance of two 3-value points with the same arithmetic, in the
// same order, as squared_distance() of features.hpp, so that exact searches
// report bit-identical distances to the brute force.
inline float sq3(float ax, float ay, float az, float bx, float by, float bz) {
  const float tx = ax - bx, ty = ay - by, tz = az - bz;
#ifdef __FMA__
  // what the compiler makes of that loop with fused multiply-adds (-mfma),
  // spelled out so the vector scans can match it bit for bit
  return std::fma(tz, tz, std::fma(ty, ty, tx * tx));
#else
  float s = 0;
  s += tx * tx;
  s += ty * ty;
  s += tz * tz;
  return s;
#endif
}

// Rows of `o` per image row: rows with pixel y in [y0, y1) are [at[y0], at[y1]).
std::vector<int> row_starts(const Object& o);

// Keeps the k best (distance, id) pairs in caller storage, ascending, ties to
// the lower id (the brute force's order).
struct TopK {
  int k;
  int* ids;
  float* d;
  int filled = 0;
  TopK(int k_, int* ids_, float* d_) : k(k_), ids(ids_), d(d_) {
    for (int j = 0; j < k; ++j) ids[j] = -1, d[j] = std::numeric_limits<float>::infinity();
  }
  __attribute__((always_inline)) float worst() const {
    return filled < k ? std::numeric_limits<float>::infinity() : d[k - 1];
  }
  __attribute__((always_inline)) void add(float dist, int id) {
    if (filled == k && !(dist < d[k - 1] || (dist == d[k - 1] && id < ids[k - 1]))) return;
    int j = filled < k ? filled++ : k - 1;
    while (j > 0 && (d[j - 1] > dist || (d[j - 1] == dist && ids[j - 1] > id))) {
      d[j] = d[j - 1];
      ids[j] = ids[j - 1];
      --j;
    }
    d[j] = dist;
    ids[j] = id;
  }
};

// Runs body(begin, end) over [0, n) on `threads` threads (0 = all).
void parallel_rows(int n, int threads, int grain, const std::function<void(int, int)>& body);

// The per-pixel values and the rows; `patch` 1..7; `need_row_of` fills row_of.
Expected<Object> make_object(const ObjectView& view, Feature feature, int patch, bool need_row_of, int threads);

// Squared distance of a contiguous patch `a` (dims floats) to `src` row `s`;
// may stop early and return something > `bound` once the sum exceeds it (the
// unrolled kernels of 3-value patches never do: measured faster, object.cpp).
float patch_sq(const float* a, const Object& src, int s, float bound);
// The same with `a`'s patch rows a_stride floats apart (a patch read in place).
float patch_sq_strided(const float* a, size_t a_stride, const Object& src, int s, float bound);
// The distance of patch a (rows a_stride floats apart) to patch b (rows
// b_stride apart), `patch` rows of w = patch * channels floats, stopping
// early like patch_sq: the kernel patch_sq_strided uses, for callers that
// find patches themselves. One pixel (patch 1) sums in element order.
using PatchKernel = float (*)(const float* a, size_t a_stride, const float* b, size_t b_stride, int patch, int w,
                              float bound);
PatchKernel patch_kernel(int patch, int channels);
// The same sum in strict element order, bit-identical to features.hpp's
// squared_distance() (for methods whose decisions chain, like region growing).
float patch_sq_ordered(const float* a, const Object& src, int s);
// patch_sq_ordered for `count` (<= 4) pairs at once, row ra[k] of `a` against
// row rb[k] of `b`: each sum bit-identical to patch_sq_ordered's, the chains
// interleaved so that their add latencies overlap.
void patch_sq_ordered_pairs(const Object& a, const int* ra, const Object& b, const int* rb, int count, float* out);

}  // namespace veneer::match::fast
