// k nearest by the full feature distance (nearest.hpp).
//
// 1x1 features of 3 values (normals): the exact index over the values.
// Everything else: each patch vector v (P*P pixels x C channels) is projected
// on orthonormal functions -- per channel the patch mean (times P) and, for
// P > 1, its x and y ramps -- and the C channels of each onto their 3
// principal directions W (identity when C = 3): y has 3 (1x1) or 9 values.
// The rows of that linear map are orthonormal, so |y_a - y_b| <= |v_a - v_b|:
// the projected distance is a lower bound of the true one. The kd-tree over y
// gives candidates in order of that bound; they are re-ranked by the exact
// distance, and the k-th exact distance is proven final once it is below the
// bound of the first candidate not taken. Otherwise the list grows once (x4),
// after which the best found is kept (counted as not certified: approximate,
// see Stats::certified).
// Intensities at 1x1: when the 3 principal directions keep >= 99.9 % of the
// variance, a pixel the projection does not certify is looked up by the exact
// kd-tree at full dimension (exact); between 90 and 99.9 % the grown list's best
// is kept (approximate) -- except for `linear`, which always gets the exact
// nearest; below 90 % every pixel goes to the full-dimension tree.
#include "nearest.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>

#include "index_fast.hpp"

namespace veneer::match::fast {

namespace {

// Per channel, the patch's coefficients on three orthonormal spatial
// functions: the constant 1/P, and the ramps x/nu and y/nu (nu^2 = P * sum of
// i^2 over -r..r). Output rows: [mean (c), ramp x (c), ramp y (c)], or just the
// mean for 1x1.
void patch_moments(const Object& o, int threads, std::vector<float>& out, int& per_row) {
  const int c = o.channels, p = o.patch, r = p / 2;
  const int parts = p > 1 ? 3 : 1;
  per_row = parts * c;
  double sum_i2 = 0;
  for (int i = -r; i <= r; ++i) sum_i2 += i * i;
  const float inv_nu = p > 1 ? static_cast<float>(1.0 / std::sqrt(p * sum_i2)) : 0.0f;
  out.assign(static_cast<size_t>(o.rows()) * per_row, 0.0f);
  parallel_rows(o.rows(), threads, 512, [&](int b, int e) {
    for (int i = b; i < e; ++i) {
      size_t stride;
      const float* q = o.patch_ptr(i, stride);
      float* m = out.data() + static_cast<size_t>(i) * per_row;
      for (int y = 0; y < p; ++y)
        for (int x = 0; x < p; ++x)
          for (int k = 0; k < c; ++k) {
            const float v = q[y * stride + x * c + k];
            m[k] += v;
            if (parts > 1) {
              m[c + k] += static_cast<float>(x - r) * v;
              m[2 * c + k] += static_cast<float>(y - r) * v;
            }
          }
      for (int k = 0; k < c; ++k) {
        m[k] /= static_cast<float>(p);
        if (parts > 1) m[c + k] *= inv_nu, m[2 * c + k] *= inv_nu;
      }
    }
  });
}

// Top-3 principal directions of the rows of a and b (c columns), as 3 x c.
cv::Mat principal3(const std::vector<float>& a, const std::vector<float>& b, int c, int per_row, double& explained) {
  cv::Mat acc = cv::Mat::zeros(c, c, CV_64F);
  std::vector<double> mean(c, 0.0);
  size_t count = 0;
  for (const auto* v : {&a, &b}) {
    const size_t rows = v->size() / per_row;
    const size_t step = std::max<size_t>(1, rows / 20000);  // a fixed subsample: deterministic
    for (size_t i = 0; i < rows; i += step) {
      const float* r = v->data() + i * per_row;
      for (int x = 0; x < c; ++x) {
        mean[x] += r[x];
        for (int y = x; y < c; ++y) acc.at<double>(x, y) += static_cast<double>(r[x]) * r[y];
      }
      ++count;
    }
  }
  for (int x = 0; x < c; ++x) mean[x] /= static_cast<double>(count);
  for (int x = 0; x < c; ++x)
    for (int y = x; y < c; ++y) {
      const double v = acc.at<double>(x, y) / static_cast<double>(count) - mean[x] * mean[y];
      acc.at<double>(x, y) = acc.at<double>(y, x) = v;
    }
  cv::Mat values, vectors;
  cv::eigen(acc, values, vectors);  // descending eigenvalues, eigenvectors as rows
  double total = 0, top = 0;
  for (int i = 0; i < c; ++i) total += std::max(0.0, values.at<double>(i));
  for (int i = 0; i < std::min(3, c); ++i) top += std::max(0.0, values.at<double>(i));
  explained = total > 0 ? top / total : 1.0;
  cv::Mat w = cv::Mat::zeros(3, c, CV_32F);
  for (int i = 0; i < std::min(3, c); ++i)
    for (int x = 0; x < c; ++x) w.at<float>(i, x) = static_cast<float>(vectors.at<double>(i, x));
  return w;
}

// Each of the `parts` blocks of c channels projected on the 3 rows of w.
void project(const std::vector<float>& m, int c, int parts, const cv::Mat& w, std::vector<float>& y) {
  const size_t rows = m.size() / (static_cast<size_t>(parts) * c);
  const int out = 3 * parts;
  y.assign(rows * out, 0.0f);
  for (size_t i = 0; i < rows; ++i)
    for (int part = 0; part < parts; ++part)
      for (int j = 0; j < 3; ++j) {
        float s = 0;
        const float* v = m.data() + (i * parts + part) * c;
        for (int x = 0; x < c; ++x) s += w.at<float>(j, x) * v[x];
        y[i * out + part * 3 + j] = s;
      }
}

}  // namespace

// Nearest normal patch, approximate and fast: candidates are the 12 source
// rows whose patch-mean direction is nearest (the grid), plus the matches of
// the left and upper neighbours shifted by one pixel (as in PatchMatch's
// propagation); the exact patch distance picks among them. Rows are taken in
// fixed blocks, each in scan order, so the result does not depend on threads.
// The 9-D certified search (below) is exact but its kd-tree costs ~10 us per
// query; this path trades that for a stated tolerance (tests).
Status nearest_patch_normals(const Object& dst, const Object& src, int threads, const Progress& progress,
                             NearestLists& out, Stats* stats) {
  const int n = dst.rows(), ns = src.rows();
  std::vector<float> md, ms;
  int per_row = 0;
  patch_moments(dst, threads, md, per_row);
  patch_moments(src, threads, ms, per_row);
  // unit mean directions (rows of 3)
  auto directions = [&](const std::vector<float>& m, int rows) {
    std::vector<float> y(static_cast<size_t>(rows) * 3);
    for (int i = 0; i < rows; ++i) {
      const float* v = m.data() + static_cast<size_t>(i) * per_row;
      const float len = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
      for (int j = 0; j < 3; ++j) y[static_cast<size_t>(i) * 3 + j] = len > 1e-9f ? v[j] / len : 0.0f;
      if (!(len > 1e-9f)) y[static_cast<size_t>(i) * 3 + 2] = 1.0f;
    }
    return y;
  };
  const std::vector<float> yd = directions(md, n), ys = directions(ms, ns);
  OctGridIndex grid;
  grid.build(ys.data(), ns, 3);
  const int kc = std::min(ns, 12);
  const int block = 1024, blocks = (n + block - 1) / block;
  std::atomic<bool> stop{false};
  parallel_rows(blocks, threads, 1, [&](int bb, int be) {
    std::vector<float> buf(static_cast<size_t>(dst.dims));
    std::vector<int> cid(kc);
    std::vector<float> cd(kc);
    for (int blk = bb; blk < be; ++blk) {
      if (progress.cancelled()) stop = true;
      if (stop) return;
      const int r0 = blk * block, r1 = std::min(n, r0 + block);
      for (int d = r0; d < r1; ++d) {
        dst.gather(d, buf.data());
        grid.knn(&yd[static_cast<size_t>(d) * 3], kc, cid.data(), cd.data());
        int best = -1;
        float best_sq = std::numeric_limits<float>::infinity();
        auto offer = [&](int s) {
          if (s < 0 || s == best) return;
          const float v = patch_sq(buf.data(), src, s, best_sq);
          if (v < best_sq || (v == best_sq && s < best)) best_sq = v, best = s;
        };
        for (int j = 0; j < kc; ++j) offer(cid[j]);
        if (!src.row_of.empty() && !dst.row_of.empty()) {
          const cv::Point pt = dst.pixels[d];
          for (const cv::Point off : {cv::Point(-1, 0), cv::Point(0, -1)}) {
            const int nb = dst.row_at(pt.x + off.x, pt.y + off.y);
            if (nb < r0 || nb >= d) continue;  // only rows this block already matched
            const cv::Point m = src.pixels[out.ids[nb]];
            offer(src.row_at(m.x - off.x, m.y - off.y));
          }
        }
        out.ids[d] = best;
        out.sq[d] = best_sq;
      }
    }
  });
  if (stop) return make_error("cancelled during nearest search");
  if (stats) {
    stats->index = "grid";
    stats->projected_dims = 3;
    stats->explained_variance = 1;
    stats->certified = 0;  // approximate by design
    stats->candidates = kc + 2;
  }
  return {};
}

Status nearest_lists(const Object& dst, const Object& src, int k, const std::string& index_kind, int threads,
                     const Progress& progress, NearestLists& out, Stats* stats) {
  const int n = dst.rows(), ns = src.rows();
  out.k = k;
  out.ids.assign(static_cast<size_t>(n) * k, -1);
  out.sq.assign(static_cast<size_t>(n) * k, std::numeric_limits<float>::infinity());
  std::atomic<bool> stop{false};
  auto cancelled = [&] {
    if (progress.cancelled()) stop = true;
    return stop.load(std::memory_order_relaxed);
  };

  // Direct exact search over the pixel values.
  auto direct = [&](NearestIndex& index, const char* name, bool exact = true) -> Status {
    index.build(src.flat.data(), ns, src.channels);
    const auto* grid = dynamic_cast<const OctGridIndex*>(&index);
    parallel_rows(n, threads, 256, [&](int b, int e) {
      if (cancelled()) return;
      int slot = -1;
      for (int d = b; d < e; ++d) {
        const float* q = dst.flat.data() + static_cast<size_t>(d) * dst.channels;
        int* ids = &out.ids[static_cast<size_t>(d) * k];
        float* sq = &out.sq[static_cast<size_t>(d) * k];
        // neighbouring pixels have neighbouring normals: start from the last match
        if (grid && k == 1) {
          if (!grid->nearest_slot(q, slot, ids[0], sq[0], exact)) {
            grid->nearest_from(q, k, ids, sq, d > b ? out.ids[d - 1] : -1);
            slot = -1;
          }
        } else {
          index.knn(q, k, ids, sq);
        }
      }
    });
    if (stop) return make_error("cancelled during nearest search");
    if (stats)
      stats->index = name, stats->projected_dims = 0, stats->certified = exact ? 1 : 0, stats->explained_variance = 1;
    return {};
  };
  if (dst.patch == 1 && dst.channels == 3) {
    if (index_kind != "grid" && index_kind != "lookup" && index_kind != "kdtree")
      return make_error("unknown fast index '" + index_kind + "' (grid, lookup, kdtree)");
    // long lists: the kd-tree (measured faster at k = 100 by bench_match)
    if (k > 16 || index_kind == "kdtree") {
      auto index = make_kdtree();
      return direct(*index, "kdtree");
    }
    OctGridIndex grid;
    if (index_kind == "lookup" && k == 1) return direct(grid, "lookup", false);
    return direct(grid, "grid");
  }

  if (dst.channels == 3 && dst.patch > 1 && k == 1) return nearest_patch_normals(dst, src, threads, progress, out, stats);
  std::vector<float> md, ms;
  int per_row = 0;
  patch_moments(dst, threads, md, per_row);
  patch_moments(src, threads, ms, per_row);
  const int c = dst.channels, parts = per_row / c;
  double explained = 1;
  if (dst.patch == 1 && c > 3) {
    const cv::Mat w = principal3(md, ms, c, per_row, explained);
    if (explained < 0.9) {  // the projection keeps too little: full dimension
      auto index = make_kdtree();
      auto s = direct(*index, "kdtree");
      if (stats) stats->explained_variance = explained;
      return s;
    }
  }
  // y: per spatial function, the 3 principal channel directions (identity for normals)
  std::vector<float> yd, ys;
  if (c == 3) {
    yd = std::move(md);
    ys = std::move(ms);
  } else {
    const cv::Mat w = principal3(md, ms, c, per_row, explained);
    project(md, c, parts, w, yd);
    project(ms, c, parts, w, ys);
  }
  const int ydims = 3 * parts;
  auto index = make_kdtree();
  index->build(ys.data(), ns, ydims);
  // One growth step (x4); past it the best found is kept (not certified).
  const int first = std::min(ns, std::max(12, 2 * k + 8));
  const int cap = std::min(ns, (k > 1 ? 4 : 2) * first);
  std::atomic<int> certified{0};
  std::atomic<long> exact_distances{0};
  // With nearly all variance kept (>= 99.9 %: Lambertian sets), a pixel the projection
  // cannot certify asks the exact kd-tree at full dimension; otherwise (shadows,
  // highlights) that would be most pixels at ~10 us each, and the grown
  // candidate list's best is kept instead (approximate, counted in Stats).
  std::unique_ptr<NearestIndex> full;
  // `linear` (any index but the lookup) asks for the exact nearest whatever it costs
  const bool exact = index_kind != "lookup";
  if (dst.patch == 1 && (explained >= 0.999 || exact)) {
    full = make_kdtree();
    full->build(src.flat.data(), ns, c);
  }
  parallel_rows(n, threads, 128, [&](int b, int e) {
    if (cancelled()) return;
    std::vector<float> buf(static_cast<size_t>(dst.dims));
    std::vector<int> cid;
    std::vector<float> clb;
    int local_certified = 0;
    long local_exact = 0;
    for (int d = b; d < e; ++d) {
      dst.gather(d, buf.data());
      int* ids = &out.ids[static_cast<size_t>(d) * k];
      float* sq = &out.sq[static_cast<size_t>(d) * k];
      for (int want = first;; want = std::min(cap, want * 4)) {
        cid.resize(want);
        clb.resize(want);
        index->knn(&yd[static_cast<size_t>(d) * ydims], want, cid.data(), clb.data());
        TopK top(k, ids, sq);
        for (int j = 0; j < want && cid[j] >= 0; ++j) {
          const float bound = top.worst();
          const float v = patch_sq(buf.data(), src, cid[j], bound);
          if (v <= bound) top.add(v, cid[j]);
        }
        // Proven when every source row is seen, or the next row's lower
        // bound (>= the last candidate's) is above the k-th exact distance.
        const bool all = want >= ns;
        const bool proven = all || clb[want - 1] * (1.0f - 1e-4f) > top.worst();
        if (proven) ++local_certified;
        local_exact += want;
        if (!proven && full) {
          full->knn(dst.flat.data() + static_cast<size_t>(d) * c, k, ids, sq);
          ++local_certified;  // exact all the same
          break;
        }
        if (proven || want >= cap) break;
      }
    }
    certified += local_certified;
    exact_distances += local_exact;
  });
  if (stop) return make_error("cancelled during nearest search");
  if (stats) {
    stats->index = "kdtree";
    stats->projected_dims = ydims;
    stats->explained_variance = explained;
    stats->certified = n > 0 ? static_cast<double>(certified.load()) / n : 1.0;
    stats->candidates = n > 0 ? static_cast<double>(exact_distances.load()) / n : 0.0;
  }
  return {};
}

}  // namespace veneer::match::fast
