#pragma once
// Veneer's own demosaicing of a Bayer mosaic (raw.hpp's Demosaic::mhc): no
// LibRaw types here; raw_decode.cpp unpacks the file with LibRaw and hands
// the mosaic over. Not part of the public API.
#include <array>
#include <cstdint>

#include <opencv2/core.hpp>

namespace veneer::io::detail {

// A Bayer mosaic as the sensor stored it, and how to make it linear.
struct Mosaic {
  const uint16_t* data = nullptr;  // the sensor's samples, row after row
  int pitch = 0;                   // samples from one row to the next
  int top = 0, left = 0;           // where the picture starts inside the rows
  int width = 0, height = 0;       // the picture's size (both even)
  // The colour (0 = R, 1 = G, 2 = B) of the picture's pixel (y, x) is
  // cfa[(y & 1) * 2 + (x & 1)]: one R, one B, two G on a diagonal.
  std::array<int, 4> cfa{};
  std::array<float, 4> black{};    // per cfa position: the black level
  std::array<float, 4> scale{};    // per cfa position: white balance / (white - black)
  float rgb_cam[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};  // camera RGB -> linear sRGB
};

// True when `cfa` is a Bayer pattern this demosaic takes.
bool is_bayer(const std::array<int, 4>& cfa);

// The mosaic as CV_32FC3 BGR, 1.0 = the white level: black subtracted,
// white-balanced, clipped to [0, 1], the two missing colours of each pixel
// interpolated by Malvar, He and Cutler's gradient-corrected linear filters
// (ICASSP 2004; 5x5, about AHD's quality at a bilinear's cost), then the
// camera-to-sRGB matrix, clipped to [0, 1]. Rows run in parallel. With
// `half`, CV_16FC3: each row narrowed as it is made (no float frame).
cv::Mat demosaic_mhc(const Mosaic& mosaic, bool half = false);

}  // namespace veneer::io::detail
