// Blending of overlapping chunks for repaint (fast.hpp, blend_plan, blend_repaint).
#include <algorithm>
#include <cmath>
#include <vector>

#include "object.hpp"
#include "veneer/match/fast.hpp"

namespace veneer::match::fast {

namespace {

// A normal to guide by: finite and not the zero vector PS leaves where it had no solve.
bool usable(const cv::Vec3f& n) {
  return std::isfinite(n[0]) && std::isfinite(n[1]) && std::isfinite(n[2]) && n.dot(n) > 1e-12f;
}

}  // namespace

Expected<BlendPlan> blend_plan(const Map& map, const cv::Mat& destination_mask, const cv::Mat& source_mask,
                               int radius, int threads, const BlendGuide* guide) {
  if (map.xy.type() != CV_32FC2 || map.xy.size() != destination_mask.size())
    return make_error("blend_repaint: the map must be CV_32FC2 of the destination mask's size");
  if (destination_mask.type() != CV_8UC1 || source_mask.type() != CV_8UC1)
    return make_error("blend_repaint: masks must be CV_8UC1");
  if (radius < 0 || radius > 16) return make_error("blend_repaint: radius must be in 0..16, got " + std::to_string(radius));
  if (guide) {
    if (guide->destination.type() != CV_32FC3 || guide->destination.size() != map.xy.size())
      return make_error("blend_repaint: the guide's destination normals must be CV_32FC3 of the map's size");
    if (guide->source.type() != CV_32FC3 || guide->source.size() != source_mask.size())
      return make_error("blend_repaint: the guide's source normals must be CV_32FC3 of the source photo's size");
    if (!(guide->sigma > 0) || !std::isfinite(guide->sigma))
      return make_error("blend_repaint: the guide's sigma must be > 0, got " + std::to_string(guide->sigma));
  }
  const int w = destination_mask.cols, h = destination_mask.rows, sw = source_mask.cols;
  BlendPlan plan;
  plan.destination_size = destination_mask.size();
  plan.source_size = source_mask.size();
  const float sigma2 = 2.0f * std::max(1.0f, radius * 0.5f) * std::max(1.0f, radius * 0.5f);
  // the Gaussian weight of every offset in the window, once per call (not per pixel)
  const int side = 2 * radius + 1;
  std::vector<float> weight_of(static_cast<size_t>(side) * side);
  for (int dy = -radius; dy <= radius; ++dy)
    for (int dx = -radius; dx <= radius; ++dx)
      weight_of[(dy + radius) * side + dx + radius] = std::exp(-static_cast<float>(dx * dx + dy * dy) / sigma2);
  const float inv_2s2 = guide ? static_cast<float>(1.0 / (2.0 * guide->sigma * guide->sigma)) : 0.0f;
  // per image row its pixels' terms, then joined in row order (the same plan for any thread count)
  struct Rows {
    std::vector<BlendPlan::Pixel> pixels;
    std::vector<BlendPlan::Term> terms;
  };
  std::vector<Rows> rows(static_cast<size_t>(h));
  parallel_rows(h, threads, 4, [&](int y0, int y1) {
    for (int y = y0; y < y1; ++y) {
      Rows& r = rows[static_cast<size_t>(y)];
      for (int x = 0; x < w; ++x) {
        if (!destination_mask.at<uchar>(y, x)) continue;
        const cv::Vec2f own = map.xy.at<cv::Vec2f>(y, x);
        if (own[0] < 0) continue;
        const cv::Vec3f nd = guide ? guide->destination.at<cv::Vec3f>(y, x) : cv::Vec3f();
        const bool guided = guide && usable(nd);
        const size_t first = r.terms.size();
        float weight = 0;
        for (int dy = -radius; dy <= radius; ++dy)
          for (int dx = -radius; dx <= radius; ++dx) {
            const int nx = x + dx, ny = y + dy;
            if (nx < 0 || ny < 0 || nx >= w || ny >= h || !destination_mask.at<uchar>(ny, nx)) continue;
            const cv::Vec2f m = map.xy.at<cv::Vec2f>(ny, nx);
            if (m[0] < 0) continue;
            // the neighbour's chunk, continued to this pixel
            const int qx = static_cast<int>(m[0]) - dx, qy = static_cast<int>(m[1]) - dy;
            if (qx < 0 || qy < 0 || qx >= sw || qy >= source_mask.rows || !source_mask.at<uchar>(qy, qx)) continue;
            float wgt = weight_of[(dy + radius) * side + dx + radius];
            if (guided) {
              const cv::Vec3f ns = guide->source.at<cv::Vec3f>(qy, qx);
              if (!usable(ns)) continue;
              const cv::Vec3f e = nd - ns;
              wgt *= std::exp(-e.dot(e) * inv_2s2);
            }
            if (!(wgt > 0)) continue;
            r.terms.push_back({qy * sw + qx, wgt});
            weight += wgt;
          }
        if (weight > 1e-20f) {
          for (size_t t = first; t < r.terms.size(); ++t) r.terms[t].weight /= weight;
        } else {  // no proposal fits (or none is on the source): the pixel's own match
          r.terms.resize(first);
          const int qx = static_cast<int>(std::lround(own[0])), qy = static_cast<int>(std::lround(own[1]));
          if (qx < 0 || qy < 0 || qx >= sw || qy >= source_mask.rows) continue;
          r.terms.push_back({qy * sw + qx, 1.0f});
        }
        r.pixels.push_back({y * w + x, static_cast<int>(r.terms.size() - first)});
      }
    }
  });
  size_t np = 0, nt = 0;
  for (const Rows& r : rows) np += r.pixels.size(), nt += r.terms.size();
  plan.pixels.reserve(np);
  plan.terms.reserve(nt);
  for (Rows& r : rows) {
    plan.pixels.insert(plan.pixels.end(), r.pixels.begin(), r.pixels.end());
    plan.terms.insert(plan.terms.end(), r.terms.begin(), r.terms.end());
    r = Rows{};
  }
  plan.first.resize(plan.pixels.size() + 1);
  plan.first[0] = 0;
  for (size_t i = 0; i < plan.pixels.size(); ++i) plan.first[i + 1] = plan.first[i] + plan.pixels[i].terms;
  return plan;
}

Expected<cv::Mat> apply_blend(const BlendPlan& plan, const cv::Mat& source_photo, int threads) {
  if (source_photo.type() != CV_32FC3 || source_photo.size() != plan.source_size)
    return make_error("blend_repaint: the source photo must be CV_32FC3 of the source mask's size");
  cv::Mat out(plan.destination_size, CV_32FC3, cv::Scalar::all(0));
  const auto* src = source_photo.ptr<cv::Vec3f>(0);
  auto* dst = out.ptr<cv::Vec3f>(0);
  const int n = static_cast<int>(plan.pixels.size());
  parallel_rows(n, threads, 4096, [&](int b, int e) {
    for (int i = b; i < e; ++i) {
      cv::Vec3f sum(0, 0, 0);
      for (int t = plan.first[i]; t < plan.first[i + 1]; ++t) sum += plan.terms[t].weight * src[plan.terms[t].source];
      dst[plan.pixels[i].destination] = sum;
    }
  });
  return out;
}

Expected<cv::Mat> blend_repaint(const Map& map, const cv::Mat& destination_mask, const cv::Mat& source_photo,
                                const cv::Mat& source_mask, int radius, int threads, const BlendGuide* guide) {
  if (source_photo.type() != CV_32FC3 || source_photo.size() != source_mask.size())
    return make_error("blend_repaint: the source photo must be CV_32FC3 of the source mask's size");
  auto plan = blend_plan(map, destination_mask, source_mask, radius, threads, guide);
  if (!plan) return plan.error();
  return apply_blend(*plan, source_photo, threads);
}

}  // namespace veneer::match::fast
