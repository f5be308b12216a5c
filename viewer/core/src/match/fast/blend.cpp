// Blending of overlapping chunks for repaint (fast.hpp, blend_plan, apply_blend, blend_repaint).
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

// A pixel as floats (8-bit values stay 0..255); a float pixel as it is.
const cv::Vec3f& as_float(const cv::Vec3f& p) { return p; }
cv::Vec3f as_float(const cv::Vec3b& p) { return cv::Vec3f(p[0], p[1], p[2]); }

template <class Pixel>
void weighted_sums(const BlendPlan& plan, const cv::Mat& photo, cv::Mat& out, int threads) {
  const Pixel* src = photo.ptr<Pixel>(0);
  Pixel* dst = out.ptr<Pixel>(0);
  parallel_rows(static_cast<int>(plan.pixels.size()), threads, 4096, [&](int b, int e) {
    for (int i = b; i < e; ++i) {
      cv::Vec3f sum(0, 0, 0);
      for (int t = plan.first[i]; t < plan.first[i + 1]; ++t)
        sum += plan.terms[t].weight * as_float(src[plan.terms[t].source]);
      Pixel& o = dst[plan.pixels[i]];
      for (int c = 0; c < 3; ++c) o[c] = cv::saturate_cast<typename Pixel::value_type>(sum[c]);
    }
  });
}

}  // namespace

Expected<BlendPlan> blend_plan(const Map& map, const cv::Mat& destination_mask, const cv::Mat& source_mask,
                               int radius, int threads, const BlendGuide* guide) {
  if (map.xy.type() != CV_32FC2) return make_error("blend_repaint: the map must be CV_32FC2");
  const bool all = destination_mask.empty();
  if (!all && destination_mask.size() != map.xy.size())
    return make_error("blend_repaint: the destination mask must have the map's size");
  if ((!all && destination_mask.type() != CV_8UC1) || source_mask.type() != CV_8UC1)
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
  const int w = map.xy.cols, h = map.xy.rows, sw = source_mask.cols;
  auto in_destination = [&](int x, int y) { return all || destination_mask.at<uchar>(y, x) != 0; };
  BlendPlan plan;
  plan.destination_size = map.xy.size();
  plan.source_size = source_mask.size();
  const float sigma2 = 2.0f * std::max(1.0f, radius * 0.5f) * std::max(1.0f, radius * 0.5f);
  // the Gaussian weight of every offset in the window, once per call (not per pixel)
  const int side = 2 * radius + 1;
  std::vector<float> weight_of(static_cast<size_t>(side) * side);
  for (int dy = -radius; dy <= radius; ++dy)
    for (int dx = -radius; dx <= radius; ++dx)
      weight_of[(dy + radius) * side + dx + radius] = std::exp(-static_cast<float>(dx * dx + dy * dy) / sigma2);
  const float inv_2s2 = guide ? static_cast<float>(1.0 / (2.0 * guide->sigma * guide->sigma)) : 0.0f;
  // per image row its pixels, where each one's terms end, and the terms; then
  // joined in row order (the same plan for any thread count)
  struct Rows {
    std::vector<int> pixels, ends;
    std::vector<BlendPlan::Term> terms;
  };
  std::vector<Rows> rows(static_cast<size_t>(h));
  parallel_rows(h, threads, 4, [&](int y0, int y1) {
    for (int y = y0; y < y1; ++y) {
      Rows& r = rows[static_cast<size_t>(y)];
      for (int x = 0; x < w; ++x) {
        if (!in_destination(x, y)) continue;
        const cv::Vec2f own = map.xy.at<cv::Vec2f>(y, x);
        if (own[0] < 0) continue;
        const cv::Vec3f nd = guide ? guide->destination.at<cv::Vec3f>(y, x) : cv::Vec3f();
        const bool guided = guide && usable(nd);
        const size_t first = r.terms.size();
        // Inside a chunk the neighbours all continue to the same source
        // pixel: one term per source pixel with its Gaussian weights summed
        // (a full-resolution plan held up to 25 terms a pixel, ~1 GB), and
        // the guide's factor, which depends on the source pixel alone, is
        // worked out once per term instead of once per neighbour.
        for (int dy = -radius; dy <= radius; ++dy)
          for (int dx = -radius; dx <= radius; ++dx) {
            const int nx = x + dx, ny = y + dy;
            if (nx < 0 || ny < 0 || nx >= w || ny >= h || !in_destination(nx, ny)) continue;
            const cv::Vec2f m = map.xy.at<cv::Vec2f>(ny, nx);
            if (m[0] < 0) continue;
            // the neighbour's chunk, continued to this pixel
            const int qx = static_cast<int>(m[0]) - dx, qy = static_cast<int>(m[1]) - dy;
            if (qx < 0 || qy < 0 || qx >= sw || qy >= source_mask.rows || !source_mask.at<uchar>(qy, qx)) continue;
            const float wgt = weight_of[(dy + radius) * side + dx + radius];
            const int source = qy * sw + qx;
            bool merged = false;
            for (size_t t = first; t < r.terms.size() && !merged; ++t)
              if (r.terms[t].source == source) r.terms[t].weight += wgt, merged = true;
            if (!merged) r.terms.push_back({source, wgt});
          }
        float weight = 0;
        size_t kept = first;
        for (size_t t = first; t < r.terms.size(); ++t) {
          BlendPlan::Term term = r.terms[t];
          if (guided) {
            const cv::Vec3f ns = guide->source.at<cv::Vec3f>(term.source / sw, term.source % sw);
            if (!usable(ns)) continue;
            const cv::Vec3f e = nd - ns;
            term.weight *= std::exp(-e.dot(e) * inv_2s2);
          }
          if (!(term.weight > 0)) continue;
          weight += term.weight;
          r.terms[kept++] = term;
        }
        r.terms.resize(kept);
        if (weight > 1e-20f) {
          for (size_t t = first; t < r.terms.size(); ++t) r.terms[t].weight /= weight;
        } else {  // no proposal fits (or none is on the source): the pixel's own match (none off the photo: black)
          r.terms.resize(first);
          const int qx = static_cast<int>(std::lround(own[0])), qy = static_cast<int>(std::lround(own[1]));
          if (qx >= 0 && qy >= 0 && qx < sw && qy < source_mask.rows) r.terms.push_back({qy * sw + qx, 1.0f});
        }
        r.pixels.push_back(y * w + x);
        r.ends.push_back(static_cast<int>(r.terms.size()));
      }
    }
  });
  size_t np = 0, nt = 0;
  for (const Rows& r : rows) np += r.pixels.size(), nt += r.terms.size();
  plan.pixels.reserve(np);
  plan.first.reserve(np + 1);
  plan.terms.reserve(nt);
  plan.first.push_back(0);
  for (Rows& r : rows) {
    const int base = static_cast<int>(plan.terms.size());
    plan.pixels.insert(plan.pixels.end(), r.pixels.begin(), r.pixels.end());
    for (int end : r.ends) plan.first.push_back(base + end);
    plan.terms.insert(plan.terms.end(), r.terms.begin(), r.terms.end());
    r = Rows{};
  }
  return plan;
}

Status apply_blend(const BlendPlan& plan, const cv::Mat& source_photo, cv::Mat& out, int threads) {
  const int type = source_photo.type();
  if ((type != CV_8UC3 && type != CV_32FC3) || source_photo.size() != plan.source_size)
    return make_error("blend_repaint: the source photo must be CV_8UC3 or CV_32FC3 of the source mask's size");
  if (out.type() != type || out.size() != plan.destination_size)
    return make_error("blend_repaint: the output must have the photo's type and the map's size");
  if (type == CV_8UC3)
    weighted_sums<cv::Vec3b>(plan, source_photo, out, threads);
  else
    weighted_sums<cv::Vec3f>(plan, source_photo, out, threads);
  return {};
}

Expected<cv::Mat> blend_repaint(const Map& map, const cv::Mat& destination_mask, const cv::Mat& source_photo,
                                const cv::Mat& source_mask, int radius, int threads, const BlendGuide* guide) {
  auto plan = blend_plan(map, destination_mask, source_mask, radius, threads, guide);
  if (!plan) return plan.error();
  cv::Mat out(map.xy.size(), CV_32FC3, cv::Scalar::all(0));
  if (auto s = apply_blend(*plan, source_photo, out, threads); !s) return s.error();
  return out;
}

}  // namespace veneer::match::fast
