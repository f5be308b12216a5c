// The fast engine's entry points (fast.hpp): direct matching (linear/flann),
// candidates, patchmatch and regiongrow with the faithful methods' semantics
// (matcher.cpp), and the dispatch to `coherent` (coherent.cpp).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <deque>
#include <limits>
#include <mutex>
#include <unordered_map>

#include <opencv2/imgproc.hpp>
#include <tbb/parallel_invoke.h>

#include "candidates.hpp"
#include "combined.hpp"
#include "engine.hpp"
#include "index_fast.hpp"
#include "nearest.hpp"
#include "object.hpp"
#include "veneer/match/fast.hpp"
#include "veneer/match/features.hpp"
#include "veneer/util/log.hpp"

namespace veneer::match::fast {

namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

// Thesis eq. 4.2: the destination's bounding box stretched onto the source's
// (the same arithmetic as matcher.cpp).
cv::Point2f box_map(const cv::Rect& d, const cv::Rect& s, cv::Point p) {
  const float sx = static_cast<float>(s.width) / static_cast<float>(d.width);
  const float sy = static_cast<float>(s.height) / static_cast<float>(d.height);
  return {s.x + (p.x - d.x + 0.5f) * sx - 0.5f, s.y + (p.y - d.y + 0.5f) * sy - 0.5f};
}

// `linear` is the exact nearest (the grid, certified); `flann` -- in the
// thesis an approximate search -- is the lookup for normals, which is about
// twice as fast and rarely misses (bench_match measures both).
Expected<Map> run_direct(const Object& dst, const Object& src, const MatchOptions& o, const Progress& p,
                         Stats* stats) {
  NearestLists nn;
  const char* index = o.method == Method::flann ? default_index() : "grid";
  // the map is written block by block as the search fills it
  Map map = new_map(dst.size);
  nn.on_rows = [&](int b, int e) {
    for (int d = b; d < e; ++d)
      if (nn.ids[d] >= 0) put(map, dst, src, d, nn.ids[d], nn.sq[d]);
  };
  if (auto s = nearest_lists(dst, src, 1, index, o.threads, p, nn, stats); !s) return s.error();
  if (!nn.rows_reported) parallel_rows(dst.rows(), o.threads, 4096, nn.on_rows);
  return map;
}

Expected<Map> run_candidates(const Object& dst, const Object& src, const MatchOptions& o, const Progress& p,
                             Stats* stats) {
  const int k = o.candidates;
  Map map = new_map(dst.size);
  if (candidates3_applies(dst, src)) {
    // 3 values per pixel: the K sets by ball queries, never sorted (candidates.cpp; exact)
    stats->index = "morton-tree";
    std::vector<cv::Point2f> targets(dst.rows());
    parallel_rows(dst.rows(), o.threads, 8192, [&](int b, int e) {
      for (int d = b; d < e; ++d) targets[d] = box_map(dst.bbox, src.bbox, dst.pixels[d]);
    });
    std::vector<int> chosen;
    std::vector<float> chosen_sq;
    if (auto s = choose_candidates3(dst, src, k, targets, o.threads, p, chosen, chosen_sq, &stats->candidates); !s)
      return s.error();
    parallel_rows(dst.rows(), o.threads, 4096, [&](int b, int e) {
      for (int d = b; d < e; ++d)
        if (chosen[d] >= 0) put(map, dst, src, d, chosen[d], chosen_sq[d]);
    });
    return map;
  }
  stats->index = "grid";
  NearestLists nn;
  if (auto s = nearest_lists(dst, src, k, "grid", o.threads, p, nn, stats); !s) return s.error();
  for (int d = 0; d < dst.rows(); ++d) {
    const cv::Point2f target = box_map(dst.bbox, src.bbox, dst.pixels[d]);
    float best = kInf;
    int chosen = -1;
    float chosen_sq = kInf;
    for (int j = 0; j < k; ++j) {
      const int id = nn.ids[static_cast<size_t>(d) * k + j];
      if (id < 0) break;
      const cv::Point q = src.pixels[id];
      const float dx = q.x - target.x, dy = q.y - target.y;
      const float image_d = dx * dx + dy * dy;
      if (image_d < best) best = image_d, chosen = id, chosen_sq = nn.sq[static_cast<size_t>(d) * k + j];
    }
    if (chosen >= 0) put(map, dst, src, d, chosen, chosen_sq);
  }
  return map;
}


// PatchMatch with matcher.cpp's semantics (propagation from the neighbours already visited with the scan
// direction alternating per iteration, random search in windows halving from
// the source's size, off-object candidates cost +inf) but a better start (see
// below), run on horizontal bands
// in parallel. A band propagates only within itself; the band edges move by
// half a band every other iteration so no seam stays. Random numbers come from a
// hash of (seed, iteration, pixel), so the map does not depend on threads.
// uniformity u > 0 adds u * uses(s) / fair_share to the RMS distance, with
// live use counts; that makes the scan sequential (one band).
Expected<Map> run_patchmatch(const Object& dst, const Object& src, const MatchOptions& o, const Progress& p) {
  const int n = dst.rows(), ns = src.rows();
  std::vector<int> match(n);
  std::vector<float> sq(n);
  const float area = static_cast<float>(dst.patch * dst.patch);
  const float u = static_cast<float>(o.uniformity);
  const float fair = std::max(1e-6f, static_cast<float>(n) / static_cast<float>(ns));
  std::vector<int> uses;

  // Init: the faithful method starts from random source object pixels; the
  // fast one starts from each pixel's nearest by its centre value (a few ms;
  // for patches the grid's lookup), which leaves the 5 iterations refining
  // instead of searching.
  {
    std::vector<int> ids;
    if (dst.channels == 3) {
      if (auto s = nearest_centres(dst, src, o.threads, p, ids, dst.patch == 1); !s) return s.error();
    } else {
      Object d1 = dst, s1 = src;
      for (Object* o1 : {&d1, &s1}) {
        o1->patch = 1;
        o1->dims = o1->channels;
        o1->slot.assign(o1->rows(), -1);
        o1->box.clear();
        o1->patch_at.clear();
      }
      NearestLists nn;
      if (auto s = nearest_lists(d1, s1, 1, default_index(), o.threads, p, nn, nullptr); !s) return s.error();
      ids = std::move(nn.ids);
    }
    parallel_rows(n, o.threads, 256, [&](int b, int e) {
      for (int d = b; d < e; ++d) {
        match[d] = ids[d] >= 0 ? ids[d]
                               : static_cast<int>(hash3(o.seed, 0xffffu, static_cast<uint64_t>(d)) %
                                                  static_cast<uint64_t>(ns));
        size_t a_stride;
        const float* a = dst.patch_ptr(d, a_stride);  // read in place
        sq[d] = patch_sq_strided(a, a_stride, src, match[d], kInf);
      }
    });
  }
  const std::vector<int> at = row_starts(dst);
  // The source over its bounding box, dense: per pixel whether it is off the
  // object, interior (its patch read in place: the offset follows from the
  // position) or on the rim (stored patch, through its row), one byte each so
  // that the table stays in cache; and its row. Random search reads them at
  // random places, and the frame-wide row_of puts every image row 4 KB apart
  // (a TLB entry each, the same cache sets). An interior candidate's patch
  // address follows from its position, not from a table read, so its loads
  // start as soon as the branch on the table is predicted. The row is read
  // only when a candidate wins, for rim patches, and for the use counts of
  // uniformity. Matches are followed by position.
  enum : uint8_t { kOff = 0, kInterior = 1, kRim = 2 };
  const cv::Rect sb = src.bbox;
  std::vector<int> src_rows(static_cast<size_t>(sb.area()), -1);
  std::vector<uint8_t> src_kind(static_cast<size_t>(sb.area()), kOff);
  const float* src_base = src.patch == 1 ? src.flat.data() : src.box.data();
  const size_t src_stride = src.patch == 1 ? static_cast<size_t>(src.channels) : src.box_stride;
  parallel_rows(ns, o.threads, 8192, [&](int b, int e) {
    for (int i = b; i < e; ++i) {
      const cv::Point q = src.pixels[i];
      const size_t cell = static_cast<size_t>(q.y - sb.y) * sb.width + (q.x - sb.x);
      src_rows[cell] = i;
      src_kind[cell] = src.patch > 1 && src.slot[i] < 0 ? kInterior : kRim;
    }
  });
  auto rim_offset = [&](int row) {
    return src.patch == 1 ? static_cast<size_t>(row) * src.channels : static_cast<size_t>(src.patch_at[row]);
  };
  const int half = src.patch / 2;
  const PatchKernel kernel = patch_kernel(src.patch, src.channels);
  const int patch_w = src.patch * src.channels;
  std::vector<cv::Point> match_at(n);
  parallel_rows(n, o.threads, 8192, [&](int b, int e) {
    for (int d = b; d < e; ++d) match_at[d] = src.pixels[match[d]];
  });
  // With uniformity the use counts must be live for every pixel: one band.
  // Otherwise 8 bands of whole image rows holding about equal numbers of
  // object pixels (equal heights left one core idle for a while on a small
  // object); odd iterations cut halfway between (9 bands, the outer two half).
  const int h = dst.size.height;
  const int band_count = u > 0 ? 1 : 8;
  auto band_cuts = [&](bool halfway) {
    std::vector<int> cuts{0};  // first image row of each band, then h
    if (band_count > 1)
      for (int k = 1; k <= band_count - (halfway ? 0 : 1); ++k) {
        const long want = (2L * k - (halfway ? 1 : 0)) * n / (2L * band_count);
        cuts.push_back(static_cast<int>(std::lower_bound(at.begin(), at.end(), want) - at.begin()));
      }
    cuts.push_back(h);
    return cuts;
  };
  const std::vector<int> even_cuts = band_cuts(false), odd_cuts = band_cuts(true);
  // Windows halve from the source object's extent (larger ones only land off it).
  const int max_radius = std::max(src.bbox.width, src.bbox.height);
  // After the first pass, from the nearest-by-centre start, windows wider than
  // 16 px won under 0.4 % of their draws (bull <- orange, 21k px) for the
  // cost of a random source read each: later passes search within 16 px.
  const int far_radius = 16;
  for (int it = 0; it < o.iterations; ++it) {
    if (p.cancelled()) return make_error("cancelled during patchmatch");
    p.report(static_cast<double>(it) / o.iterations, "patchmatch");
    if (u > 0) {
      uses.assign(ns, 0);
      for (int d = 0; d < n; ++d) ++uses[match[d]];
    }
    const bool forward = it % 2 == 0;
    const int step = forward ? 1 : -1;
    const std::vector<int>& cuts = it % 2 ? odd_cuts : even_cuts;
    const int bands = static_cast<int>(cuts.size()) - 1;
    parallel_rows(bands, o.threads, 1, [&](int bb, int be) {
      // this band's own changes to the use counts, applied live
      std::unordered_map<int, int> delta;
      auto penalty = [&](int s) {
        if (u <= 0) return 0.0f;
        auto it = delta.find(s);
        return u * static_cast<float>(uses[s] + (it == delta.end() ? 0 : it->second)) / fair;
      };
      auto total = [&](float q, int s) { return std::sqrt(q / area) + penalty(s); };
      for (int bi = bb; bi < be; ++bi) {
        delta.clear();
        const int y0 = cuts[bi], y1 = cuts[bi + 1];
        const int r0 = at[y0], r1 = at[y1];
        for (int i = r0; i < r1; ++i) {
          const int d = forward ? i : r1 - 1 + r0 - i;
          const cv::Point pt = dst.pixels[d];
          size_t a_stride;
          const float* a = dst.patch_ptr(d, a_stride);  // read in place, not copied
          float best = u > 0 ? total(sq[d], match[d]) : 0.0f;  // with uniformity: RMS distance + penalty
          auto offer = [&](int x, int y) {
            const int bx = x - sb.x, by = y - sb.y;
            if (static_cast<unsigned>(bx) >= static_cast<unsigned>(sb.width) ||
                static_cast<unsigned>(by) >= static_cast<unsigned>(sb.height))
              return;  // off the source's box
            const size_t cell = static_cast<size_t>(by) * sb.width + bx;
            const uint8_t kind = src_kind[cell];
            if (kind == kOff || (x == match_at[d].x && y == match_at[d].y)) return;  // off the source, or no change
            if (u <= 0) {  // plain distances: compared squared, no roots
              const float v = kind == kInterior
                                  ? kernel(a, a_stride,
                                           src_base + static_cast<size_t>(by - half) * src_stride +
                                               static_cast<size_t>(bx - half) * src.channels,
                                           src_stride, src.patch, patch_w, sq[d])
                                  : kernel(a, a_stride, src_base + rim_offset(src_rows[cell]), src_stride, src.patch,
                                           patch_w, sq[d]);
              if (v < sq[d]) match[d] = src_rows[cell], match_at[d] = cv::Point(x, y), sq[d] = v;
              return;
            }
            int s = src_rows[cell];
            const float pen = penalty(s);
            const float room = best - pen;
            if (room <= 0) return;
            const float bound = room * room * area;
            const float v = kernel(a, a_stride, src_base + rim_offset(s), src_stride, src.patch, patch_w, bound);
            if (v > bound) return;
            const float t = std::sqrt(v / area) + pen;
            if (t < best) {
              --delta[match[d]], ++delta[s];
              best = t, match[d] = s, match_at[d] = cv::Point(x, y), sq[d] = v;
            }
          };
          for (const cv::Point off : {cv::Point(-step, 0), cv::Point(0, -step)}) {
            const int ny = pt.y + off.y;
            if (ny < y0 || ny >= y1) continue;  // another band's pixel: not this iteration
            const int nb = dst.row_at(pt.x + off.x, ny);
            if (nb < 0) continue;
            const cv::Point m = match_at[nb];
            offer(m.x - off.x, m.y - off.y);
          }
          uint64_t r = hash3(o.seed, static_cast<uint64_t>(it), static_cast<uint64_t>(d));
          for (int radius = it == 0 ? max_radius : std::min(max_radius, far_radius); radius >= 1; radius /= 2) {
            const cv::Point c = match_at[d];
            r = mix64(r);
            const int span = 2 * radius + 1;
            // uniform in [0, span) by multiply-shift (no division)
            const int ox = static_cast<int>(((r & 0xffffffffu) * static_cast<uint64_t>(span)) >> 32) - radius;
            const int oy = static_cast<int>(((r >> 32) * static_cast<uint64_t>(span)) >> 32) - radius;
            offer(c.x + ox, c.y + oy);
          }
        }
      }
    });
  }
  Map map = new_map(dst.size);
  parallel_rows(n, o.threads, 4096, [&](int b, int e) {
    for (int d = b; d < e; ++d) put(map, dst, src, d, match[d], sq[d]);
  });
  return map;
}

// Region growing with matcher.cpp's semantics (thesis sec. 4.2.2; the match
// constraint is relative: no more than T worse than the pixel's direct match): the direct
// matches come from the fast nearest search (parallel, exact: see nearest.cpp);
// the growth is the same sequential breadth-first pass, with distances read
// through the fast layout.
Expected<Map> run_regiongrow(const Object& dst, const Object& src, const MatchOptions& o, const Progress& p,
                             Stats* stats) {
  NearestLists nn;
  if (auto s = nearest_lists(dst, src, 1, "grid", o.threads, p, nn, stats); !s) return s.error();
  const int n = dst.rows();
  const float t = static_cast<float>(o.threshold);
  auto rms = [&](float v) { return map_distance(v, dst.patch); };
  // the direct distances, summed in element order (see below)
  std::vector<float> direct_sq(n);
  parallel_rows(n, o.threads, 512, [&](int b, int e) {
    std::vector<float> buf(dst.dims);
    for (int d = b; d < e; ++d) {
      dst.gather(d, buf.data());
      direct_sq[d] = patch_sq_ordered(buf.data(), src, nn.ids[d]);
    }
  });
  std::vector<int> match(n, -1);
  std::vector<float> sq(n, kInf);
  // The distances between neighbouring patches (to the right and below) of
  // each object, computed up front on all cores: the growth asks for them
  // often. (a - b)^2 == (b - a)^2 exactly, so either order of a pair gives the
  // faithful method's value.
  auto edges = [&](const Object& ob, std::vector<float>& right, std::vector<float>& down) {
    right.assign(ob.rows(), kInf);
    down.assign(ob.rows(), kInf);
    parallel_rows(ob.rows(), o.threads, 512, [&](int b, int e) {
      int ra[4], rb[4];
      float out[4];
      for (int i = b; i < e; ++i) {
        const cv::Point pt = ob.pixels[i];
        const int r = ob.row_at(pt.x + 1, pt.y), dn = ob.row_at(pt.x, pt.y + 1);
        int c = 0;
        if (r >= 0) ra[c] = i, rb[c++] = r;
        if (dn >= 0) ra[c] = i, rb[c++] = dn;
        if (c == 0) continue;
        patch_sq_ordered_pairs(ob, ra, ob, rb, c, out);
        c = 0;
        if (r >= 0) right[i] = out[c++];
        if (dn >= 0) down[i] = out[c++];
      }
    });
  };
  std::vector<float> dst_right, dst_down, src_right, src_down;
  if (t > 0) {
    edges(dst, dst_right, dst_down);
    edges(src, src_right, src_down);
  }
  // distance between row r and its neighbour at r + off (both on the object)
  auto edge = [](const Object& ob, const std::vector<float>& right, const std::vector<float>& down, int r,
                 cv::Point off) {
    const cv::Point pt = ob.pixels[r];
    if (off.x == 1) return right[r];
    if (off.y == 1) return down[r];
    const int back = ob.row_at(pt.x + off.x, pt.y + off.y);
    return off.x == -1 ? right[back] : down[back];
  };
  std::deque<int> queue;
  const cv::Point offsets[4] = {{1, 0}, {-1, 0}, {0, 1}, {0, -1}};
  for (int seed = 0; seed < n; ++seed) {
    if (match[seed] >= 0) continue;
    if ((seed & 4095) == 0 && p.cancelled()) return make_error("cancelled during region growing");
    match[seed] = nn.ids[seed];
    sq[seed] = direct_sq[seed];
    if (t <= 0) continue;
    queue.push_back(seed);
    while (!queue.empty()) {
      const int d = queue.front();
      queue.pop_front();
      const cv::Point pt = dst.pixels[d];
      const cv::Point m = src.pixels[match[d]];
      // the neighbours' data distances first, all four at once (none of
      // them depends on the others' outcome), then the decisions in order
      int qd[4], qsr[4], which[4], count = 0;
      for (int k = 0; k < 4; ++k) {
        const cv::Point off = offsets[k];
        const int q = dst.row_at(pt.x + off.x, pt.y + off.y);
        if (q < 0) continue;
        const int qs = src.row_at(m.x + off.x, m.y + off.y);
        if (qs < 0) continue;
        qd[count] = q, qsr[count] = qs, which[count++] = k;
      }
      if (count == 0) continue;
      // Summed in element order like the faithful method: growth decisions
      // chain, so rounding must agree bit for bit.
      float datas[4];
      patch_sq_ordered_pairs(dst, qd, src, qsr, count, datas);
      for (int j = 0; j < count; ++j) {
        const int q = qd[j], qs = qsr[j];
        const cv::Point off = offsets[which[j]];
        const float data = datas[j];
        if (!(data < sq[q])) continue;  // only a smaller distance overwrites
        if (!(rms(data) - rms(direct_sq[q]) < t)) continue;  // not much worse than its direct match
        if (!(rms(edge(dst, dst_right, dst_down, d, off)) < t)) continue;
        if (!(rms(edge(src, src_right, src_down, match[d], off)) < t)) continue;
        match[q] = qs;
        sq[q] = data;
        queue.push_back(q);
      }
    }
  }
  Map map = new_map(dst.size);
  for (int d = 0; d < n; ++d) put(map, dst, src, d, match[d], sq[d]);
  return map;
}

}  // namespace

// A full-frame map is 8 MB at 1024x680; freshly allocated, its pages fault in
// and are zeroed by the kernel on every call, which cost more CPU than the
// whole nearest search on a 21k px object (perf). So the last few maps'
// buffers are kept and handed out again once no caller holds them any more
// (OpenCV's reference count is back to the pool's own), and filled in parallel.
Map new_map(cv::Size size) {
  static std::mutex lock;
  static std::vector<std::pair<cv::Mat, cv::Mat>> pool;  // (xy, distance), at most 4
  Map map;
  {
    std::lock_guard<std::mutex> guard(lock);
    for (auto& [xy, dist] : pool)
      if (xy.size() == size && xy.u && xy.u->refcount == 1 && dist.u && dist.u->refcount == 1) {
        map.xy = xy;
        map.distance = dist;
        break;
      }
    if (map.xy.empty()) {
      map.xy.create(size, CV_32FC2);
      map.distance.create(size, CV_32FC1);
      if (pool.size() >= 4) pool.erase(pool.begin());
      pool.emplace_back(map.xy, map.distance);
    }
  }
  parallel_rows(size.height, 0, 32, [&](int b, int e) {
    map.xy.rowRange(b, e).setTo(cv::Scalar(-1, -1));
    map.distance.rowRange(b, e).setTo(cv::Scalar(0));
  });
  return map;
}

bool supports(const MatchOptions& options) {
  switch (options.method) {
    case Method::linear:
    case Method::flann:
    case Method::candidates:
    case Method::patchmatch:
    case Method::regiongrow:
    case Method::coherent:
    case Method::combined:
      return true;
    case Method::baseline:
      return false;
  }
  return false;
}

// Measured by bench_match: the grid answers nearest-normal queries faster
// than the kd-tree at both object sizes, and its lookup (no certification)
// about twice as fast again for +0.07 degrees of mean normal error.
const char* default_index() { return "lookup"; }

namespace {

// The view with its normals smoothed over sigma px (Gaussian, masked: only
// object pixels count), renormalised; the rest shared.
ObjectView smoothed_normals(const ObjectView& v, double sigma) {
  ObjectView out = v;
  out.normals = cv::Mat(v.normals.size(), CV_32FC3, cv::Scalar::all(0));  // new data: v's stays untouched
  // over the object's box and 3 sigma around it (beyond, all zero anyway)
  const int m = static_cast<int>(std::ceil(3 * sigma)) + 1;
  const cv::Rect box = (cv::boundingRect(v.mask) + cv::Size(2 * m, 2 * m) - cv::Point(m, m)) &
                       cv::Rect(cv::Point(0, 0), v.mask.size());
  cv::Mat masked = cv::Mat::zeros(box.size(), CV_32FC3), sum;  // (a sum's direction needs no weights)
  v.normals(box).copyTo(masked, v.mask(box));
  cv::GaussianBlur(masked, sum, {0, 0}, sigma, sigma, cv::BORDER_CONSTANT);
  for (int y = 0; y < box.height; ++y)
    for (int x = 0; x < box.width; ++x) {
      if (!v.mask.at<uchar>(box.y + y, box.x + x)) continue;
      const cv::Vec3f n = sum.at<cv::Vec3f>(y, x);
      const float len = static_cast<float>(cv::norm(n));
      out.normals.at<cv::Vec3f>(box.y + y, box.x + x) =
          len > 1e-6f ? n / len : v.normals.at<cv::Vec3f>(box.y + y, box.x + x);
    }
  return out;
}

// `coherent`'s threshold is a normal error (|dn|, about radians). Intensity
// features (each lamp's share of the pixel's light) change by another amount
// for the same turn of the surface, set by the lamps' layout. When the
// destination has normals, the threshold is converted by how much its
// features change per unit of normal change between neighbouring pixels (the
// median ratio over right and lower neighbours whose normals differ by 0.02
// or more; smaller differences are mostly noise); else it stays as given.
// Albedo divides out of the features, so texture does not move the ratio.
double feature_per_normal(const ObjectView& v, const Object& o) {
  if (v.normals.empty() || v.normals.size() != o.values.size()) return 1.0;
  const int c = o.channels;
  std::vector<float> ratios;
  for (int y = 0; y + 1 < v.mask.rows; ++y)
    for (int x = 0; x + 1 < v.mask.cols; ++x) {
      if (!v.mask.at<uchar>(y, x)) continue;
      const cv::Vec3f n = v.normals.at<cv::Vec3f>(y, x);
      const float* f = o.values.ptr<float>(y) + static_cast<size_t>(x) * c;
      for (const cv::Point d : {cv::Point(1, 0), cv::Point(0, 1)}) {
        if (!v.mask.at<uchar>(y + d.y, x + d.x)) continue;
        const double a = cv::norm(v.normals.at<cv::Vec3f>(y + d.y, x + d.x) - n);
        if (a < 0.02) continue;  // mostly noise
        const float* g = o.values.ptr<float>(y + d.y) + static_cast<size_t>(x + d.x) * c;
        double b = 0;
        for (int i = 0; i < c; ++i) b += (f[i] - g[i]) * (f[i] - g[i]);
        ratios.push_back(static_cast<float>(std::sqrt(b) / a));
      }
    }
  if (ratios.size() < 16) return 1.0;
  auto mid = ratios.begin() + ratios.size() / 2;
  std::nth_element(ratios.begin(), mid, ratios.end());
  return *mid > 0 ? *mid : 1.0;
}

}  // namespace

Expected<Map> compute_map(const ObjectView& destination, const ObjectView& source, const MatchOptions& options,
                          const Progress& progress) {
  return compute_map(destination, source, options, progress, nullptr);
}

Expected<Map> compute_map(const ObjectView& destination, const ObjectView& source, const MatchOptions& options,
                          const Progress& progress, Stats* stats) {
  const auto t0 = std::chrono::steady_clock::now();
  if (!supports(options))
    return make_error(std::string("the fast engine does not serve method '") + method_name(options.method) + "'");
  if (auto s = options.check(); !s) return s.error();
  if (auto s = check_pair(destination, source, options.feature); !s) return s.error();
  if (options.method == Method::combined) {
    // its own features (normals, shading, colour) and pyramid
    auto map = run_combined(destination, source, options, progress);
    if (stats) {
      *stats = Stats{};
      stats->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    }
    if (map) progress.report(1.0, "done");
    return map;
  }
  // pixel -> row lookups: for the methods that walk the image, and for the
  // propagation candidates of the patch search
  const bool grid_needed = options.method == Method::patchmatch || options.method == Method::regiongrow ||
                           options.method == Method::coherent ||
                           (options.patch > 1 && options.feature == Feature::normals);
  // `coherent` on normals judges single pixels: patches are not built
  const int patch = options.method == Method::coherent && options.feature == Feature::normals ? 1 : options.patch;
  // both objects at once (each is parallel inside too; their serial parts overlap)
  Expected<Object> dst = make_error("unreachable"), src = make_error("unreachable");
  auto make_dst = [&] { dst = make_object(destination, options.feature, patch, grid_needed, options.threads); };
  // `coherent` with a guide: the source's normals smoothed (see MatchOptions::coherent_guide)
  const bool guided = options.method == Method::coherent && options.feature == Feature::normals &&
                      options.coherent_guide > 0;
  auto make_src = [&] {
    src = make_object(guided ? smoothed_normals(source, options.coherent_guide) : source, options.feature, patch,
                      grid_needed, options.threads);
  };
  if (options.threads == 1) {
    make_dst();
    make_src();
  } else {
    tbb::parallel_invoke(make_dst, make_src);
  }
  if (!dst) return make_error("destination: " + dst.message());
  if (!src) return make_error("source: " + src.message());
  Stats local;
  Stats* st = stats ? stats : &local;
  *st = Stats{};
  st->index = default_index();
  Expected<Map> map = make_error("unreachable");
  switch (options.method) {
    case Method::linear:
    case Method::flann: map = run_direct(*dst, *src, options, progress, st); break;
    case Method::candidates: map = run_candidates(*dst, *src, options, progress, st); break;
    case Method::patchmatch: map = run_patchmatch(*dst, *src, options, progress); break;
    case Method::regiongrow: map = run_regiongrow(*dst, *src, options, progress, st); break;
    case Method::coherent: {
      MatchOptions o = options;
      if (o.feature == Feature::intensities) o.coherent_threshold *= feature_per_normal(destination, *dst);
      map = run_coherent(*dst, *src, o, progress, st);
      break;
    }
    case Method::combined:
    case Method::baseline: break;
  }
  st->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (map) {
    progress.report(1.0, "done");
    VLOG_DEBUG("Match", "fast {} {} {}x{}: {} -> {} pixels in {:.4f} s", method_name(options.method),
               feature_name(options.feature), options.patch, options.patch, dst->rows(), src->rows(), st->seconds);
  }
  return map;
}

}  // namespace veneer::match::fast
