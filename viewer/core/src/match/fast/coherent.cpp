// Method `coherent`: normal-guided transfer in coherent chunks, after
// StyleBlit (Sýkora et al., Eurographics 2019).
//
// Every destination pixel first gets its nearest source pixel by the chosen
// feature (the fast exact search; for normals the patch size is not used).
// Then, for jittered seed grids of spacing 2^L ... 4, 2 (coarse to fine), the
// pixels not yet assigned are split into chunks -- those sharing a nearest
// seed s (among the 3x3 cells around their own) -- and each pixel p of a
// chunk proposes the source pixel m(s) + (p - s): the seed's match shifted by
// p's offset from the seed, i.e. the whole chunk of source copied rigidly. A
// chunk is taken whole when the mean error of its proposals (RMS, the map's
// scale; |dn| for normals; off the source object = 1) is under
// options.coherent_threshold and none of them errs more than twice that.
// Judging the chunk rather than each pixel keeps chunks whole where a few
// pixels sit near the threshold. Errors are on the raw features: a low-passed
// guide (tried: 3x3 and 5x5 masked means) cost 5-9 degrees of true normal
// agreement on the bull for no gain in coherence (bench_coherent).
// Pixels no level accepts keep their nearest match. Jitter comes from a hash
// of (seed, level, cell): the same options give the same map, and a small
// threshold change only changes the chunks whose error sits near it.
//
// Uniformity u > 0 (StyLit/Ebsynth-style): a seed picks its match among its
// 16 nearest by distance + u * uses / fair_share, where uses counts the
// destination pixels already mapped near that source pixel (true counts from
// the coarser levels plus the footprint of this level's earlier seeds), so one
// good source region is not stamped everywhere; with it each pixel is judged
// on its own error plus the reuse penalty.
#include <algorithm>
#include <cmath>

#include "engine.hpp"
#include "nearest.hpp"

namespace veneer::match::fast {

Expected<Map> run_coherent(const Object& dst, const Object& src, const MatchOptions& o, const Progress& p,
                           Stats* stats) {
  const float u = static_cast<float>(o.uniformity);
  // Without uniformity a seed takes its nearest source pixel: choosing among
  // its 8 or 32 nearest the one that fits the whole chunk best gained at most
  // 2 points of coherence at equal normal error for 3-6x the time (bench_coherent).
  const int k = u > 0 ? std::min(16, src.rows()) : 1;
  const double cap = 2.0;  // no pixel of an accepted chunk errs more than cap x threshold
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
    // seed rows [jb, je); in parallel unless the reuse counts chain them
    auto make_seeds = [&](int jb, int je) {
    for (int j = jb; j < je; ++j)
      for (int i = 0; i < gx; ++i) {
        const uint64_t r = hash3(o.seed, static_cast<uint64_t>(level), static_cast<uint64_t>(j) * gx + i);
        const cv::Point at(box.x + i * s + static_cast<int>((r & 0xffff) % s),
                           box.y + j * s + static_cast<int>(((r >> 16) & 0xffff) % s));
        const size_t cell = static_cast<size_t>(j) * gx + i;
        seed_at[cell] = at;
        const int row = dst.row_at(at.x, at.y);
        if (row < 0) continue;
        if (u <= 0) {
          seed_match[cell] = nn.ids[static_cast<size_t>(row) * k];
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
    };
    if (u <= 0)
      parallel_rows(gy, o.threads, 4, make_seeds);
    else
      make_seeds(0, gy);
    if (u <= 0) {
      // Chunks: the unassigned pixels sharing a nearest seed. Each seed's
      // source position is the one of its nearest normals (kc of them) that
      // fits its whole chunk best (mean error, off-object = 1); the chunk is
      // taken whole when that mean passes the threshold and no pixel in it
      // errs more than `cap` times the threshold.
      // (k = 1: one proposal per pixel, so no per-chunk lists are needed)
      std::vector<int> owner(n, -1), prop(n, -1);
      std::vector<float> err(n, 0.0f);
      parallel_rows(n, o.threads, 512, [&](int b, int e) {
        for (int d = b; d < e; ++d) {
          if (chosen[d] >= 0) continue;
          const cv::Point pt = dst.pixels[d];
          const int ci = (pt.x - box.x) / s, cj = (pt.y - box.y) / s;
          int best_cell = -1, best_d2 = std::numeric_limits<int>::max();
          for (int j = std::max(0, cj - 1); j <= std::min(gy - 1, cj + 1); ++j)
            for (int i = std::max(0, ci - 1); i <= std::min(gx - 1, ci + 1); ++i) {
              const int cell = j * gx + i;
              if (seed_match[cell] < 0) continue;
              const cv::Point a = seed_at[cell];
              const int d2 = (a.x - pt.x) * (a.x - pt.x) + (a.y - pt.y) * (a.y - pt.y);
              if (d2 < best_d2) best_d2 = d2, best_cell = cell;
            }
          if (best_cell < 0) continue;
          owner[d] = best_cell;
          const cv::Point m = src.pixels[seed_match[best_cell]];
          const cv::Point a = seed_at[best_cell];
          const int row = src.row_at(m.x + pt.x - a.x, m.y + pt.y - a.y);
          prop[d] = row;
          err[d] = row < 0 ? 1.0f : std::min(1.0f, std::sqrt(pixel_sq(d, row)));
        }
      });
      std::vector<double> sum(seed_at.size(), 0.0);
      std::vector<float> worst(seed_at.size(), 0.0f);
      std::vector<int> cnt(seed_at.size(), 0);
      for (int d = 0; d < n; ++d)
        if (owner[d] >= 0) {
          sum[owner[d]] += err[d];
          worst[owner[d]] = std::max(worst[owner[d]], err[d]);
          ++cnt[owner[d]];
        }
      const double thr = o.coherent_threshold;
      parallel_rows(n, o.threads, 1024, [&](int b, int e) {
        for (int d = b; d < e; ++d) {
          const int c0 = owner[d];
          if (c0 < 0 || prop[d] < 0) continue;
          if (sum[c0] / cnt[c0] < thr && worst[c0] < cap * thr) chosen[d] = prop[d];
        }
      });
      continue;
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
    // the feature distance
    const float* a = dst.flat.data() + static_cast<size_t>(d) * c;
    const float* b = src.flat.data() + static_cast<size_t>(s) * c;
    float v = 0;
    for (int i = 0; i < c; ++i) v += (a[i] - b[i]) * (a[i] - b[i]);
    map.distance.at<float>(pt.y, pt.x) = std::sqrt(v);
  }
  return map;
}

}  // namespace veneer::match::fast
