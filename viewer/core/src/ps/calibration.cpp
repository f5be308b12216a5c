// Light calibration from a mirror sphere (see calibration.hpp).
#include "veneer/ps/calibration.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include <opencv2/imgproc.hpp>

#include "veneer/ps/segmentation.hpp"

namespace veneer::ps {

Status CalibrationOptions::check() const {
  if (!(highlight_fraction > 0 && highlight_fraction < 1))
    return make_error("highlight_fraction must be in (0, 1), got " + std::to_string(highlight_fraction));
  if (!(lamp_distance_m >= 0 && lamp_distance_m <= 20))
    return make_error("lamp_distance_m must be in [0, 20] m (0 = directions only), got " +
                      std::to_string(lamp_distance_m));
  return Status::success();
}

double angle_deg(const cv::Vec3d& a, const cv::Vec3d& b) {
  const double na = cv::norm(a), nb = cv::norm(b);
  if (!(na > 0 && nb > 0)) return 180.0;
  return std::acos(std::clamp(a.dot(b) / (na * nb), -1.0, 1.0)) * 180.0 / CV_PI;
}

namespace {

// Algebraic (Kasa) fit, then Gauss-Newton on the geometric distances.
bool fit_once(const std::vector<cv::Point2d>& pts, Circle* c) {
  if (pts.size() < 3) return false;
  cv::Mat a(static_cast<int>(pts.size()), 3, CV_64F), b(static_cast<int>(pts.size()), 1, CV_64F);
  for (int i = 0; i < a.rows; ++i) {
    a.at<double>(i, 0) = pts[i].x;
    a.at<double>(i, 1) = pts[i].y;
    a.at<double>(i, 2) = 1.0;
    b.at<double>(i) = -(pts[i].x * pts[i].x + pts[i].y * pts[i].y);
  }
  // Points on a line (or fewer than 3 distinct) fit no circle.
  cv::Mat w;
  cv::SVD::compute(a, w, cv::SVD::NO_UV);
  if (!(w.at<double>(2) > 1e-9 * w.at<double>(0))) return false;
  cv::Mat s;
  if (!cv::solve(a, b, s, cv::DECOMP_SVD)) return false;
  double cx = -s.at<double>(0) / 2, cy = -s.at<double>(1) / 2;
  const double r2 = cx * cx + cy * cy - s.at<double>(2);
  if (!(r2 > 0) || !std::isfinite(r2)) return false;
  double r = std::sqrt(r2);
  for (int it = 0; it < 10; ++it) {
    cv::Matx33d jtj = cv::Matx33d::zeros();
    cv::Vec3d jtr(0, 0, 0);
    for (const auto& p : pts) {
      const double dx = p.x - cx, dy = p.y - cy, d = std::hypot(dx, dy);
      if (d < 1e-9) continue;
      const cv::Vec3d j(-dx / d, -dy / d, -1.0);  // d(residual)/d(cx, cy, r), residual = d - r
      const double res = d - r;
      jtj += j * j.t();
      jtr += j * res;
    }
    cv::Vec3d step;
    if (!cv::solve(cv::Mat(jtj), cv::Mat(-jtr), cv::Mat(step), cv::DECOMP_CHOLESKY)) break;
    cx += step[0];
    cy += step[1];
    r += step[2];
    if (cv::norm(step) < 1e-6) break;
  }
  double ss = 0;
  for (const auto& p : pts) ss += std::pow(std::hypot(p.x - cx, p.y - cy) - r, 2);
  *c = {{cx, cy}, r, std::sqrt(ss / pts.size())};
  return std::isfinite(r) && r > 0;
}

}  // namespace

Expected<Circle> fit_circle(const std::vector<cv::Point2d>& points) {
  Circle c;
  if (!fit_once(points, &c)) return make_error("no circle fits " + std::to_string(points.size()) + " points");
  // Drop far points (a stand, a reflection on the rim) and refit.
  const double keep = std::max(3.0 * c.rms, 1.0);
  std::vector<cv::Point2d> inliers;
  for (const auto& p : points)
    if (std::abs(std::hypot(p.x - c.center.x, p.y - c.center.y) - c.radius) <= keep) inliers.push_back(p);
  Circle refit;
  if (inliers.size() >= 3 && inliers.size() < points.size() && fit_once(inliers, &refit)) return refit;
  return c;
}

Expected<LightCalibration> calibrate_mirror_sphere(const io::ImageSet& set, const cv::Mat& sphere_mask,
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
  cv::Mat sphere = labels == best;

  // Outline points half way between a sphere pixel and an outside 4-neighbour
  // (sub-pixel, unbiased); the image border is not the sphere's edge.
  std::vector<cv::Point2d> outline;
  for (int y = 1; y + 1 < size.height; ++y) {
    const uint8_t* m = sphere.ptr<uint8_t>(y);
    for (int x = 1; x + 1 < size.width; ++x) {
      if (!m[x]) continue;
      if (!m[x - 1]) outline.emplace_back(x - 0.5, y);
      if (!m[x + 1]) outline.emplace_back(x + 0.5, y);
      if (!sphere.at<uint8_t>(y - 1, x)) outline.emplace_back(x, y - 0.5);
      if (!sphere.at<uint8_t>(y + 1, x)) outline.emplace_back(x, y + 0.5);
    }
  }
  auto circle = fit_circle(outline);
  if (!circle) return make_error("fitting the sphere's outline: " + circle.message());
  LightCalibration cal;
  cal.center = circle->center;
  cal.radius = circle->radius;
  cal.circle_rms_px = circle->rms;
  if (cal.circle_rms_px > 0.05 * cal.radius)
    return make_error("the sphere's outline is not a circle (" + std::to_string(cal.circle_rms_px) +
                      " px RMS off a circle of radius " + std::to_string(cal.radius) + " px)");

  cv::Mat grey, above, blobs;
  for (size_t i = 0; i < set.images.size(); ++i) {
    if (set.images[i].size() != size) return make_error("image " + std::to_string(i) + " differs in size");
    if (set.images[i].channels() == 3)
      cv::cvtColor(set.images[i], grey, cv::COLOR_BGR2GRAY);
    else
      grey = set.images[i];
    if (grey.depth() != CV_32F) grey.convertTo(grey, CV_32F);
    double maxv = 0;
    cv::Point at;
    cv::minMaxLoc(grey, nullptr, &maxv, nullptr, &at, sphere);
    if (!(maxv > 1e-4)) return make_error("image " + std::to_string(i) + " shows no highlight on the sphere");
    const double thr = options.highlight_fraction * maxv;
    // The brightest blob: a flare or a second reflection elsewhere is not the lamp.
    above = (grey >= thr) & sphere;
    cv::connectedComponents(above, blobs, 8, CV_32S);
    const int blob = blobs.at<int>(at);
    double sx = 0, sy = 0, sw = 0;
    int area = 0;
    for (int y = 0; y < size.height; ++y) {
      const float* g = grey.ptr<float>(y);
      const int* b = blobs.ptr<int>(y);
      for (int x = 0; x < size.width; ++x) {
        if (b[x] != blob) continue;
        const double wgt = g[x] - thr + 1e-6;
        sx += wgt * x;
        sy += wgt * y;
        sw += wgt;
        ++area;
      }
    }
    const cv::Point2d hl(sx / sw, sy / sw);
    cal.highlights.push_back(hl);
    cal.highlight_area.push_back(area);
    // Sphere normal at the highlight (image y goes down, rig y up); the camera
    // looks along -z, so the view vector is (0, 0, 1).
    const double nx = (hl.x - cal.center.x) / cal.radius, ny = -(hl.y - cal.center.y) / cal.radius;
    const double r2 = nx * nx + ny * ny;
    if (r2 >= 1.0)
      return make_error("image " + std::to_string(i) + ": the highlight lies on the sphere's rim (no direction)");
    const cv::Vec3d n(nx, ny, std::sqrt(1.0 - r2));
    const cv::Vec3d v(0, 0, 1);
    cv::Vec3d l = 2.0 * n.dot(v) * n - v;
    l /= cv::norm(l);
    cal.directions.push_back(l);
    if (options.lamp_distance_m > 0) cal.positions_m.push_back(l * options.lamp_distance_m);
  }
  return cal;
}

Status apply_calibration(io::ImageSet& set, const LightCalibration& calibration) {
  if (calibration.directions.size() != set.lights.size())
    return make_error("the calibration has " + std::to_string(calibration.directions.size()) +
                      " directions, the set has " + std::to_string(set.lights.size()) + " lights");
  if (!calibration.positions_m.empty() && calibration.positions_m.size() != calibration.directions.size())
    return make_error("the calibration has " + std::to_string(calibration.positions_m.size()) + " positions for " +
                      std::to_string(calibration.directions.size()) + " directions");
  for (size_t i = 0; i < set.lights.size(); ++i) {
    set.lights[i].direction = calibration.directions[i];
    if (!calibration.positions_m.empty()) set.lights[i].position_m = calibration.positions_m[i];
  }
  return Status::success();
}

}  // namespace veneer::ps
