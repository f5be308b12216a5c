#pragma once
// Light calibration from a mirror sphere: in each photo the lamp shows as a
// highlight on the chrome ball; the sphere's normal there bisects the view
// direction and the light direction, so reflecting the view vector about it
// gives the lamp's direction (orthographic camera, distant lights).
//
// The result is a user's file (`veneer calibrate` writes it, `veneer normals
// --lights` and the rig's config read it): "veneer-lights/1" JSON with one
// entry per lamp (direction, and position when the lamps' distance is known).
#include <filesystem>
#include <optional>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/io/imageset.hpp"
#include "veneer/util/expected.hpp"

namespace veneer::ps {

struct CalibrationOptions {
  double highlight_fraction = 0.9;  // pixels above this fraction of the photo's brightest
                                    // in-sphere value form the highlight (0, 1)
  double lamp_distance_m = 0;       // the lamps' distance from the sphere's centre [m]; > 0 gives
                                    // positions (direction * distance), 0 = directions only
  Status check() const;
};

struct LightCalibration {
  cv::Point2d center;                    // sphere centre in pixels (circle fitted to the outline)
  double radius = 0;                     // sphere radius in pixels
  double circle_rms_px = 0;              // RMS distance of the outline points from the fitted circle
  std::vector<cv::Point2d> highlights;   // highlight centroid per photo [px], sub-pixel
  std::vector<double> highlight_area;    // pixels in each photo's highlight blob
  std::vector<cv::Vec3d> directions;     // unit light direction per photo (rig frame)
  std::vector<cv::Vec3d> positions_m;    // per photo when a lamp distance was given, else empty
};

// The sphere comes from `sphere_mask` (CV_8UC1; empty = set.mask, else the
// brightest-sum segmentation): a circle is fitted to the outline of its
// largest component (points on the image border left out). Each photo's
// highlight is the brightest blob on the sphere (the connected pixels above
// highlight_fraction of the brightest that hold the brightest), its centroid
// weighted by brightness. Fails when no sphere or a photo without a highlight
// is found.
Expected<LightCalibration> calibrate_mirror_sphere(const io::ImageSet& set, const cv::Mat& sphere_mask = {},
                                                   const CalibrationOptions& options = {});

// A circle fitted to points by least squares (algebraic fit, then points
// farther than 3x the RMS dropped and refitted). Needs >= 3 points not on a line.
struct Circle {
  cv::Point2d center;
  double radius = 0;
  double rms = 0;
};
Expected<Circle> fit_circle(const std::vector<cv::Point2d>& points);

// Replaces the set's light directions with calibrated ones (same count
// required); positions too when the calibration has them.
Status apply_calibration(io::ImageSet& set, const LightCalibration& calibration);

// The lights file ("veneer-lights/1"): written atomically; read back with the
// sphere, highlights, directions and positions. A file with a wrong format,
// a non-unit or non-finite direction, or mismatched counts is refused.
Status write_light_calibration(const LightCalibration& calibration, const std::filesystem::path& file);
Expected<LightCalibration> read_light_calibration(const std::filesystem::path& file);
Expected<LightCalibration> parse_light_calibration(const std::string& json);
std::string light_calibration_json(const LightCalibration& calibration);

// A picture to check the calibration by eye: the brightest of the photos
// (tone mapped), the fitted circle in green, each highlight as a red cross
// numbered with its lamp (1-based), 8-bit BGR.
cv::Mat calibration_picture(const io::ImageSet& set, const LightCalibration& calibration);

// Angle in degrees between two directions (not necessarily unit).
double angle_deg(const cv::Vec3d& a, const cv::Vec3d& b);

}  // namespace veneer::ps
