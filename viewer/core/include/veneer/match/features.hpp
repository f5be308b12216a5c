#pragma once
// Feature vectors of an object's pixels, as the thesis compares them (ch. 4):
//  - normals: x, y, z per pixel;
//  - intensities: one value per lamp, the pixel's grey intensity under that
//    lamp divided by the sum of its grey intensities under all lamps (eq. 4.1a);
//  - a patch of side 1, 3, 5 or 7 concatenates the values of its pixels
//    (eq. 4.1c), row by row. Borders are mirrored: a patch pixel that falls
//    outside the image or off the object is replaced by its mirror image
//    through the patch centre (and by the centre itself if that is off too),
//    so that background values never enter a feature.
// Only mask pixels get a row; rows are in scan order (y, then x).
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/match/matcher.hpp"
#include "veneer/util/expected.hpp"

namespace veneer::match {

struct FeatureSet {
  int dims = 0;                    // floats per row
  int patch = 1;                   // patch side
  std::vector<float> data;         // rows x dims, row-major
  std::vector<cv::Point> pixels;   // row -> pixel
  cv::Mat row_of;                  // CV_32SC1, pixel -> row, -1 off the object
  cv::Rect bbox;                   // bounding box of the object pixels
  cv::Size size;                   // image size

  int rows() const { return static_cast<int>(pixels.size()); }
  const float* row(int i) const { return data.data() + static_cast<size_t>(i) * dims; }
  int row_at(int x, int y) const {
    if (x < 0 || y < 0 || x >= size.width || y >= size.height) return -1;
    return row_of.at<int>(y, x);
  }
};

// Checks a view for `feature` (types, sizes, a non-empty mask); `role` names
// it in messages ("destination" / "source").
Status check_view(const ObjectView& view, Feature feature, const std::string& role);
// Checks that two views can be compared with `feature` (same lamps for intensities).
Status check_pair(const ObjectView& destination, const ObjectView& source, Feature feature);

// The per-pixel values before patching: CV_32FC(n) with n = 3 (normals) or
// the lamp count (intensities); zero off the object.
Expected<cv::Mat> pixel_values(const ObjectView& view, Feature feature);

Expected<FeatureSet> make_features(const ObjectView& view, Feature feature, int patch);

// Squared Euclidean distance of two rows of `dims` floats.
inline float squared_distance(const float* a, const float* b, int dims) {
  float s = 0;
  for (int i = 0; i < dims; ++i) {
    float d = a[i] - b[i];
    s += d * d;
  }
  return s;
}

// The distance written into a map: root mean square over the patch's pixels
// of the per-pixel Euclidean distance, so 1x1 and 7x7 read on the same scale
// (for normals 1x1 it is |n_d - n_s|, about the angle in radians when small).
inline float map_distance(float squared, int patch) {
  return std::sqrt(squared / static_cast<float>(patch * patch));
}

}  // namespace veneer::match
