// Repainting through a map (repaint.hpp).
#include "veneer/repaint/repaint.hpp"

#include <algorithm>
#include <cmath>

#include <opencv2/core/utility.hpp>

namespace veneer::repaint {

cv::Mat median_photo(const std::vector<cv::Mat>& photos) {
  if (photos.empty()) return {};
  cv::Mat out(photos[0].size(), CV_32FC3);
  const int n = static_cast<int>(photos.size());
  cv::parallel_for_(cv::Range(0, out.rows), [&](const cv::Range& rows) {
    std::vector<float> v(n);
    for (int y = rows.start; y < rows.end; ++y)
      for (int x = 0; x < out.cols; ++x)
        for (int c = 0; c < 3; ++c) {
          for (int i = 0; i < n; ++i) v[i] = photos[i].at<cv::Vec3f>(y, x)[c];
          std::nth_element(v.begin(), v.begin() + n / 2, v.end());
          float m = v[n / 2];
          if (n % 2 == 0) m = 0.5f * (m + *std::max_element(v.begin(), v.begin() + n / 2));
          out.at<cv::Vec3f>(y, x)[c] = m;
        }
  });
  return out;
}

cv::Mat lit_photo(const std::vector<cv::Mat>& photos) {
  if (photos.empty()) return {};
  cv::Mat out(photos[0].size(), CV_32FC3);
  const int n = static_cast<int>(photos.size());
  cv::parallel_for_(cv::Range(0, out.rows), [&](const cv::Range& rows) {
    for (int y = rows.start; y < rows.end; ++y)
      for (int x = 0; x < out.cols; ++x) {
        int first = -1, second = -1;
        float g1 = -1, g2 = -1;
        for (int i = 0; i < n; ++i) {
          const cv::Vec3f v = photos[i].at<cv::Vec3f>(y, x);
          const float g = v[0] + v[1] + v[2];
          if (g > g1) second = first, g2 = g1, first = i, g1 = g;
          else if (g > g2) second = i, g2 = g;
        }
        out.at<cv::Vec3f>(y, x) = photos[second >= 0 ? second : first].at<cv::Vec3f>(y, x);
      }
  });
  return out;
}

cv::Mat repaint(const Map& map, const cv::Mat& photo, const cv::Mat& backdrop) {
  cv::Mat out = backdrop.empty() ? cv::Mat(map.xy.size(), CV_32FC3, cv::Scalar::all(0)) : backdrop.clone();
  for (int y = 0; y < map.xy.rows; ++y)
    for (int x = 0; x < map.xy.cols; ++x) {
      const cv::Vec2f m = map.xy.at<cv::Vec2f>(y, x);
      if (m[0] < 0) continue;
      const int sx = static_cast<int>(std::lround(m[0])), sy = static_cast<int>(std::lround(m[1]));
      if (sx < photo.cols && sy < photo.rows) out.at<cv::Vec3f>(y, x) = photo.at<cv::Vec3f>(sy, sx);
    }
  return out;
}

Expected<cv::Mat> repaint_planned(const fast::BlendPlan& plan, const cv::Mat& photo, const cv::Mat& backdrop) {
  cv::Mat out = backdrop.empty() ? cv::Mat(plan.destination_size, CV_32FC3, cv::Scalar::all(0)) : backdrop.clone();
  if (auto s = fast::apply_blend(plan, photo, out); !s) return s.error();
  return out;
}

Expected<cv::Mat> repaint_blended(const Map& map, const cv::Mat& photo, const cv::Mat& source_mask, int radius,
                                  const cv::Mat& backdrop, const fast::BlendGuide* guide) {
  if (radius == 0) return repaint(map, photo, backdrop);
  const cv::Mat smask = source_mask.empty() ? cv::Mat(photo.size(), CV_8UC1, cv::Scalar(255)) : source_mask;
  auto plan = fast::blend_plan(map, {}, smask, radius, 0, guide);  // every mapped pixel
  if (!plan) return plan.error();
  return repaint_planned(*plan, photo, backdrop);
}

}  // namespace veneer::repaint
