// Malvar-He-Cutler demosaicing (demosaic.hpp).
#include "demosaic.hpp"

#include <algorithm>
#include <vector>

#include <opencv2/core/hal/hal.hpp>
#include <opencv2/core/utility.hpp>

#include "veneer/io/big_buffers.hpp"

namespace veneer::io::detail {

bool is_bayer(const std::array<int, 4>& cfa) {
  int count[3] = {};
  for (int c : cfa) {
    if (c < 0 || c > 2) return false;
    ++count[c];
  }
  if (count[0] != 1 || count[1] != 2 || count[2] != 1) return false;
  return (cfa[0] == 1 && cfa[3] == 1) || (cfa[1] == 1 && cfa[2] == 1);  // the greens on a diagonal
}

namespace {

constexpr int kPad = 2;  // the filters reach two pixels out

// Linear, white-balanced, clipped samples of the picture, with a border of
// kPad mirrored pixels (reflect-101 keeps each pixel's colour: x = -1
// mirrors to 1, -2 to 2).
cv::Mat linear_mosaic(const Mosaic& m) {
  cv::Mat padded(m.height + 2 * kPad, m.width + 2 * kPad, CV_32FC1);
  cv::parallel_for_(cv::Range(0, m.height), [&](const cv::Range& rows) {
    for (int y = rows.start; y < rows.end; ++y) {
      const uint16_t* s = m.data + size_t(y + m.top) * m.pitch + m.left;
      float* o = padded.ptr<float>(y + kPad) + kPad;
      const int p = (y & 1) * 2;
      const float b0 = m.black[p], b1 = m.black[p + 1], k0 = m.scale[p], k1 = m.scale[p + 1];
      for (int x = 0; x < m.width; x += 2) {
        o[x] = std::clamp((float(s[x]) - b0) * k0, 0.f, 1.f);
        o[x + 1] = std::clamp((float(s[x + 1]) - b1) * k1, 0.f, 1.f);
      }
      for (int d = 1; d <= kPad; ++d) {
        o[-d] = o[d];
        o[m.width - 1 + d] = o[m.width - 1 - d];
      }
    }
  });
  for (int d = 1; d <= kPad; ++d) {
    padded.row(kPad + d).copyTo(padded.row(kPad - d));
    padded.row(kPad + m.height - 1 - d).copyTo(padded.row(kPad + m.height - 1 + d));
  }
  return padded;
}

}  // namespace

cv::Mat demosaic_mhc(const Mosaic& m, bool half) {
  const cv::Mat padded = linear_mosaic(m);
  const size_t st = padded.step1();
  cv::Mat out;
  out.allocator = prefault_allocator();
  out.create(m.height, m.width, half ? CV_16FC3 : CV_32FC3);
  bool identity = true;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) identity = identity && m.rgb_cam[r][c] == (r == c ? 1.f : 0.f);
  cv::parallel_for_(cv::Range(0, m.height), [&](const cv::Range& rows) {
    std::vector<float> row_buffer(half ? size_t(m.width) * 3 : 0);  // a half row is made as float first
    for (int y = rows.start; y < rows.end; ++y) {
      const float* p = padded.ptr<float>(y + kPad) + kPad;
      float* const row = half ? row_buffer.data() : out.ptr<float>(y);
      float* o = row;
      for (int x = 0; x < m.width; ++x, p += 1, o += 3) {
        const int own = m.cfa[(y & 1) * 2 + (x & 1)];
        // the filters, each / 8 (the paper's Figure 2)
        auto at = [&](int dy, int dx) { return p[dy * static_cast<std::ptrdiff_t>(st) + dx]; };
        const float c = at(0, 0);
        const float cross = at(-2, 0) + at(2, 0) + at(0, -2) + at(0, 2);
        float rgb[3];
        if (own == 1) {
          // green: red and blue from its row's and its column's neighbours
          const float diag = at(-1, -1) + at(-1, 1) + at(1, -1) + at(1, 1);
          const float h = (5 * c + 4 * (at(0, -1) + at(0, 1)) - diag - (at(0, -2) + at(0, 2)) +
                           0.5f * (at(-2, 0) + at(2, 0))) * 0.125f;
          const float v = (5 * c + 4 * (at(-1, 0) + at(1, 0)) - diag - (at(-2, 0) + at(2, 0)) +
                           0.5f * (at(0, -2) + at(0, 2))) * 0.125f;
          const int row_colour = m.cfa[(y & 1) * 2 + ((x + 1) & 1)];  // the colour left and right of it
          rgb[1] = c;
          rgb[row_colour] = h;
          rgb[2 - row_colour] = v;
        } else {
          const float g = (4 * c + 2 * (at(-1, 0) + at(1, 0) + at(0, -1) + at(0, 1)) - cross) * 0.125f;
          const float other = (6 * c + 2 * (at(-1, -1) + at(-1, 1) + at(1, -1) + at(1, 1)) - 1.5f * cross) * 0.125f;
          rgb[own] = c;
          rgb[1] = g;
          rgb[2 - own] = other;
        }
        if (!identity) {
          float t[3];
          for (int r = 0; r < 3; ++r) t[r] = m.rgb_cam[r][0] * rgb[0] + m.rgb_cam[r][1] * rgb[1] + m.rgb_cam[r][2] * rgb[2];
          for (int r = 0; r < 3; ++r) rgb[r] = t[r];
        }
        o[0] = std::clamp(rgb[2], 0.f, 1.f);
        o[1] = std::clamp(rgb[1], 0.f, 1.f);
        o[2] = std::clamp(rgb[0], 0.f, 1.f);
      }
      if (half) cv::hal::cvt32f16f(row, out.ptr<cv::float16_t>(y), m.width * 3);
    }
  });
  return out;
}

}  // namespace veneer::io::detail
