// The fast engine's object layout (object.hpp).
#include "object.hpp"

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <limits>

#ifdef __AVX2__
#include <immintrin.h>
#endif

#include <opencv2/imgproc.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

namespace veneer::match::fast {

void parallel_rows(int n, int threads, int grain, const std::function<void(int, int)>& body) {
  if (n <= 0) return;
  auto run = [&] {
    tbb::parallel_for(tbb::blocked_range<int>(0, n, std::max(1, grain)),
                      [&](const tbb::blocked_range<int>& r) { body(r.begin(), r.end()); });
  };
  if (threads == 1) {
    body(0, n);
  } else if (threads > 1) {
    tbb::task_arena arena(threads);
    arena.execute(run);
  } else {
    run();
  }
}

Expected<Object> make_object(const ObjectView& view, Feature feature, int patch, bool need_row_of, int threads) {
  Object o;
  o.patch = patch;
  o.size = view.mask.size();
  const int w = o.size.width, h = o.size.height;
  if (feature == Feature::normals) {
    o.channels = 3;
    o.values = view.normals;  // shared; only object pixels are ever read
  } else {
    o.channels = static_cast<int>(view.images.size());
    if (o.channels < 1 || o.channels > CV_CN_MAX)
      return make_error("intensities need 1.." + std::to_string(CV_CN_MAX) + " photos, got " +
                        std::to_string(o.channels));
  }
  o.dims = o.channels * patch * patch;

  // Rows in scan order: count per image row, prefix sums, fill in parallel.
  std::vector<int> per_row(h + 1, 0);
  parallel_rows(h, threads, 16, [&](int b, int e) {
    for (int y = b; y < e; ++y) per_row[y + 1] = cv::countNonZero(view.mask.row(y));
  });
  for (int y = 0; y < h; ++y) per_row[y + 1] += per_row[y];
  const int n = per_row[h];
  if (n == 0) return make_error("the mask is empty (no object pixels)");
  o.pixels.resize(n);
  if (need_row_of) o.row_of.create(o.size, CV_32SC1);
  if (feature == Feature::intensities) o.values.create(o.size, CV_32FC(o.channels));
  const int c = o.channels;
  o.flat.resize(static_cast<size_t>(n) * c);
  std::vector<int> row_min(h, w), row_max(h, -1);
  parallel_rows(h, threads, 8, [&](int b, int e) {
    std::vector<float> grey(c);
    for (int y = b; y < e; ++y) {
      const uchar* m = view.mask.ptr<uchar>(y);
      int* ro = need_row_of ? o.row_of.ptr<int>(y) : nullptr;
      int at = per_row[y];
      if (ro) std::fill(ro, ro + w, -1);
      if (per_row[y + 1] == at) continue;  // nothing on this row
      for (int x = 0; x < w; ++x) {
        // background is most of a frame: skip it 8 mask bytes at a time
        if (x + 8 <= w) {
          uint64_t eight;
          std::memcpy(&eight, m + x, 8);
          if (!eight) {
            x += 7;
            continue;
          }
        }
        if (!m[x]) continue;
        if (ro) ro[x] = at;
        if (row_max[y] < 0) row_min[y] = x;
        row_max[y] = x;
        o.pixels[at] = cv::Point(x, y);
        float* f = o.flat.data() + static_cast<size_t>(at) * c;
        if (feature == Feature::normals) {
          const float* v = view.normals.ptr<float>(y) + 3 * x;
          f[0] = v[0], f[1] = v[1], f[2] = v[2];
        } else {
          // eq. 4.1a exactly as features.cpp computes it
          double sum = 0;
          for (int l = 0; l < c; ++l) {
            const cv::Vec3f& px = view.images[l].at<cv::Vec3f>(y, x);
            grey[l] = std::max(0.0f, (px[0] + px[1] + px[2]) / 3.0f);
            sum += grey[l];
          }
          float* v = o.values.ptr<float>(y) + static_cast<size_t>(x) * c;
          for (int l = 0; l < c; ++l) f[l] = v[l] = sum > 0 ? static_cast<float>(grey[l] / sum) : 0.0f;
        }
        ++at;
      }
    }
  });
  int x0 = w, x1 = -1, y0 = -1, y1 = -1;
  for (int y = 0; y < h; ++y) {
    if (row_max[y] < 0) continue;
    if (y0 < 0) y0 = y;
    y1 = y;
    x0 = std::min(x0, row_min[y]);
    x1 = std::max(x1, row_max[y]);
  }
  o.bbox = cv::Rect(x0, y0, x1 - x0 + 1, y1 - y0 + 1);

  o.slot.assign(n, -1);
  if (patch == 1) return o;
  // Interior: the whole patch window lies on the object. Eroded over the
  // bounding box grown by the patch radius only (the mask is 0 around it;
  // most of a frame, for a thesis-sized object).
  const int r = patch / 2;
  const cv::Rect roi = cv::Rect(o.bbox.x - r, o.bbox.y - r, o.bbox.width + 2 * r, o.bbox.height + 2 * r) &
                       cv::Rect(0, 0, w, h);
  cv::Mat on = view.mask(roi) != 0, interior;
  cv::erode(on, interior, cv::Mat::ones(patch, patch, CV_8U), cv::Point(-1, -1), 1, cv::BORDER_CONSTANT,
            cv::Scalar(0));
  int rims = 0;
  for (int i = 0; i < n; ++i)
    if (!interior.at<uchar>(o.pixels[i].y - roi.y, o.pixels[i].x - roi.x)) o.slot[i] = rims++;
  const size_t patch_w = static_cast<size_t>(patch) * c;
  {
    const size_t line = 16;  // floats per cache line
    size_t lines = (std::max(static_cast<size_t>(o.bbox.width) * c, patch_w) + line - 1) / line;
    if (lines % 2 == 0) ++lines;
    o.box_stride = lines * line;
  }
  const size_t per_band = o.box_stride / patch_w;  // rim patches side by side in a band of P rows
  const size_t bands = (static_cast<size_t>(rims) + per_band - 1) / per_band;
  const size_t rim_base = o.box_stride * o.bbox.height;
  // not zeroed: only the object's patches are ever read, and they are all written below
  o.box.resize(rim_base + bands * patch * o.box_stride);
  if (o.box.size() > std::numeric_limits<uint32_t>::max())
    return make_error("the object's patches exceed 16 GB");
  parallel_rows(o.bbox.height, threads, 32, [&](int b, int e) {
    for (int y = b; y < e; ++y)
      std::copy_n(o.values.ptr<float>(o.bbox.y + y) + static_cast<size_t>(o.bbox.x) * c,
                  static_cast<size_t>(o.bbox.width) * c, o.box.data() + y * o.box_stride);
  });
  o.patch_at.resize(n);
  parallel_rows(n, threads, 256, [&](int b, int e) {
    for (int i = b; i < e; ++i) {
      const cv::Point p = o.pixels[i];
      if (o.slot[i] < 0) {
        o.patch_at[i] = static_cast<uint32_t>(static_cast<size_t>(p.y - r - o.bbox.y) * o.box_stride +
                                              static_cast<size_t>(p.x - r - o.bbox.x) * c);
        continue;
      }
      const size_t k = static_cast<size_t>(o.slot[i]);
      const size_t at = rim_base + (k / per_band) * patch * o.box_stride + (k % per_band) * patch_w;
      o.patch_at[i] = static_cast<uint32_t>(at);
      for (int dy = -r; dy <= r; ++dy) {
        float* out = o.box.data() + at + static_cast<size_t>(dy + r) * o.box_stride;
        // the mask rows of the pixel and of its mirror through the centre (null off the frame)
        const int y = p.y + dy, ym = p.y - dy;
        const uchar* m = y >= 0 && y < h ? view.mask.ptr<uchar>(y) : nullptr;
        const uchar* mm = ym >= 0 && ym < h ? view.mask.ptr<uchar>(ym) : nullptr;
        for (int dx = -r; dx <= r; ++dx) {
          const int x = p.x + dx, xm = p.x - dx;
          const float* v;
          if (m && x >= 0 && x < w && m[x])
            v = o.values.ptr<float>(y) + static_cast<size_t>(x) * c;
          else if (mm && xm >= 0 && xm < w && mm[xm])  // mirrored through the centre (features.hpp)
            v = o.values.ptr<float>(ym) + static_cast<size_t>(xm) * c;
          else
            v = o.values.ptr<float>(p.y) + static_cast<size_t>(p.x) * c;
          for (int k2 = 0; k2 < c; ++k2) *out++ = v[k2];
        }
      }
    }
  });
  return o;
}

namespace {
#ifndef __AVX2__
// Sum of squared differences of `len` floats in 8 independent lanes (the
// compiler vectorises this without reassociating a single sum).
inline float ssd(const float* a, const float* b, int len) {
  float lane[8] = {0, 0, 0, 0, 0, 0, 0, 0};
  int i = 0;
  for (; i + 8 <= len; i += 8)
    for (int l = 0; l < 8; ++l) {
      const float t = a[i + l] - b[i + l];
      lane[l] += t * t;
    }
  float s = 0;
  for (; i < len; ++i) {
    const float t = a[i] - b[i];
    s += t * t;
  }
  return s + ((lane[0] + lane[1]) + (lane[2] + lane[3])) + ((lane[4] + lane[5]) + (lane[6] + lane[7]));
}
#endif
}  // namespace

float patch_sq(const float* a, const Object& src, int s, float bound) {
  return patch_sq_strided(a, static_cast<size_t>(src.patch) * src.channels, src, s, bound);
}

namespace {
#ifdef __AVX2__
inline float hsum(__m256 v) {
  const __m128 q = _mm_add_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps(v, 1));
  const __m128 h = _mm_add_ps(q, _mm_movehl_ps(q, q));
  return _mm_cvtss_f32(_mm_add_ss(h, _mm_shuffle_ps(h, h, 1)));
}

// A patch of P rows of W floats, fully unrolled: one accumulator per 8-float
// column of the row (the row's tail through a masked load: lanes past the row
// are neither read nor counted), so the FMAs of a row do not wait on each
// other -- one shared accumulator made every distance a chain of P * ceil(W/8)
// dependent FMAs. No early exit: without a branch on the partial sum the
// core overlaps one candidate's loads with the next one's, and those
// branches mispredicted often (PatchMatch 7x7 and normals 7x7, one thread:
// 7-18 % faster than checking the bound after rows 2 and 5, which was the
// best with one accumulator; after row 1, 2, 3 or 4 alone: all slower).
template <int P, int W>
inline float sq_fixed(const float* a, size_t a_stride, const float* b, size_t b_stride) {
  constexpr int full = W / 8, tail = W % 8, cols = full + (tail ? 1 : 0);
  static_assert(cols >= 1 && cols <= 4);
  const __m256i tail_mask = _mm256_cmpgt_epi32(_mm256_set1_epi32(tail), _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
  __m256 acc[cols];
  for (int j = 0; j < cols; ++j) acc[j] = _mm256_setzero_ps();
  auto sum = [&] {
    __m256 t = acc[0];
    for (int j = 1; j < cols; ++j) t = _mm256_add_ps(t, acc[j]);
    return hsum(t);
  };
#pragma GCC unroll 8
  for (int i = 0; i < P; ++i) {
    const float* ar = a + i * a_stride;
    const float* br = b + i * b_stride;
#pragma GCC unroll 4
    for (int j = 0; j < full; ++j) {
      const __m256 t = _mm256_sub_ps(_mm256_loadu_ps(ar + 8 * j), _mm256_loadu_ps(br + 8 * j));
      acc[j] = _mm256_fmadd_ps(t, t, acc[j]);
    }
    if constexpr (tail != 0) {
      const __m256 t = _mm256_sub_ps(_mm256_maskload_ps(ar + 8 * full, tail_mask),
                                     _mm256_maskload_ps(br + 8 * full, tail_mask));
      acc[full] = _mm256_fmadd_ps(t, t, acc[full]);
    }
  }
  return sum();
}
#endif

// One pixel: the faithful sum, bit for bit (patch_sq_ordered's order).
float sq_pixel(const float* a, size_t, const float* b, size_t, int, int w, float) {
  float sum = 0;
  for (int j = 0; j < w; ++j) {
    const float t = a[j] - b[j];
    sum += t * t;
  }
  return sum;
}

// Any patch: 8 lanes per step; the bound is checked after rows 2 and 5.
float sq_any(const float* a, size_t a_stride, const float* b, size_t b_stride, int patch, int w, float bound) {
#ifdef __AVX2__
  // the row's tail through a masked load (lanes past the row are neither read nor counted)
  const int full = w & ~7, tail = w - full;
  const __m256i tail_mask = _mm256_cmpgt_epi32(_mm256_set1_epi32(tail), _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
  __m256 acc = _mm256_setzero_ps();
  for (int i = 0; i < patch; ++i) {
    const float* ar = a + i * a_stride;
    const float* br = b + i * b_stride;
    for (int j = 0; j < full; j += 8) {
      const __m256 t = _mm256_sub_ps(_mm256_loadu_ps(ar + j), _mm256_loadu_ps(br + j));
      acc = _mm256_fmadd_ps(t, t, acc);
    }
    if (tail) {
      const __m256 t = _mm256_sub_ps(_mm256_maskload_ps(ar + full, tail_mask), _mm256_maskload_ps(br + full, tail_mask));
      acc = _mm256_fmadd_ps(t, t, acc);
    }
    if (i % 3 == 1 && i + 1 < patch) {
      const float sum = hsum(acc);
      if (sum > bound) return sum;
    }
  }
  return hsum(acc);
#else
  float sum = 0;
  for (int i = 0; i < patch; ++i) {
    sum += ssd(a + i * a_stride, b + i * b_stride, w);
    if (sum > bound) return sum;
  }
  return sum;
#endif
}

#ifdef __AVX2__
template <int P, int W>
float sq_fixed_kernel(const float* a, size_t a_stride, const float* b, size_t b_stride, int, int, float) {
  return sq_fixed<P, W>(a, a_stride, b, b_stride);
}
#endif

}  // namespace

PatchKernel patch_kernel(int patch, int channels) {
  if (patch == 1) return sq_pixel;
#ifdef __AVX2__
  if (channels == 3) {  // normals: the patch sizes the methods offer, unrolled
    switch (patch) {
      case 3: return sq_fixed_kernel<3, 9>;
      case 5: return sq_fixed_kernel<5, 15>;
      case 7: return sq_fixed_kernel<7, 21>;
      default: break;
    }
  }
#endif
  return sq_any;
}

float patch_sq_strided(const float* a, size_t a_stride, const Object& src, int s, float bound) {
  size_t stride;
  const float* b = src.patch_ptr(s, stride);
  const int w = src.patch * src.channels;
  if (src.patch == 1) return sq_pixel(a, 0, b, 0, 1, w, bound);
#ifdef __AVX2__
  if (src.channels == 3) {  // inlined here: the common case
    switch (src.patch) {
      case 3: return sq_fixed<3, 9>(a, a_stride, b, stride);
      case 5: return sq_fixed<5, 15>(a, a_stride, b, stride);
      case 7: return sq_fixed<7, 21>(a, a_stride, b, stride);
      default: break;
    }
  }
#endif
  return sq_any(a, a_stride, b, stride, src.patch, w, bound);
}

float patch_sq_ordered(const float* a, const Object& src, int s) {
  size_t stride;
  const float* b = src.patch_ptr(s, stride);
  const int w = src.patch * src.channels;
  float sum = 0;
  for (int i = 0; i < src.patch; ++i)
    for (int j = 0; j < w; ++j) {
      const float t = a[i * w + j] - b[i * stride + j];
      sum += t * t;
    }
  return sum;
}

void patch_sq_ordered_pairs(const Object& a, const int* ra, const Object& b, const int* rb, int count, float* out) {
  const float* pa[4];
  const float* pb[4];
  size_t sa[4], sb[4];
  for (int k = 0; k < 4; ++k) {
    const int at = k < count ? k : 0;  // unused lanes repeat the first pair
    pa[k] = a.patch_ptr(ra[at], sa[k]);
    pb[k] = b.patch_ptr(rb[at], sb[k]);
  }
  const int w = b.patch * b.channels;
  float s0 = 0, s1 = 0, s2 = 0, s3 = 0;
  for (int i = 0; i < b.patch; ++i) {
    const float* a0 = pa[0] + i * sa[0];
    const float* a1 = pa[1] + i * sa[1];
    const float* a2 = pa[2] + i * sa[2];
    const float* a3 = pa[3] + i * sa[3];
    const float* b0 = pb[0] + i * sb[0];
    const float* b1 = pb[1] + i * sb[1];
    const float* b2 = pb[2] + i * sb[2];
    const float* b3 = pb[3] + i * sb[3];
    for (int j = 0; j < w; ++j) {
      const float t0 = a0[j] - b0[j], t1 = a1[j] - b1[j], t2 = a2[j] - b2[j], t3 = a3[j] - b3[j];
      s0 += t0 * t0;
      s1 += t1 * t1;
      s2 += t2 * t2;
      s3 += t3 * t3;
    }
  }
  const float s[4] = {s0, s1, s2, s3};
  for (int k = 0; k < count; ++k) out[k] = s[k];
}

std::vector<int> row_starts(const Object& o) {
  std::vector<int> at(o.size.height + 1, 0);
  for (const cv::Point& p : o.pixels) ++at[p.y + 1];
  for (int y = 0; y < o.size.height; ++y) at[y + 1] += at[y];
  return at;
}

}  // namespace veneer::match::fast
