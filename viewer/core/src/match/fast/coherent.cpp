// Method `coherent`: normal-guided transfer in coherent chunks, after
// StyleBlit (Sýkora et al., Eurographics 2019).
//
// Every destination pixel first gets its nearest source pixel by the chosen
// feature (the fast exact search); for normals both objects are first
// low-passed (masked 5x5 mean: the guide) and the patch size is not used. Then, for jittered seed grids of
// spacing 2^L ... 4, 2 (coarse to fine), a pixel p looks up the nearest seed
// s of the grid (among the 3x3 cells around its own), proposes the source
// pixel m(s) + (p - s) -- the seed's match shifted by p's offset from the seed,
// i.e. a whole chunk of source copied rigidly -- and keeps the coarsest
// proposal that lands on the source object with a per-pixel guide error
// (RMS, the map's scale; |dn| for normals) under options.coherent_threshold.
// Pixels no level accepts keep their nearest match. Jitter comes from a hash
// of (seed, level, cell): the same options give the same map, and a small
// threshold change only flips the pixels whose error sits near it.
//
// Uniformity u > 0 (StyLit/Ebsynth-style): a seed picks its match among its
// 16 nearest by distance + u * uses / fair_share, where uses counts the
// destination pixels already mapped near that source pixel (true counts from
// the coarser levels plus the footprint of this level's earlier seeds), so one
// good source region is not stamped everywhere.
#include <algorithm>
#include <cmath>

#include <opencv2/imgproc.hpp>

#include "engine.hpp"
#include "nearest.hpp"

namespace veneer::match::fast {

namespace {

// The guide for normals: a masked 5x5 mean of the normals, renormalised. Fine
// relief (an orange's dimples, a stone's grain) is appearance to carry along,
// not shape to match; judged on raw normals, every chunk would break on it.
Object normal_guide(const Object& o) {
  Object g = o;
  cv::Mat on = o.row_of >= 0, weight, masked = cv::Mat::zeros(o.size, CV_32FC3), sum, count;
  o.values.copyTo(masked, on);
  on.convertTo(weight, CV_32F, 1.0 / 255.0);
  cv::boxFilter(masked, sum, -1, cv::Size(5, 5), cv::Point(-1, -1), false, cv::BORDER_CONSTANT);
  cv::boxFilter(weight, count, -1, cv::Size(5, 5), cv::Point(-1, -1), false, cv::BORDER_CONSTANT);
  g.values = sum;
  g.patch = 1;
  g.dims = 3;
  g.slot.assign(g.rows(), -1);
  g.rim.clear();
  for (int i = 0; i < g.rows(); ++i) {
    const cv::Point q = g.pixels[i];
    cv::Vec3f v = sum.at<cv::Vec3f>(q.y, q.x) / std::max(1e-6f, count.at<float>(q.y, q.x));
    const float len = static_cast<float>(cv::norm(v));
    if (len > 1e-6f) v /= len;
    g.values.at<cv::Vec3f>(q.y, q.x) = v;
    for (int k = 0; k < 3; ++k) g.flat[static_cast<size_t>(i) * 3 + k] = v[k];
  }
  return g;
}

}  // namespace

Expected<Map> run_coherent(const Object& dst_raw, const Object& src_raw, const MatchOptions& o, const Progress& p,
                           Stats* stats) {
  const bool guided = o.feature == Feature::normals;
  const Object dst = guided ? normal_guide(dst_raw) : dst_raw;
  const Object src = guided ? normal_guide(src_raw) : src_raw;
  const float u = static_cast<float>(o.uniformity);
  const int k = u > 0 ? std::min(16, src.rows()) : 1;
  NearestLists nn;
  if (auto s = nearest_lists(dst, src, k, default_index(), o.threads, p, nn, stats); !s) return s.error();
  const int n = dst.rows(), c = dst.channels;
  const float thr2 = static_cast<float>(o.coherent_threshold * o.coherent_threshold);
  auto pixel_sq = [&](int d, int s) {
    const float* a = dst.flat.data() + static_cast<size_t>(d) * c;
    const float* b = src.flat.data() + static_cast<size_t>(s) * c;
    float v = 0;
    for (int i = 0; i < c; ++i) {
      const float t = a[i] - b[i];
      v += t * t;
    }
    return v;
  };

  std::vector<int> chosen(n, -1);
  const cv::Rect box = dst.bbox;
  int spacing = 2;
  while (spacing * 2 <= std::max(box.width, box.height) / 2 && spacing < 256) spacing *= 2;
  const float area = static_cast<float>(dst.patch * dst.patch);
  const float fair = std::max(1e-6f, static_cast<float>(n) / static_cast<float>(src.rows()));
  std::vector<int> uses;
  if (u > 0) uses.assign(static_cast<size_t>(src.size.area()), 0);

  for (int level = 0; spacing >= 2; ++level, spacing /= 2) {
    if (p.cancelled()) return make_error("cancelled during coherent transfer");
    p.report(0.5 + 0.5 * level / 8.0, "coherent chunks");
    const int s = spacing;
    const int gx = box.width / s + 1, gy = box.height / s + 1;
    // Seeds: one jittered point per cell; its destination row and source match.
    std::vector<cv::Point> seed_at(static_cast<size_t>(gx) * gy);
    std::vector<int> seed_match(seed_at.size(), -1);
    for (int j = 0; j < gy; ++j)
      for (int i = 0; i < gx; ++i) {
        const uint64_t r = hash3(o.seed, static_cast<uint64_t>(level), static_cast<uint64_t>(j) * gx + i);
        const cv::Point at(box.x + i * s + static_cast<int>((r & 0xffff) % s),
                           box.y + j * s + static_cast<int>(((r >> 16) & 0xffff) % s));
        const size_t cell = static_cast<size_t>(j) * gx + i;
        seed_at[cell] = at;
        const int row = dst.row_at(at.x, at.y);
        if (row < 0) continue;
        if (u <= 0) {
          seed_match[cell] = nn.ids[row];
          continue;
        }
        float best = std::numeric_limits<float>::infinity();
        for (int m = 0; m < k; ++m) {
          const int id = nn.ids[static_cast<size_t>(row) * k + m];
          if (id < 0) break;
          const cv::Point q = src.pixels[id];
          const float cost = std::sqrt(nn.sq[static_cast<size_t>(row) * k + m] / area) +
                             u * static_cast<float>(uses[static_cast<size_t>(q.y) * src.size.width + q.x]) / fair;
          if (cost < best) best = cost, seed_match[cell] = id;
        }
        // this chunk's footprint, until the true counts replace it
        const cv::Point q = src.pixels[seed_match[cell]];
        for (int y = std::max(0, q.y - s / 2); y < std::min(src.size.height, q.y + s / 2 + 1); ++y)
          for (int x = std::max(0, q.x - s / 2); x < std::min(src.size.width, q.x + s / 2 + 1); ++x)
            ++uses[static_cast<size_t>(y) * src.size.width + x];
      }
    parallel_rows(n, o.threads, 512, [&](int b, int e) {
      for (int d = b; d < e; ++d) {
        if (chosen[d] >= 0) continue;
        const cv::Point pt = dst.pixels[d];
        const int ci = (pt.x - box.x) / s, cj = (pt.y - box.y) / s;
        // seeds of the 3x3 cells around, nearest first (ties in cell order)
        int cells[9], d2s[9], count = 0;
        for (int j = std::max(0, cj - 1); j <= std::min(gy - 1, cj + 1); ++j)
          for (int i = std::max(0, ci - 1); i <= std::min(gx - 1, ci + 1); ++i) {
            const int cell = j * gx + i;
            if (seed_match[cell] < 0) continue;
            const cv::Point a = seed_at[cell];
            const int d2 = (a.x - pt.x) * (a.x - pt.x) + (a.y - pt.y) * (a.y - pt.y);
            int at = count++;
            while (at > 0 && d2s[at - 1] > d2) cells[at] = cells[at - 1], d2s[at] = d2s[at - 1], --at;
            cells[at] = cell, d2s[at] = d2;
          }
        // StyleBlit takes the nearest seed; the next ones are tried too before
        // going finer, which keeps chunks larger where the nearest fails.
        for (int t = 0; t < count && chosen[d] < 0; ++t) {
          const cv::Point m = src.pixels[seed_match[cells[t]]];
          const cv::Point a = seed_at[cells[t]];
          const int row = src.row_at(m.x + pt.x - a.x, m.y + pt.y - a.y);
          if (row < 0) continue;
          const float v = pixel_sq(d, row);
          if (u <= 0) {
            if (v < thr2) chosen[d] = row;
          } else {
            // the error plus the reuse penalty (counts frozen for the level) must pass
            const cv::Point q = src.pixels[row];
            const float cost =
                std::sqrt(v) + u * static_cast<float>(uses[static_cast<size_t>(q.y) * src.size.width + q.x]) / fair;
            if (cost * cost < thr2) chosen[d] = row;
          }
        }
      }
    });
    if (u > 0) {
      std::fill(uses.begin(), uses.end(), 0);
      for (int d = 0; d < n; ++d)
        if (chosen[d] >= 0) {
          const cv::Point q = src.pixels[chosen[d]];
          ++uses[static_cast<size_t>(q.y) * src.size.width + q.x];
        }
    }
  }
  // Pixels no chunk took keep their nearest; with uniformity, the nearest of
  // their 16 by distance + reuse penalty (live counts, scan order).
  for (int d = 0; d < n; ++d) {
    if (chosen[d] >= 0) continue;
    if (u <= 0) {
      chosen[d] = nn.ids[static_cast<size_t>(d) * k];
      continue;
    }
    float best = std::numeric_limits<float>::infinity();
    for (int m = 0; m < k; ++m) {
      const int id = nn.ids[static_cast<size_t>(d) * k + m];
      if (id < 0) break;
      const cv::Point q = src.pixels[id];
      const float cost = std::sqrt(nn.sq[static_cast<size_t>(d) * k + m] / area) +
                         u * static_cast<float>(uses[static_cast<size_t>(q.y) * src.size.width + q.x]) / fair;
      if (cost < best) best = cost, chosen[d] = id;
    }
    if (chosen[d] >= 0) {
      const cv::Point q = src.pixels[chosen[d]];
      ++uses[static_cast<size_t>(q.y) * src.size.width + q.x];
    }
  }
  Map map = new_map(dst.size);
  for (int d = 0; d < n; ++d) {
    const int s = chosen[d];
    if (s < 0) continue;
    const cv::Point pt = dst.pixels[d], q = src.pixels[s];
    map.xy.at<cv::Vec2f>(pt.y, pt.x) = cv::Vec2f(static_cast<float>(q.x), static_cast<float>(q.y));
    // the distance of the raw features (the guide only steers the chunks)
    const float* a = dst_raw.flat.data() + static_cast<size_t>(d) * c;
    const float* b = src_raw.flat.data() + static_cast<size_t>(s) * c;
    float v = 0;
    for (int i = 0; i < c; ++i) v += (a[i] - b[i]) * (a[i] - b[i]);
    map.distance.at<float>(pt.y, pt.x) = std::sqrt(v);
  }
  return map;
}

}  // namespace veneer::match::fast
