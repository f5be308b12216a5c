// Blending of overlapping chunks for repaint (fast.hpp, blend_repaint).
#include <algorithm>
#include <cmath>
#include <vector>

#include "object.hpp"
#include "veneer/match/fast.hpp"

namespace veneer::match::fast {

Expected<cv::Mat> blend_repaint(const Map& map, const cv::Mat& destination_mask, const cv::Mat& source_photo,
                                const cv::Mat& source_mask, int radius, int threads) {
  if (map.xy.type() != CV_32FC2 || map.xy.size() != destination_mask.size())
    return make_error("blend_repaint: the map must be CV_32FC2 of the destination mask's size");
  if (destination_mask.type() != CV_8UC1 || source_mask.type() != CV_8UC1)
    return make_error("blend_repaint: masks must be CV_8UC1");
  if (source_photo.type() != CV_32FC3 || source_photo.size() != source_mask.size())
    return make_error("blend_repaint: the source photo must be CV_32FC3 of the source mask's size");
  if (radius < 0 || radius > 16) return make_error("blend_repaint: radius must be in 0..16, got " + std::to_string(radius));
  const int w = destination_mask.cols, h = destination_mask.rows;
  cv::Mat out(destination_mask.size(), CV_32FC3, cv::Scalar::all(0));
  const float sigma2 = 2.0f * std::max(1.0f, radius * 0.5f) * std::max(1.0f, radius * 0.5f);
  // the Gaussian weight of every offset in the window, once per call (not per pixel)
  const int side = 2 * radius + 1;
  std::vector<float> weight_of(static_cast<size_t>(side) * side);
  for (int dy = -radius; dy <= radius; ++dy)
    for (int dx = -radius; dx <= radius; ++dx)
      weight_of[(dy + radius) * side + dx + radius] = std::exp(-static_cast<float>(dx * dx + dy * dy) / sigma2);
  parallel_rows(h, threads, 4, [&](int y0, int y1) {
    for (int y = y0; y < y1; ++y) {
      for (int x = 0; x < w; ++x) {
        if (!destination_mask.at<uchar>(y, x) || map.xy.at<cv::Vec2f>(y, x)[0] < 0) continue;
        cv::Vec3f sum(0, 0, 0);
        float weight = 0;
        for (int dy = -radius; dy <= radius; ++dy)
          for (int dx = -radius; dx <= radius; ++dx) {
            const int nx = x + dx, ny = y + dy;
            if (nx < 0 || ny < 0 || nx >= w || ny >= h || !destination_mask.at<uchar>(ny, nx)) continue;
            const cv::Vec2f m = map.xy.at<cv::Vec2f>(ny, nx);
            if (m[0] < 0) continue;
            // the neighbour's chunk, continued to this pixel
            const int qx = static_cast<int>(m[0]) - dx, qy = static_cast<int>(m[1]) - dy;
            if (qx < 0 || qy < 0 || qx >= source_mask.cols || qy >= source_mask.rows || !source_mask.at<uchar>(qy, qx))
              continue;
            const float wgt = weight_of[(dy + radius) * side + dx + radius];
            sum += wgt * source_photo.at<cv::Vec3f>(qy, qx);
            weight += wgt;
          }
        if (weight > 0) out.at<cv::Vec3f>(y, x) = sum / weight;
      }
    }
  });
  return out;
}

}  // namespace veneer::match::fast
