// The pictures of a map a user looks at (repaint.hpp).
#include <algorithm>
#include <cmath>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "veneer/io/image_io.hpp"
#include "veneer/repaint/repaint.hpp"

namespace veneer::repaint {

cv::Mat map_picture(const Map& map, cv::Size source_size) {
  cv::Mat out(map.xy.size(), CV_8UC3, cv::Scalar::all(0));
  for (int y = 0; y < map.xy.rows; ++y)
    for (int x = 0; x < map.xy.cols; ++x) {
      const cv::Vec2f m = map.xy.at<cv::Vec2f>(y, x);
      if (m[0] < 0) continue;
      out.at<cv::Vec3b>(y, x) = cv::Vec3b(255, cv::saturate_cast<uchar>(255.0 * m[1] / source_size.height),
                                          cv::saturate_cast<uchar>(255.0 * m[0] / source_size.width));
    }
  return out;
}

cv::Mat reuse_picture(const cv::Mat& counts, const cv::Mat& source_photo) {
  cv::Mat grey(counts.size(), CV_8UC3, cv::Scalar::all(0));
  if (!source_photo.empty()) {
    cv::Mat g;
    cv::cvtColor(io::tonemap_picture(source_photo), g, cv::COLOR_BGR2GRAY);
    g *= 0.45;  // dimmed so the heat stands out
    cv::cvtColor(g, grey, cv::COLOR_GRAY2BGR);
  }
  double max_count = 0;
  cv::minMaxLoc(counts, nullptr, &max_count);
  if (max_count <= 0) return grey;
  cv::Mat level(counts.size(), CV_8UC1, cv::Scalar(0));
  for (int y = 0; y < counts.rows; ++y)
    for (int x = 0; x < counts.cols; ++x) {
      const int c = counts.at<int>(y, x);
      if (c > 0) level.at<uchar>(y, x) = cv::saturate_cast<uchar>(40 + 215 * std::log1p(c) / std::log1p(max_count));
    }
  cv::Mat heat;
  cv::applyColorMap(level, heat, cv::COLORMAP_INFERNO);
  heat.copyTo(grey, counts > 0);
  return grey;
}

cv::Mat origin_picture(const Map& map, const cv::Mat& destination_photo, const cv::Mat& source_photo,
                       const std::vector<cv::Point>& points) {
  const cv::Mat d = io::tonemap_picture(destination_photo), s = io::tonemap_picture(source_photo);
  const int h = std::max(d.rows, s.rows);
  cv::Mat out(h, d.cols + s.cols, CV_8UC3, cv::Scalar::all(0));
  d.copyTo(out(cv::Rect(0, 0, d.cols, d.rows)));
  s.copyTo(out(cv::Rect(d.cols, 0, s.cols, s.rows)));
  cv::line(out, {d.cols, 0}, {d.cols, h - 1}, cv::Scalar(90, 90, 90), 1);
  const int r = std::max(2, d.cols / 200);
  for (size_t i = 0; i < points.size(); ++i) {
    const cv::Point p = points[i];
    // distinct hues around the colour wheel
    cv::Mat hsv(1, 1, CV_8UC3, cv::Scalar(static_cast<double>((i * 37) % 180), 220, 255)), bgr;
    cv::cvtColor(hsv, bgr, cv::COLOR_HSV2BGR);
    const cv::Vec3b c = bgr.at<cv::Vec3b>(0, 0);
    const cv::Scalar colour(c[0], c[1], c[2]);
    if (p.x < 0 || p.y < 0 || p.x >= map.xy.cols || p.y >= map.xy.rows || !map.valid(p.x, p.y)) {
      cv::drawMarker(out, p, cv::Scalar(0, 0, 255), cv::MARKER_TILTED_CROSS, 4 * r, 2);
      continue;
    }
    const cv::Vec2f m = map.xy.at<cv::Vec2f>(p);
    const cv::Point q(d.cols + static_cast<int>(std::lround(m[0])), static_cast<int>(std::lround(m[1])));
    cv::line(out, p, q, colour, 1, cv::LINE_AA);
    cv::circle(out, p, r, colour, -1, cv::LINE_AA);
    cv::circle(out, q, r, colour, -1, cv::LINE_AA);
  }
  return out;
}

std::vector<cv::Point> spread_points(const Map& map, int count) {
  std::vector<cv::Point> mapped;
  for (int y = 0; y < map.xy.rows; ++y)
    for (int x = 0; x < map.xy.cols; ++x)
      if (map.valid(x, y)) mapped.emplace_back(x, y);
  if (mapped.empty() || count <= 0) return {};
  const cv::Rect box = cv::boundingRect(mapped);
  const int side = std::max(1, static_cast<int>(std::ceil(std::sqrt(static_cast<double>(count)))));
  std::vector<cv::Point> out;
  for (int j = 0; j < side; ++j)
    for (int i = 0; i < side; ++i) {
      const int x = box.x + (2 * i + 1) * box.width / (2 * side), y = box.y + (2 * j + 1) * box.height / (2 * side);
      if (x < map.xy.cols && y < map.xy.rows && map.valid(x, y)) out.emplace_back(x, y);
    }
  return out;
}

cv::Mat confidence_picture(const Map& map) {
  cv::Mat pic(map.xy.size(), CV_8UC3, cv::Scalar(0, 0, 0));
  std::vector<float> d;
  for (int y = 0; y < map.xy.rows; ++y)
    for (int x = 0; x < map.xy.cols; ++x)
      if (map.valid(x, y)) d.push_back(map.distance.at<float>(y, x));
  if (d.empty()) return pic;
  auto mid = d.begin() + d.size() / 2;
  std::nth_element(d.begin(), mid, d.end());
  const float scale = std::max(*mid, 1e-6f) * 4;  // 4x the median distance and beyond: no confidence
  for (int y = 0; y < map.xy.rows; ++y)
    for (int x = 0; x < map.xy.cols; ++x) {
      if (!map.valid(x, y)) continue;  // unmapped (and background): black
      const float c = 1.0f - std::min(1.0f, map.distance.at<float>(y, x) / scale);
      const auto g = static_cast<uchar>(std::lround(255 * c));
      pic.at<cv::Vec3b>(y, x) = {g, g, g};
    }
  return pic;
}

}  // namespace veneer::repaint
