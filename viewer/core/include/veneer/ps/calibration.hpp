#pragma once
// Light calibration from a mirror sphere: in each photo the lamp shows as a
// highlight on the chrome ball; the sphere's normal there bisects the view
// direction and the light direction, so reflecting the view vector about it
// gives the lamp's direction (orthographic camera, distant lights).
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/io/imageset.hpp"
#include "veneer/util/expected.hpp"

namespace veneer::ps {

struct CalibrationOptions {
  double highlight_fraction = 0.9;  // pixels above this fraction of the image's brightest
                                    // in-sphere value form the highlight (0, 1)
  Status check() const;
};

struct LightCalibration {
  cv::Point2d center;                    // sphere centre in pixels
  double radius = 0;                     // sphere radius in pixels
  std::vector<cv::Point2d> highlights;   // highlight centroid per photo [px]
  std::vector<cv::Vec3d> directions;     // unit light direction per photo (rig frame)
};

// The sphere comes from `sphere_mask` (CV_8UC1; empty = set.mask, else the
// brightest-sum segmentation). Fails when no sphere or a photo without a
// highlight is found.
Expected<LightCalibration> calibrate_mirror_sphere(const ImageSet& set, const cv::Mat& sphere_mask = {},
                                                   const CalibrationOptions& options = {});

// Replaces the set's light directions with calibrated ones (same count required).
Status apply_calibration(ImageSet& set, const LightCalibration& calibration);

}  // namespace veneer::ps
