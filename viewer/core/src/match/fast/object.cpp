// The fast engine's object layout (object.hpp).
#include "object.hpp"

#include <algorithm>
#include <cstdint>
#include <cstring>

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
  // Interior: the whole patch window lies on the object.
  cv::Mat on = view.mask != 0, interior;
  cv::erode(on, interior, cv::Mat::ones(patch, patch, CV_8U), cv::Point(-1, -1), 1, cv::BORDER_CONSTANT,
            cv::Scalar(0));
  int rims = 0;
  for (int i = 0; i < n; ++i)
    if (!interior.at<uchar>(o.pixels[i].y, o.pixels[i].x)) o.slot[i] = rims++;
  o.rim.resize(static_cast<size_t>(rims) * o.dims);
  const int r = patch / 2;
  auto on_object = [&](int x, int y) { return x >= 0 && y >= 0 && x < w && y < h && view.mask.at<uchar>(y, x) != 0; };
  parallel_rows(n, threads, 256, [&](int b, int e) {
    for (int i = b; i < e; ++i) {
      if (o.slot[i] < 0) continue;
      const cv::Point p = o.pixels[i];
      float* out = o.rim.data() + static_cast<size_t>(o.slot[i]) * o.dims;
      for (int dy = -r; dy <= r; ++dy) {
        for (int dx = -r; dx <= r; ++dx) {
          int x = p.x + dx, y = p.y + dy;
          if (!on_object(x, y)) {
            x = p.x - dx;  // mirrored through the centre (features.hpp)
            y = p.y - dy;
            if (!on_object(x, y)) x = p.x, y = p.y;
          }
          const float* v = o.values.ptr<float>(y) + static_cast<size_t>(x) * c;
          for (int k = 0; k < c; ++k) *out++ = v[k];
        }
      }
    }
  });
  return o;
}

namespace {
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
}  // namespace

float patch_sq(const float* a, const Object& src, int s, float bound) {
  size_t stride;
  const float* b = src.patch_ptr(s, stride);
  const int w = src.patch * src.channels;
  float sum = 0;
  for (int i = 0; i < src.patch; ++i) {
    sum += ssd(a + static_cast<size_t>(i) * w, b + i * stride, w);
    if (sum > bound) return sum;
  }
  return sum;
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

}  // namespace veneer::match::fast
