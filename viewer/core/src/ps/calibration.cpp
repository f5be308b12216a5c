// Light calibration from a mirror sphere (see calibration.hpp).
#include "veneer/ps/calibration.hpp"

#include <cmath>
#include <string>

#include <opencv2/imgproc.hpp>

#include "veneer/ps/segmentation.hpp"

namespace veneer::ps {

Status CalibrationOptions::check() const {
  if (!(highlight_fraction > 0 && highlight_fraction < 1))
    return make_error("highlight_fraction must be in (0, 1), got " + std::to_string(highlight_fraction));
  return Status::success();
}

Expected<LightCalibration> calibrate_mirror_sphere(const ImageSet& set, const cv::Mat& sphere_mask,
                                                   const CalibrationOptions& options) {
  if (Status st = options.check(); !st) return make_error("calibration options: " + st.message());
  if (set.images.empty()) return make_error("the set has no images to calibrate from");
  const cv::Size size = set.images[0].size();
  cv::Mat mask = sphere_mask;
  if (mask.empty()) mask = set.mask;
  if (mask.empty()) {
    SegmentOptions so;
    so.method = SegmentMethod::otsu;
    auto seg = segment(set, so);
    if (!seg) return make_error("finding the sphere: " + seg.message());
    mask = seg->mask;
  }
  if (mask.size() != size || mask.type() != CV_8UC1) return make_error("the sphere mask does not match the images");
  // The sphere: the largest component of the mask.
  cv::Mat labels, stats, centroids;
  const int nl = cv::connectedComponentsWithStats(mask, labels, stats, centroids, 8, CV_32S);
  int best = 0;
  for (int l = 1; l < nl; ++l)
    if (best == 0 || stats.at<int>(l, cv::CC_STAT_AREA) > stats.at<int>(best, cv::CC_STAT_AREA)) best = l;
  if (best == 0 || stats.at<int>(best, cv::CC_STAT_AREA) < 50) return make_error("no sphere found in the mask");
  LightCalibration cal;
  const double w = stats.at<int>(best, cv::CC_STAT_WIDTH), h = stats.at<int>(best, cv::CC_STAT_HEIGHT);
  // Centre: the component's centroid; radius from its area (both robust to a
  // ragged edge), unless the bounding box says the disc is cut off.
  cal.center = cv::Point2d(centroids.at<double>(best, 0), centroids.at<double>(best, 1));
  cal.radius = std::sqrt(stats.at<int>(best, cv::CC_STAT_AREA) / CV_PI);
  if (std::abs(w - h) > 0.1 * std::max(w, h)) cal.radius = std::max(w, h) * 0.5;
  cv::Mat sphere = labels == best;

  for (size_t i = 0; i < set.images.size(); ++i) {
    cv::Mat grey;
    cv::cvtColor(set.images[i], grey, cv::COLOR_BGR2GRAY);
    double maxv = 0;
    cv::minMaxLoc(grey, nullptr, &maxv, nullptr, nullptr, sphere);
    if (!(maxv > 1e-4)) return make_error("image " + std::to_string(i) + " shows no highlight on the sphere");
    const double thr = options.highlight_fraction * maxv;
    double sx = 0, sy = 0, sw = 0;
    for (int y = 0; y < size.height; ++y) {
      const float* g = grey.ptr<float>(y);
      const uint8_t* m = sphere.ptr<uint8_t>(y);
      for (int x = 0; x < size.width; ++x) {
        if (!m[x] || g[x] < thr) continue;
        const double wgt = g[x] - thr + 1e-6;
        sx += wgt * x;
        sy += wgt * y;
        sw += wgt;
      }
    }
    const cv::Point2d hl(sx / sw, sy / sw);
    cal.highlights.push_back(hl);
    // Sphere normal at the highlight (image y goes down, rig y up); the camera
    // looks along -z, so the view vector is (0, 0, 1).
    const double nx = (hl.x - cal.center.x) / cal.radius, ny = -(hl.y - cal.center.y) / cal.radius;
    const double r2 = nx * nx + ny * ny;
    if (r2 >= 1.0)
      return make_error("image " + std::to_string(i) + ": the highlight lies on the sphere's rim (no direction)");
    const cv::Vec3d n(nx, ny, std::sqrt(1.0 - r2));
    const cv::Vec3d v(0, 0, 1);
    cv::Vec3d l = 2.0 * n.dot(v) * n - v;
    cal.directions.push_back(l / cv::norm(l));
  }
  return cal;
}

Status apply_calibration(ImageSet& set, const LightCalibration& calibration) {
  if (calibration.directions.size() != set.lights.size())
    return make_error("the calibration has " + std::to_string(calibration.directions.size()) +
                      " directions, the set has " + std::to_string(set.lights.size()) + " lights");
  for (size_t i = 0; i < set.lights.size(); ++i) set.lights[i].direction = calibration.directions[i];
  return Status::success();
}

}  // namespace veneer::ps
