#pragma once
// Small synthetic objects with known normals for the matcher tests: an
// ellipsoid cap (smooth normals), textured albedo, Lambertian photos under
// lamps of the thesis ring.
#include <cmath>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/match/matcher.hpp"

namespace veneer::match::testing {

inline std::vector<cv::Vec3f> ring_lamps(int count) {
  std::vector<cv::Vec3f> dirs;
  for (int i = 0; i < count; ++i) {
    const double a = 2 * M_PI * i / 8.0;
    cv::Vec3f d(static_cast<float>(0.47 * std::cos(a)), static_cast<float>(0.47 * std::sin(a)), 1.0f);
    dirs.push_back(d / cv::norm(d));
  }
  return dirs;
}

// An ellipse of radii (rx, ry) centred at `centre` in an image of `size`,
// normals of the ellipsoid cap; `seed` varies the albedo texture.
inline ObjectView ellipsoid(cv::Size size, cv::Point2f centre, float rx, float ry, int lamps = 7,
                            unsigned seed = 1) {
  ObjectView v;
  v.normals = cv::Mat(size, CV_32FC3, cv::Scalar::all(0));
  v.mask = cv::Mat(size, CV_8UC1, cv::Scalar(0));
  const auto dirs = ring_lamps(lamps);
  for (int l = 0; l < lamps; ++l) {
    v.images.emplace_back(size, CV_32FC3, cv::Scalar::all(0));
    v.lamps.push_back("ring-" + std::to_string(l));
  }
  for (int y = 0; y < size.height; ++y) {
    for (int x = 0; x < size.width; ++x) {
      const float u = (x - centre.x) / rx, w = -(y - centre.y) / ry;
      const float r2 = u * u + w * w;
      if (r2 >= 0.95f) continue;
      cv::Vec3f n(u, w, std::sqrt(1.0f - r2));
      n /= static_cast<float>(cv::norm(n));
      v.mask.at<uchar>(y, x) = 255;
      v.normals.at<cv::Vec3f>(y, x) = n;
      const float tex = 0.6f + 0.3f * static_cast<float>(std::sin(0.7 * x + seed) * std::cos(0.5 * y + 2 * seed));
      const cv::Vec3f albedo(tex, 0.5f * tex + 0.2f, 0.8f - 0.4f * tex);
      for (int l = 0; l < lamps; ++l) {
        const float shade = std::max(0.0f, n.dot(dirs[l]));
        v.images[l].at<cv::Vec3f>(y, x) = albedo * shade;
      }
    }
  }
  return v;
}

}  // namespace veneer::match::testing
