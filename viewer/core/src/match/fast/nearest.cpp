// k nearest by the full feature distance (nearest.hpp).
//
// 1x1 features of 3 values (normals): the exact index over the values.
// Everything else: each patch vector v (P*P pixels x C channels) is projected
// to y = W (sum over the patch of the pixel values) / P, where W holds the 3
// principal directions of those per-channel sums (identity when C = 3). The
// rows of that linear map are orthonormal, so |y_a - y_b| <= |v_a - v_b|: the
// projected distance is a lower bound of the true one. The index over y gives
// candidates in order of that bound; they are re-ranked by the exact distance,
// and the k-th exact distance is proven final once it is below the bound of
// the first candidate not taken. Otherwise the list grows (x4) up to a cap,
// after which the best found is kept (counted as not certified).
// Intensities at 1x1 whose 3 principal directions keep less than 99 % of the
// variance are searched at full dimension by the exact kd-tree instead.
#include "nearest.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>

#include "index_fast.hpp"

namespace veneer::match::fast {

namespace {

// Sum over the patch of each channel, divided by P (one orthonormal
// projection coefficient per channel).
void patch_means(const Object& o, int threads, std::vector<float>& out) {
  const int c = o.channels, p = o.patch;
  out.assign(static_cast<size_t>(o.rows()) * c, 0.0f);
  parallel_rows(o.rows(), threads, 512, [&](int b, int e) {
    for (int i = b; i < e; ++i) {
      size_t stride;
      const float* q = o.patch_ptr(i, stride);
      float* m = out.data() + static_cast<size_t>(i) * c;
      for (int r = 0; r < p; ++r)
        for (int x = 0; x < p; ++x)
          for (int k = 0; k < c; ++k) m[k] += q[r * stride + x * c + k];
      for (int k = 0; k < c; ++k) m[k] /= static_cast<float>(p);
    }
  });
}

// Top-3 principal directions of the rows of a and b (c columns), as 3 x c.
cv::Mat principal3(const std::vector<float>& a, const std::vector<float>& b, int c, double& explained) {
  cv::Mat acc = cv::Mat::zeros(c, c, CV_64F);
  std::vector<double> mean(c, 0.0);
  size_t count = 0;
  for (const auto* v : {&a, &b}) {
    const size_t rows = v->size() / c;
    const size_t step = std::max<size_t>(1, rows / 20000);  // a fixed subsample: deterministic
    for (size_t i = 0; i < rows; i += step) {
      const float* r = v->data() + i * c;
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

void project(const std::vector<float>& m, int c, const cv::Mat& w, std::vector<float>& y) {
  const size_t rows = m.size() / c;
  y.assign(rows * 3, 0.0f);
  for (size_t i = 0; i < rows; ++i)
    for (int j = 0; j < 3; ++j) {
      float s = 0;
      for (int x = 0; x < c; ++x) s += w.at<float>(j, x) * m[i * c + x];
      y[i * 3 + j] = s;
    }
}

}  // namespace

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
  auto direct = [&](NearestIndex& index, const char* name) -> Status {
    index.build(src.flat.data(), ns, src.channels);
    parallel_rows(n, threads, 256, [&](int b, int e) {
      if (cancelled()) return;
      for (int d = b; d < e; ++d)
        index.knn(dst.flat.data() + static_cast<size_t>(d) * dst.channels, k, &out.ids[static_cast<size_t>(d) * k],
                  &out.sq[static_cast<size_t>(d) * k]);
    });
    if (stop) return make_error("cancelled during nearest search");
    if (stats) stats->index = name, stats->projected_dims = 0, stats->certified = 1, stats->explained_variance = 1;
    return {};
  };
  if (dst.patch == 1 && dst.channels == 3) {
    auto index = make_index(index_kind);
    if (!index) return make_error("unknown fast index '" + index_kind + "' (grid, kdtree)");
    return direct(*index, index_kind == "grid" ? "grid" : "kdtree");
  }

  std::vector<float> md, ms;
  patch_means(dst, threads, md);
  patch_means(src, threads, ms);
  double explained = 1;
  const int c = dst.channels;
  cv::Mat w;
  if (c == 3) {
    w = cv::Mat::eye(3, 3, CV_32F);
  } else {
    w = principal3(md, ms, c, explained);
  }
  if (dst.patch == 1 && explained < 0.99) {
    auto index = make_kdtree();
    auto s = direct(*index, "kdtree");
    if (stats) stats->explained_variance = explained;
    return s;
  }
  std::vector<float> yd, ys;
  if (c == 3) {
    yd = std::move(md);
    ys = std::move(ms);
  } else {
    project(md, c, w, yd);
    project(ms, c, w, ys);
  }
  auto index = make_kdtree();
  index->build(ys.data(), ns, 3);
  const int first = std::min(ns, std::max(8, 2 * k + 6));
  const int cap = std::min(ns, std::max(512, 4 * k));
  std::atomic<int> certified{0};
  parallel_rows(n, threads, 128, [&](int b, int e) {
    if (cancelled()) return;
    std::vector<float> buf(static_cast<size_t>(dst.dims));
    std::vector<int> cid;
    std::vector<float> clb;
    int local_certified = 0;
    for (int d = b; d < e; ++d) {
      dst.gather(d, buf.data());
      int* ids = &out.ids[static_cast<size_t>(d) * k];
      float* sq = &out.sq[static_cast<size_t>(d) * k];
      for (int want = first;; want = std::min(cap, want * 4)) {
        cid.resize(want);
        clb.resize(want);
        index->knn(&yd[static_cast<size_t>(d) * 3], want, cid.data(), clb.data());
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
        if (proven || want >= cap) break;
      }
    }
    certified += local_certified;
  });
  if (stop) return make_error("cancelled during nearest search");
  if (stats) {
    stats->index = "kdtree";
    stats->projected_dims = 3;
    stats->explained_variance = explained;
    stats->certified = n > 0 ? static_cast<double>(certified.load()) / n : 1.0;
  }
  return {};
}

}  // namespace veneer::match::fast
