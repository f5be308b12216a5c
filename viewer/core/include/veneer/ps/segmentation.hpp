#pragma once
// Segmentation of the object from the background of an image set.
//
// The thesis threshold: the object is where the summed intensity of all the
// set's photos (ambient removed) is bright enough; the threshold may be given,
// or found by Otsu's method on the summed image. An optional rectangle limits
// the object; then the mask is cleaned: specks (small components) removed,
// small holes filled. A set that supplies its own mask (DiLiGenT mask.png)
// uses it by default.
#include <optional>
#include <string>

#include <opencv2/core.hpp>

#include "veneer/io/imageset.hpp"
#include "veneer/util/expected.hpp"

namespace veneer::ps {

enum class SegmentMethod {
  automatic,  // set.mask when present, else otsu
  supplied,   // set.mask (fails when the set has none)
  threshold,  // fixed threshold on the mean grey intensity over lamps
  otsu,       // Otsu's threshold on the log of the mean grey intensity over lamps
  none,       // every pixel (then the rectangle and cleaning still apply)
};
const char* segment_method_name(SegmentMethod);
Expected<SegmentMethod> parse_segment_method(const std::string&);

struct SegmentOptions {
  SegmentMethod method = SegmentMethod::automatic;  // see SegmentMethod
  double threshold = 0.02;      // `threshold`: mean grey intensity over lamps (1 = full scale) [0, 1)
  std::optional<cv::Rect> rect; // pixels outside are background (clipped to the image; must overlap it)
  bool clean = true;            // remove specks and fill holes
  int open_radius = 1;          // clean: morphological opening radius [px] before components (0 = off)
  double min_component_fraction = 0.002;  // clean: components smaller than this fraction of the
                                          // image area are removed [0, 1)
  double max_hole_fraction = 0.002;       // clean: background holes (not touching the border)
                                          // smaller than this fraction of the image are filled [0, 1)
  bool subtract_ambient = true; // subtract set.ambient when present
  Status check() const;
};

struct Segmentation {
  cv::Mat mask;           // CV_8UC1, 255 = object
  cv::Mat summed;         // CV_32FC1 mean grey intensity over lamps (empty for `supplied`)
  double threshold = 0;   // threshold used (threshold/otsu)
  SegmentMethod method_used = SegmentMethod::supplied;
  int object_pixels = 0;
};

// Fails for: a set with no images, `supplied` without set.mask, a rectangle
// outside the image, an empty result mask (nothing is object), bad options.
Expected<Segmentation> segment(const ImageSet& set, const SegmentOptions& options = {});

// The cleaning step on its own (CV_8UC1 in, CV_8UC1 out).
cv::Mat clean_mask(const cv::Mat& mask, const SegmentOptions& options);

}  // namespace veneer::ps
