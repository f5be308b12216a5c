// Quality figures of a map (metrics.hpp).
#include "veneer/eval/metrics.hpp"

#include <algorithm>
#include <cmath>

namespace veneer::eval {

cv::Mat reuse_counts(const Map& map, cv::Size source_size) {
  cv::Mat counts(source_size, CV_32SC1, cv::Scalar(0));
  for (int y = 0; y < map.xy.rows; ++y)
    for (int x = 0; x < map.xy.cols; ++x) {
      const cv::Vec2f m = map.xy.at<cv::Vec2f>(y, x);
      if (m[0] < 0) continue;
      const int sx = static_cast<int>(std::lround(m[0])), sy = static_cast<int>(std::lround(m[1]));
      if (sx >= 0 && sy >= 0 && sx < source_size.width && sy < source_size.height) ++counts.at<int>(sy, sx);
    }
  return counts;
}

Quality evaluate(const Map& map, const cv::Mat& destination_mask, const cv::Mat& source_mask,
                 const cv::Mat& destination_normals, const cv::Mat& source_normals) {
  Quality q;
  const bool normals = !destination_normals.empty() && !source_normals.empty();
  std::vector<double> angles;
  auto mapped_at = [&](int x, int y, cv::Point& s) {
    if (x < 0 || y < 0 || x >= map.xy.cols || y >= map.xy.rows) return false;
    if (!destination_mask.at<uchar>(y, x)) return false;
    const cv::Vec2f m = map.xy.at<cv::Vec2f>(y, x);
    if (m[0] < 0) return false;
    s = {static_cast<int>(std::lround(m[0])), static_cast<int>(std::lround(m[1]))};
    return s.x >= 0 && s.y >= 0 && s.x < source_mask.cols && s.y < source_mask.rows && source_mask.at<uchar>(s) != 0;
  };
  long pairs = 0, coherent = 0;
  for (int y = 0; y < destination_mask.rows; ++y) {
    for (int x = 0; x < destination_mask.cols; ++x) {
      if (!destination_mask.at<uchar>(y, x)) continue;
      ++q.destination_pixels;
      const cv::Vec2f m = map.xy.at<cv::Vec2f>(y, x);
      if (m[0] < 0) continue;
      cv::Point s;
      if (!mapped_at(x, y, s)) {
        ++q.background_hits;
        continue;
      }
      ++q.mapped_pixels;
      if (normals) {
        const cv::Vec3f a = destination_normals.at<cv::Vec3f>(y, x), b = source_normals.at<cv::Vec3f>(s);
        const double na = cv::norm(a), nb = cv::norm(b);
        if (na > 0 && nb > 0)
          angles.push_back(std::acos(std::clamp(a.dot(b) / (na * nb), -1.0, 1.0)) * 180.0 / M_PI);
      }
      for (const cv::Point off : {cv::Point(1, 0), cv::Point(0, 1)}) {
        cv::Point t;
        if (!mapped_at(x + off.x, y + off.y, t)) continue;
        ++pairs;
        const cv::Vec2f n = map.xy.at<cv::Vec2f>(y + off.y, x + off.x);
        if (std::hypot(n[0] - m[0], n[1] - m[1]) <= 1.5) ++coherent;
      }
    }
  }
  q.coverage = q.destination_pixels ? static_cast<double>(q.mapped_pixels) / q.destination_pixels : 0.0;
  q.coherence = pairs ? static_cast<double>(coherent) / pairs : 0.0;
  if (!angles.empty()) {
    double sum = 0;
    for (double a : angles) sum += a;
    q.normal_mean_deg = sum / angles.size();
    const size_t k = std::min(angles.size() - 1, static_cast<size_t>(std::ceil(0.95 * angles.size())) - 1);
    std::nth_element(angles.begin(), angles.begin() + k, angles.end());
    q.normal_p95_deg = angles[k];
  }
  const cv::Mat counts = reuse_counts(map, source_mask.size());
  int used = 0, object = 0;
  for (int y = 0; y < counts.rows; ++y)
    for (int x = 0; x < counts.cols; ++x) {
      const int c = counts.at<int>(y, x);
      q.reuse_max = std::max(q.reuse_max, c);
      if (source_mask.at<uchar>(y, x)) {
        ++object;
        if (c > 0) ++used;
      }
    }
  q.source_used = object ? static_cast<double>(used) / object : 0.0;
  return q;
}

double psnr(const cv::Mat& transferred, const cv::Mat& reference, const cv::Mat& mask) {
  double sum = 0;
  long n = 0;
  for (int y = 0; y < mask.rows; ++y)
    for (int x = 0; x < mask.cols; ++x) {
      if (!mask.at<uchar>(y, x)) continue;
      const cv::Vec3f a = transferred.at<cv::Vec3f>(y, x), b = reference.at<cv::Vec3f>(y, x);
      for (int c = 0; c < 3; ++c) {
        const double d = std::clamp(a[c], 0.0f, 1.0f) - std::clamp(b[c], 0.0f, 1.0f);
        sum += d * d;
        ++n;
      }
    }
  if (n == 0) return 0;
  const double mse = sum / n;
  return mse <= 1e-12 ? 120.0 : 10.0 * std::log10(1.0 / mse);
}

cv::Vec3d relight_lamp_position() { return {-0.25, 0.3, 0.75}; }

bool relight_measurable(const std::string& source_scene) {
  return source_scene == "sphere-red-gloss" || source_scene == "sphere-gray";
}

}  // namespace veneer::eval
