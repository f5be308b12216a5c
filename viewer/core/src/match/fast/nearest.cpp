// k nearest by the full feature distance (nearest.hpp).
//
// 1x1 features of 3 values (normals): the exact index over the values.
// Normal patches, k = 1: the approximate candidate search of
// nearest_patch_normals (below).
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
// see Stats::certified) -- except for any index but the lookup (`linear`,
// `candidates`, `regiongrow`; `flann` asks the lookup), which then compares
// the pixel's patch with every source patch (exact). Bull <- sphere-red-gloss
// 3x3 at 512x340, linear: 121 ms against the faithful scan's 820 ms and the
// approximate 30 ms, relighting PSNR 17.32 dB as the faithful scan against
// 16.86; regiongrow 3x3 intensities: 4x the time, 16.64 against 16.39 dB.
// Intensities at 1x1 are always exact: a pixel the projection does not
// certify is looked up by the kd-tree at full dimension; below 90 % of the
// variance kept by the 3 principal directions every pixel goes there. (Keeping
// the grown list's best instead, as `flann` did between 90 and 99.9 %, cost
// 0.5 dB of relighting PSNR on bull <- sphere-red-gloss -- 17.51 against 18.03
// -- and 0.4 deg of normal agreement on bull <- orange, for 20 % less time in
// bench_quality and 35-40 % less in bench_match's intensities row, where about
// half the pixels need the full tree.) The full tree is asked within the
// candidates' best distance, which prunes from its first node (675 against
// 840 ms at 150k px).
#include "nearest.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>

#include "index_fast.hpp"

namespace veneer::match::fast {

// Per channel, the patch's coefficients on three orthonormal spatial
// functions: the constant 1/P, and the ramps x/nu and y/nu (nu^2 = P * sum of
// i^2 over -r..r). Output rows: [mean (c), ramp x (c), ramp y (c)], or just the
// mean for 1x1.
// Interior pixels (patch wholly on the object) share work along each run of
// them on an image row: per column, the sums over the P rows (plain and
// weighted by dy), then per pixel the P columns of those -- (2 + 3) P c
// operations instead of 3 P^2 c. Rim pixels read their stored patch. Every
// value is summed in a fixed order, so the result does not depend on threads.
void patch_moments(const Object& o, int threads, std::vector<float>& out, int& per_row, bool means_only) {
  const int c = o.channels, p = o.patch, r = p / 2;
  const int parts = p > 1 && !means_only ? 3 : 1;
  per_row = parts * c;
  double sum_i2 = 0;
  for (int i = -r; i <= r; ++i) sum_i2 += i * i;
  const float inv_nu = p > 1 ? static_cast<float>(1.0 / std::sqrt(p * sum_i2)) : 0.0f;
  const float inv_p = 1.0f / static_cast<float>(p);
  const int n = o.rows();
  out.assign(static_cast<size_t>(n) * per_row, 0.0f);
  if (p == 1) {
    std::copy(o.flat.begin(), o.flat.end(), out.begin());
    return;
  }
  auto direct = [&](int i) {
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
    for (int k = 0; k < c; ++k) m[k] *= inv_p;
    if (parts > 1)
      for (int k = 0; k < c; ++k) m[c + k] *= inv_nu, m[2 * c + k] *= inv_nu;
  };
  // object rows per image row (rows are in scan order)
  const int h = o.size.height;
  const std::vector<int> at = row_starts(o);
  parallel_rows(h, threads, 4, [&](int yb, int ye) {
    std::vector<float> v0, v2;  // per column of a run: sum over dy, and of dy * value
    for (int y = yb; y < ye; ++y) {
      for (int i = at[y]; i < at[y + 1];) {
        if (o.slot[i] >= 0) {
          direct(i++);
          continue;
        }
        int j = i + 1;
        while (j < at[y + 1] && o.slot[j] < 0 && o.pixels[j].x == o.pixels[j - 1].x + 1) ++j;
        const int xa = o.pixels[i].x - r, cols = o.pixels[j - 1].x + r - xa + 1, len = cols * c;
        v0.assign(len, 0.0f);
        v2.assign(len, 0.0f);
        for (int dy = -r; dy <= r; ++dy) {
          const float* row = o.values.ptr<float>(y + dy) + static_cast<size_t>(xa) * c;
          const float w = static_cast<float>(dy);
          if (parts > 1)
            for (int t = 0; t < len; ++t) v0[t] += row[t], v2[t] += w * row[t];
          else
            for (int t = 0; t < len; ++t) v0[t] += row[t];
        }
        if (parts == 1) {
          // rows i..j-1 are consecutive pixels, their means one flat run of
          // (j - i) c floats: each column's sums added over the whole run at
          // once (the same order per value as one pixel at a time)
          float* m = out.data() + static_cast<size_t>(i) * per_row;
          const int run = (j - i) * c;
          for (int dx = 0; dx < p; ++dx) {
            const float* a0 = v0.data() + dx * c;
            for (int t = 0; t < run; ++t) m[t] += a0[t];
          }
          for (int t = 0; t < run; ++t) m[t] *= inv_p;
          i = j;
          continue;
        }
        for (int q = i; q < j; ++q) {
          float* m = out.data() + static_cast<size_t>(q) * per_row;
          const int base = (o.pixels[q].x - r - xa) * c;
          for (int dx = 0; dx < p; ++dx) {
            const float w = static_cast<float>(dx - r);
            const float* a0 = v0.data() + base + dx * c;
            const float* a2 = v2.data() + base + dx * c;
            for (int k = 0; k < c; ++k) m[k] += a0[k], m[c + k] += w * a0[k], m[2 * c + k] += a2[k];
          }
          for (int k = 0; k < c; ++k) m[k] *= inv_p, m[c + k] *= inv_nu, m[2 * c + k] *= inv_nu;
        }
        i = j;
      }
    }
  });
}

namespace {

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

namespace {

// Approximately the k nearest unit directions, cheaply: the rows bucketed by
// the octahedral cell of their direction (uv = (x, y) / |n|_1, one layer per
// hemisphere; ~1 row per occupied cell, rows of cells contiguous in memory),
// and a query takes the k nearest among the cells within one cell of its own
// uv (that box grown until it holds k rows). The true k nearest can lie just
// outside the box; for picking patch candidates that changes nothing
// measurable (bench_match: same error and coherence as the exact 12 nearest
// through OctGridIndex, which costs ~1 us a query at k = 12 against ~0.2 us).
class DirectionBuckets {
 public:
  struct Scratch {
    std::vector<float> d, kd;
    std::vector<int> id, ki;
  };

  void build(const std::vector<float>& dirs, int n) {
    side_ = std::clamp(static_cast<int>(std::sqrt(1.0 * n)), 4, 1024);
    cells_ = side_ * side_;
    scale_ = 0.5f * static_cast<float>(side_);
    start_.assign(static_cast<size_t>(2 * cells_ + 1), 0);
    std::vector<int> of(n);
    for (int i = 0; i < n; ++i) {
      int cx, cy;
      const int layer = cell(&dirs[static_cast<size_t>(i) * 3], cx, cy);
      of[i] = layer * cells_ + cy * side_ + cx;
      ++start_[of[i] + 1];
    }
    for (int c = 0; c < 2 * cells_; ++c) start_[c + 1] += start_[c];
    std::vector<int> fill(start_.begin(), start_.end() - 1);
    x_.resize(n), y_.resize(n), z_.resize(n), id_.resize(n);
    for (int i = 0; i < n; ++i) {  // in row order: cells keep ascending ids
      const int at = fill[of[i]]++;
      const float* p = &dirs[static_cast<size_t>(i) * 3];
      x_[at] = p[0], y_[at] = p[1], z_[at] = p[2], id_[at] = i;
    }
  }

  // `ids`: the k nearest (k <= rows) of the box as a set, ties at the k-th
  // distance to the lower ids.
  void knn(const float* q, int k, int* ids, Scratch& w) const {
    const float qx = q[0], qy = q[1], qz = q[2];
    float u, v;
    uv(q, u, v);
    const int layer = qz < 0 ? 1 : 0;
    const float fu = (u + 1.0f) * scale_, fv = (v + 1.0f) * scale_;
    int x0 = 0, x1 = 0, y0 = 0, y1 = 0, got = 0;
    for (float rad = 1.0f;; rad *= 1.5f) {
      x0 = std::clamp(static_cast<int>(std::floor(fu - rad)), 0, side_ - 1);
      x1 = std::clamp(static_cast<int>(std::floor(fu + rad)), 0, side_ - 1);
      y0 = std::clamp(static_cast<int>(std::floor(fv - rad)), 0, side_ - 1);
      y1 = std::clamp(static_cast<int>(std::floor(fv + rad)), 0, side_ - 1);
      got = 0;
      for (int y = y0; y <= y1; ++y) got += start_[layer * cells_ + y * side_ + x1 + 1] - start_[layer * cells_ + y * side_ + x0];
      if (got >= k || (x0 == 0 && y0 == 0 && x1 == side_ - 1 && y1 == side_ - 1)) break;
    }
    if (got < k) {  // this hemisphere holds too few: every row of both
      std::vector<float> d(k);
      TopK top(k, ids, d.data());
      for (int at = 0; at < static_cast<int>(id_.size()); ++at) top.add(sq3(x_[at], y_[at], z_[at], qx, qy, qz), id_[at]);
      return;
    }
    w.d.resize(got);
    w.id.resize(got);
    int m = 0;
    for (int y = y0; y <= y1; ++y) {
      const int c0 = layer * cells_ + y * side_;
      const int b = start_[c0 + x0], e = start_[c0 + x1 + 1];
      float* dd = w.d.data() + m;
      for (int at = b; at < e; ++at) dd[at - b] = sq3(x_[at], y_[at], z_[at], qx, qy, qz);
      std::copy(id_.begin() + b, id_.begin() + e, w.id.begin() + m);
      m += e - b;
    }
    if (m == k) {
      std::copy_n(w.id.begin(), k, ids);
      return;
    }
    // Rows farther than the k-th of any k rows (here the first k) cannot be
    // among the k nearest: k rows are strictly nearer. That bound kept nearly
    // all of the box's ~3k rows, so it is narrowed: of the 8 bounds
    // thr * 1/8 .. thr * 8/8, the least that has at least k rows within it
    // (counted for all 8 at once, without branches) keeps the k nearest too.
    // The rest are ranked by (distance, id), counted without branches; those
    // ranked below k are the answer (the rows dropped lie beyond every row
    // kept, so ranks agree).
    float thr = 0;
    for (int j = 0; j < k; ++j) thr = std::max(thr, w.d[j]);
    {
      float t[8];
      int within[8] = {0, 0, 0, 0, 0, 0, 0, 0};
      for (int b = 0; b < 8; ++b) t[b] = thr * (static_cast<float>(b + 1) * 0.125f);  // t[7] == thr
      for (int j = 0; j < m; ++j)
        for (int b = 0; b < 8; ++b) within[b] += w.d[j] <= t[b];
      int b = 0;
      while (within[b] < k) ++b;  // within[7] >= k: the first k rows are within thr
      thr = t[b];
    }
    w.kd.resize(m + 8);
    w.ki.resize(m + 8);
    float* kd = w.kd.data();
    int* ki = w.ki.data();
    int kept = 0;
    for (int j = 0; j < m; ++j) {
      kd[kept] = w.d[j];
      ki[kept] = w.id[j];
      kept += w.d[j] <= thr;
    }
    const int padded = (kept + 7) & ~7;  // whole vectors; the padding ranks last
    for (int j = kept; j < padded; ++j) kd[j] = kInfinity, ki[j] = std::numeric_limits<int>::max();
    int out = 0;
    for (int i = 0; i < kept && out < k; ++i) {
      const float di = kd[i];
      const int id = ki[i];
      int rank = 0;
      for (int j = 0; j < padded; ++j) rank += (kd[j] < di) | ((kd[j] == di) & (ki[j] < id));
      ids[out] = id;
      out += rank < k;
    }
  }

 private:
  static constexpr float kInfinity = std::numeric_limits<float>::infinity();
  int side_ = 1, cells_ = 1;
  float scale_ = 0.5f;
  std::vector<int> start_;  // 2 side^2 + 1 offsets: layer, cell row, cell column
  std::vector<float> x_, y_, z_;
  std::vector<int> id_;

  static void uv(const float* m, float& u, float& v) {
    const float s = std::fabs(m[0]) + std::fabs(m[1]) + std::fabs(m[2]);
    u = s > 0 ? m[0] / s : 0.0f;
    v = s > 0 ? m[1] / s : 0.0f;
  }
  int cell(const float* m, int& cx, int& cy) const {
    float u, v;
    uv(m, u, v);
    cx = std::clamp(static_cast<int>((u + 1.0f) * scale_), 0, side_ - 1);
    cy = std::clamp(static_cast<int>((v + 1.0f) * scale_), 0, side_ - 1);
    return m[2] < 0 ? 1 : 0;
  }
};

}  // namespace

// Nearest normal patch, approximate and fast: candidates are ~the 12 source
// rows whose patch-mean direction is nearest (DirectionBuckets), plus the
// matches of the left and upper neighbours shifted by one pixel (as in
// PatchMatch's propagation); the exact patch distance picks among them, the
// propagated ones first (they win about half the time, and a low best
// distance lets the others stop early). Rows are taken in fixed blocks, each
// in scan order, so the result does not depend on threads. The 9-D certified
// search (below) is exact but its kd-tree costs ~10 us per query; this path
// trades that for a stated tolerance (tests).
Status nearest_patch_normals(const Object& dst, const Object& src, int threads, const Progress& progress,
                             NearestLists& out, Stats* stats) {
  const int n = dst.rows(), ns = src.rows();
  // unit patch-mean directions (rows of 3)
  auto directions = [&](const Object& o) {
    std::vector<float> m;
    int per_row = 0;
    patch_moments(o, threads, m, per_row, true);
    const int rows = o.rows();
    std::vector<float> y(static_cast<size_t>(rows) * 3);
    parallel_rows(rows, threads, 4096, [&](int b, int e) {
      for (int i = b; i < e; ++i) {
        const float* v = m.data() + static_cast<size_t>(i) * per_row;
        const float len = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
        for (int j = 0; j < 3; ++j) y[static_cast<size_t>(i) * 3 + j] = len > 1e-9f ? v[j] / len : 0.0f;
        if (!(len > 1e-9f)) y[static_cast<size_t>(i) * 3 + 2] = 1.0f;
      }
    });
    return y;
  };
  const std::vector<float> yd = directions(dst), ys = directions(src);
  DirectionBuckets buckets;
  buckets.build(ys, ns);
  const int kc = std::min(ns, 12);
  const int block = 1024, blocks = (n + block - 1) / block;
  const PatchKernel kernel = patch_kernel(src.patch, src.channels);
  const int patch_w = src.patch * src.channels;
  const bool walk = !src.row_of.empty() && !dst.row_of.empty();
  std::atomic<bool> stop{false};
  parallel_rows(blocks, threads, 1, [&](int bb, int be) {
    std::vector<int> cid(kc);
    std::vector<const float*> cptr(kc);
    DirectionBuckets::Scratch scratch;
    for (int blk = bb; blk < be; ++blk) {
      if (progress.cancelled()) stop = true;
      if (stop) return;
      const int r0 = blk * block, r1 = std::min(n, r0 + block);
      for (int d = r0; d < r1; ++d) {
        const cv::Point pt = dst.pixels[d];
        buckets.knn(&yd[static_cast<size_t>(d) * 3], kc, cid.data(), scratch);
        size_t a_stride;
        const float* a = dst.patch_ptr(d, a_stride);  // read in place
        int best = -1;
        float best_sq = std::numeric_limits<float>::infinity();
        auto offer = [&](int s) {
          if (s < 0 || s == best) return;
          const float v = patch_sq_strided(a, a_stride, src, s, best_sq);
          if (v < best_sq || (v == best_sq && s < best)) best_sq = v, best = s;
        };
        if (walk) {
          for (const cv::Point off : {cv::Point(-1, 0), cv::Point(0, -1)}) {
            const int nb = dst.row_at(pt.x + off.x, pt.y + off.y);
            if (nb < r0 || nb >= d) continue;  // only rows this block already matched
            const cv::Point m = src.pixels[out.ids[nb]];
            offer(src.row_at(m.x - off.x, m.y - off.y));
          }
        }
        // the candidates' patch offsets read all at once (each read misses
        // the cache; in a row they overlap), then their distances
        for (int j = 0; j < kc; ++j) cptr[j] = src.box.data() + src.patch_at[cid[j]];
        for (int j = 0; j < kc; ++j) {
          const int s = cid[j];
          if (s == best) continue;
          const float v = kernel(a, a_stride, cptr[j], src.box_stride, src.patch, patch_w, best_sq);
          if (v < best_sq || (v == best_sq && s < best)) best_sq = v, best = s;
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

// The rows in fixed runs of 256, both cores taking runs: a scan that carries
// the previous match from row to row starts afresh at the same rows whatever
// the threads do. (The lookup's answer depends on that start: the best of
// the query's own cell and the previous match. Over the ranges the scheduler
// splits, a map of blocks -> bull came out different on 1 and on 2 threads.)
static void for_each_run(int n, int threads, const std::function<void(int, int)>& run) {
  constexpr int kRun = 256;
  parallel_rows((n + kRun - 1) / kRun, threads, 1, [&](int rb, int re) {
    for (int r = rb; r < re; ++r) run(r * kRun, std::min(n, (r + 1) * kRun));
  });
}

Status nearest_rows(const OctGridIndex& grid, const Object& dst, const int* rows, int count, int threads,
                    const Progress& progress, int* ids, float* sq, bool exact) {
  if (dst.channels != 3) return make_error("nearest_rows: 3 values per pixel needed");
  std::atomic<bool> stop{false};
  for_each_run(count, threads, [&](int b, int e) {
    if (progress.cancelled()) stop = true;
    if (stop) return;
    float ignored;
    int slot = -1;  // neighbouring pixels have neighbouring normals: start from the last match's place
    for (int i = b; i < e; ++i) {
      const int d = rows ? rows[i] : i;
      const float* q = dst.flat.data() + static_cast<size_t>(d) * 3;
      float& out = sq ? sq[d] : ignored;
      if (!grid.nearest_slot(q, slot, ids[d], out, exact)) {
        grid.nearest_from(q, 1, &ids[d], &out, i > b ? ids[rows ? rows[i - 1] : i - 1] : -1);
        slot = -1;
      }
    }
  });
  if (stop) return make_error("cancelled during nearest search");
  return {};
}

Status nearest_centres(const Object& dst, const Object& src, int threads, const Progress& progress,
                       std::vector<int>& ids, bool exact) {
  ids.assign(dst.rows(), -1);
  if (dst.channels != 3) return make_error("nearest_centres: 3 values per pixel needed");
  OctGridIndex grid;
  grid.build(src.flat.data(), src.rows(), 3);
  return nearest_rows(grid, dst, nullptr, dst.rows(), threads, progress, ids.data(), nullptr, exact);
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
    for_each_run(n, threads, [&](int b, int e) {
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
      if (out.on_rows) out.on_rows(b, e);
    });
    if (stop) return make_error("cancelled during nearest search");
    out.rows_reported = static_cast<bool>(out.on_rows);
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
  cv::Mat w;  // the 3 principal channel directions (features other than normals)
  if (c != 3) w = principal3(md, ms, c, per_row, explained);
  if (dst.patch == 1 && c > 3 && explained < 0.9) {  // the projection keeps too little: full dimension
    auto index = make_kdtree();
    auto s = direct(*index, "kdtree");
    if (stats) stats->explained_variance = explained;
    return s;
  }
  // y: per spatial function, the 3 principal channel directions (identity for normals)
  std::vector<float> yd, ys;
  if (c == 3) {
    yd = std::move(md);
    ys = std::move(ms);
  } else {
    project(md, c, parts, w, yd);
    project(ms, c, parts, w, ys);
  }
  const int ydims = 3 * parts;
  auto index = make_kdtree();
  index->build(ys.data(), ns, ydims);
  // One growth step (x4); past it the best found is kept (not certified).
  const int first = std::min(ns, std::max(12, 2 * k + 8));
  const int cap = std::min(ns, (k > 1 ? 4 : 2) * first);
  // every index but the lookup (`linear`, and the lists of `candidates` and
  // `regiongrow`) asks for the exact nearest whatever it costs
  const bool exhaustive = index_kind != "lookup";
  std::atomic<int> certified{0};
  std::atomic<long> exact_distances{0};
  // 1x1: a pixel the projection cannot certify asks the exact kd-tree at
  // full dimension (see the top of this file for what that costs). Patches
  // keep the grown candidate list's best (approximate, counted in Stats) --
  // for `linear` every source patch is then compared (exact; each distance
  // stops once over the best found).
  std::unique_ptr<NearestIndex> full;
  if (dst.patch == 1) {
    full = make_kdtree();
    full->build(src.flat.data(), ns, c);
  }
  parallel_rows(n, threads, 128, [&](int b, int e) {
    if (cancelled()) return;
    std::vector<float> buf(static_cast<size_t>(dst.dims));
    std::vector<int> cid;
    std::vector<float> clb;
    std::vector<uint8_t> seen;  // the exhaustive path's marks, sized when first needed
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
          // the candidates' k-th distance bounds the search (with a margin
          // for the tree's other summation order)
          const float radius = top.worst() * (1.0f + 1e-4f) + 1e-12f;
          full->knn_within(dst.flat.data() + static_cast<size_t>(d) * c, k, radius, ids, sq);
          ++local_certified;  // exact all the same
          break;
        }
        if (!proven && exhaustive && want >= cap) {  // the rest of the source, bounded by the best found
          if (cancelled()) return;
          if (seen.empty()) seen.assign(static_cast<size_t>(ns), 0);
          for (int j = 0; j < want && cid[j] >= 0; ++j) seen[cid[j]] = 1;
          for (int id = 0; id < ns; ++id) {
            if (seen[id]) continue;
            const float bound = top.worst();
            const float v = patch_sq(buf.data(), src, id, bound);
            if (v <= bound) top.add(v, id);
          }
          for (int j = 0; j < want && cid[j] >= 0; ++j) seen[cid[j]] = 0;
          ++local_certified;
          local_exact += ns - want;
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
